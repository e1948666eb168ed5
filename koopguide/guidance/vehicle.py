"""What the service knows of the vehicle (ArduPilot Rover); the Rover vocabulary is koopguide.mavlink.rover.

Conventions: NED metres and m/s; yaw in radians from north.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from koopguide.mavlink.rover import (
    GUIDED,
    HOLD,
    LOITER,
    MODE_NAMES,
    MSG_ATTITUDE,
    MSG_GLOBAL_POSITION_INT,
    MSG_LOCAL_POSITION_NED,
    arm,
    heartbeat,
    message_interval,
    mode_name,
    set_mode,
    velocity_setpoint,
)
from koopguide.mavlink.wire import mavlink

__all__ = [
    "GUIDED",
    "HOLD",
    "LOITER",
    "MODE_NAMES",
    "MSG_ATTITUDE",
    "MSG_GLOBAL_POSITION_INT",
    "MSG_LOCAL_POSITION_NED",
    "VehicleView",
    "arm",
    "heartbeat",
    "mavlink",
    "message_interval",
    "mode_name",
    "set_mode",
    "velocity_setpoint",
]


@dataclass
class VehicleView:
    """The latest facts from the target vehicle. Times: ``*_wall`` time.monotonic(), ``*_t`` vehicle s."""

    heartbeat_wall: float | None = None
    mode: int | None = None
    armed: bool | None = None
    fix_t: float | None = None  # vehicle time of the newest accepted LOCAL_POSITION_NED
    fix_ned: np.ndarray | None = None  # its (N, E) [m]
    global_fix: tuple[float, float, float] | None = None  # (time s, lat deg, lon deg) of GLOBAL_POSITION_INT
    attitude: tuple[float, float, float] | None = None  # ATTITUDE: (time s, heading rad from north, yaw rate rad/s)

    def link_up(self, now_wall: float, timeout_s: float) -> bool:
        return self.heartbeat_wall is not None and now_wall - self.heartbeat_wall <= timeout_s
