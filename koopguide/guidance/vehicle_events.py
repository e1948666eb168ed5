"""The vehicle facade: pymavlink messages from the target vehicle in, typed events out (MAVSDK style).

:class:`VehicleEvents` converts units (``time_boot_ms`` -> s, ``1e7 deg`` -> deg) and checks every stamp
against the :class:`~koopguide.guidance.estimation.clock.VehicleClock` before anything else sees it: a
stamp off the clock becomes :class:`~koopguide.guidance.events.InputRejected` (its message is dropped),
and a confirmed restart of the vehicle's clock becomes a
:class:`~koopguide.guidance.events.ClockRestart` ahead of the message that confirmed it. Messages the
service does not act on (COMMAND_ACK, STATUSTEXT) are returned as log lines. No sockets here: the
caller owns the link and passes each message with its arrival time ``wall_s`` [s, monotonic].
"""

from __future__ import annotations

import logging
from typing import Any

from koopguide.guidance import events as ev
from koopguide.guidance.estimation.clock import REJECTED, RESTARTED, ClockVerdict, VehicleClock
from koopguide.mavlink.wire import mavlink

ACCEPTED_RESULTS = (mavlink.MAV_RESULT_ACCEPTED, mavlink.MAV_RESULT_IN_PROGRESS)


class VehicleEvents:
    """Decodes the target vehicle's messages into events, moving ``clock`` with their stamps."""

    def __init__(self, clock: VehicleClock) -> None:
        self.clock = clock
        self.notes: list[ev.Note] = []

    def decode(self, msg: Any, wall_s: float) -> list[ev.Event]:
        """The events in ``msg`` (none for messages the service ignores)."""
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            return [ev.Heartbeat(wall_s, int(msg.custom_mode), armed)]
        if kind == "COMMAND_ACK":
            if msg.result not in ACCEPTED_RESULTS:
                self.notes.append(
                    ev.Note(logging.WARNING, f"vehicle refused command {msg.command} (MAV_RESULT {msg.result})")
                )
            return []
        if kind == "STATUSTEXT":
            self.notes.append(ev.Note(logging.INFO, f"vehicle says: {msg.text}"))
            return []
        if kind not in ("LOCAL_POSITION_NED", "ATTITUDE", "GLOBAL_POSITION_INT"):
            return []
        t = msg.time_boot_ms / 1000.0
        previous = self.clock.now()
        verdict = self.clock.observe(t, wall_s)
        if verdict in REJECTED:
            off = t - previous
            detail = f"{kind} time_boot_ms {msg.time_boot_ms} is {off:+.3f} s off the vehicle clock at {previous:.3f} s"
            return [ev.InputRejected(wall_s, "timestamp", detail)]
        out: list[ev.Event] = []
        if verdict in RESTARTED:
            out.append(ev.ClockRestart(wall_s, t, previous, rebooted=verdict is ClockVerdict.REBOOT))
        if kind == "LOCAL_POSITION_NED":
            out.append(ev.PositionFix(wall_s, t, (float(msg.x), float(msg.y)), (float(msg.vx), float(msg.vy))))
        elif kind == "ATTITUDE":
            out.append(ev.Attitude(wall_s, t, float(msg.yaw), float(msg.yawspeed)))
        else:
            out.append(ev.GlobalFix(wall_s, t, msg.lat / 1e7, msg.lon / 1e7))
        return out

    def take_notes(self) -> list[ev.Note]:
        notes, self.notes = self.notes, []
        return notes
