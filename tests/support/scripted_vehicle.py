"""A scripted ArduPilot-like vehicle on a real pymavlink socket, for failure-mode tests of the service.

It answers the way Rover does (HEARTBEAT with mode and armed flag, COMMAND_ACK, LOCAL_POSITION_NED and
ATTITUDE stamped with its own time_boot_ms), moves at the commanded velocity through the water plus an
optional current (a point mass; heading along the commanded velocity, or the yaw of a velocity + yaw setpoint,
read as Rover does: speed |v| along the yaw, astern when vx < 0), and records every setpoint it
receives with its own time. A test can pause its positions, or everything (link loss), make it ignore
setpoints (a stalled boat), reboot it (its clock restarts, MANUAL, disarmed), and inject messages from a
foreign system id or raw garbage. Runs on its own thread.
"""

from __future__ import annotations

import math
import os
import threading
import time
from dataclasses import dataclass, field

os.environ["MAVLINK20"] = "1"

from pymavlink import mavutil

from koopguide.mavlink.rover import GUIDED, HOLD, LOITER, MANUAL, YAW_IGNORE  # noqa: F401 (the tests use them from here)

mavutil.set_dialect("ardupilotmega")
mavlink = mavutil.mavlink


@dataclass
class Received:
    t: float  # vehicle time [s]
    kind: str
    msg: object


@dataclass
class ScriptedVehicle:
    port: int  # the service's listening UDP port
    start_ned: tuple[float, float] = (1.0, -1.0)
    sysid: int = 1
    position_hz: float = 20.0
    mode: int = MANUAL
    armed: bool = False
    pause_positions: bool = False
    silent: bool = False  # nothing at all is sent (link loss)
    ignore_setpoints: bool = False  # a stalled boat: setpoints are received but not followed
    current_ned: tuple[float, float] = (0.0, 0.0)  # water current [m/s], added to the velocity
    received: list[Received] = field(default_factory=list)
    _stop: threading.Event = field(default_factory=threading.Event)

    def __post_init__(self) -> None:
        self.conn = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{self.port}", source_system=self.sysid, source_component=1, dialect="ardupilotmega"
        )
        self.n, self.e = self.start_ned
        self.vn = self.ve = 0.0
        self.heading = 0.0  # [rad] from north
        self.yaw: float | None = None  # the yaw of the last velocity + yaw setpoint [rad]
        self.t0 = time.monotonic()
        self.lock = threading.Lock()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> ScriptedVehicle:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self.thread.join(5)
        self.conn.close()

    @property
    def t(self) -> float:
        return time.monotonic() - self.t0

    def setpoints(self, since: float = 0.0) -> list[Received]:
        with self.lock:
            return [r for r in self.received if r.kind == "SET_POSITION_TARGET_LOCAL_NED" and r.t >= since]

    def of_kind(self, kind: str) -> list[Received]:
        with self.lock:
            return [r for r in self.received if r.kind == kind]

    def wait_for(self, predicate, timeout: float = 10.0) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return True
            time.sleep(0.02)
        return False

    # ------------------------------------------------------------------------------ loop
    def _run(self) -> None:
        dt = 1.0 / self.position_hz
        next_hb = 0.0
        while not self._stop.is_set():
            t = self.t
            self._receive(t)
            with self.lock:
                vn, ve = self.vn + self.current_ned[0], self.ve + self.current_ned[1]
                self.n += vn * dt
                self.e += ve * dt
            if not self.silent:
                if t >= next_hb:
                    next_hb = t + 1.0
                    self.send_heartbeat()
                ms = int(t * 1000)
                if not self.pause_positions:
                    self.conn.mav.local_position_ned_send(ms, self.n, self.e, 0.0, vn, ve, 0.0)
                if self.yaw is not None:
                    self.heading = self.yaw
                elif math.hypot(self.vn, self.ve) > 1e-6:
                    self.heading = math.atan2(self.ve, self.vn)
                self.conn.mav.attitude_send(ms, 0.0, 0.0, self.heading, 0.0, 0.0, 0.0)
            time.sleep(dt)

    def reboot(self) -> None:
        """Restart: the clock from 0 again, MANUAL, disarmed, at rest (telemetry rates back to default)."""
        with self.lock:
            self.t0 = time.monotonic()
            self.mode, self.armed = MANUAL, False
            self.vn = self.ve = 0.0

    def send_heartbeat(self) -> None:
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mavlink.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0)
        self.conn.mav.heartbeat_send(
            mavlink.MAV_TYPE_SURFACE_BOAT,
            mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
            base,
            self.mode,
            mavlink.MAV_STATE_ACTIVE,
        )

    def _receive(self, t: float) -> None:
        while True:
            msg = self.conn.recv_match(blocking=False)
            if msg is None:
                return
            kind = msg.get_type()
            with self.lock:
                self.received.append(Received(t, kind, msg))
            if kind == "COMMAND_LONG" and not self.silent:
                self._command(msg)
            elif kind == "SET_POSITION_TARGET_LOCAL_NED" and self.mode == GUIDED and self.armed:
                self._follow(msg)
            if self.mode != GUIDED:
                self.vn = self.ve = 0.0

    def _follow(self, msg) -> None:
        if self.ignore_setpoints:
            return
        if msg.type_mask & YAW_IGNORE:  # velocity only: that velocity (through the water), heading along it
            self.vn, self.ve, self.yaw = msg.vx, msg.vy, None
        else:  # velocity + yaw, as Rover reads it: heading yaw, speed |v|, astern when vx < 0
            speed = math.copysign(math.hypot(msg.vx, msg.vy), msg.vx)
            self.yaw = msg.yaw
            self.vn, self.ve = speed * math.cos(msg.yaw), speed * math.sin(msg.yaw)

    def _command(self, msg) -> None:
        if msg.command == mavlink.MAV_CMD_DO_SET_MODE:
            self.mode = int(msg.param2)
        elif msg.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            self.armed = msg.param1 == 1
        self.conn.mav.command_ack_send(msg.command, mavlink.MAV_RESULT_ACCEPTED)
        self.send_heartbeat()
