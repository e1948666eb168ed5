"""What the supervisor asks of the vehicle, and when to ask again (pure; wall time passed in).

Mode changes and arming are asked again every ``mavlink.command_retry_s`` until the heartbeat shows
them; the telemetry rates (SET_MESSAGE_INTERVAL) on (re)connect, after a reboot or a heartbeat gap, and
again every 2 x ``command_retry_s`` while no fresh position arrives. Times: wall seconds [s].
"""

from __future__ import annotations

import math

from koopguide.guidance import events as ev
from koopguide.guidance.settings import GuidanceConfig
from koopguide.mavlink import rover

ATTITUDE_RATE_HZ = 10.0  # requested ATTITUDE rate (turn slowdown, current estimate, zero-velocity yaw) at most
FRESH_STREAM_S = 2.0  # positions younger than this (vehicle s): the streams are flowing, no need to ask again


class RequestSchedule:
    def __init__(self, cfg: GuidanceConfig) -> None:
        self.cfg = cfg
        self.streams_due = True  # ask for the telemetry at the next chance
        self._streams_wall = -math.inf
        self._last: dict[str, float] = {}  # what -> wall time last asked

    def once_per_retry(self, what: str, request: ev.Request, wall: float) -> list[ev.Request]:
        """``[request]`` now, or again after ``command_retry_s``; else ``[]``."""
        if wall - self._last.get(what, -math.inf) < self.cfg.mavlink.command_retry_s:
            return []
        self._last[what] = wall
        return [request]

    def streams(self, position_age_s: float | None, wall: float) -> list[ev.Request]:
        """The telemetry rates, when due."""
        retry = self.cfg.mavlink.command_retry_s
        fresh = position_age_s is not None and position_age_s < FRESH_STREAM_S
        if not self.streams_due and (fresh or wall - self._streams_wall < 2 * retry):
            return []
        self.streams_due, self._streams_wall = False, wall
        rate = self.cfg.mavlink.position_rate_hz
        out: list[ev.Request] = [
            ev.MessageInterval(rover.MSG_LOCAL_POSITION_NED, rate),
            ev.MessageInterval(rover.MSG_ATTITUDE, min(rate, ATTITUDE_RATE_HZ)),
        ]
        if self.cfg.frame.goal_latlon is not None:
            out.append(ev.MessageInterval(rover.MSG_GLOBAL_POSITION_INT, rate))
        return out
