"""What the service knows of the vehicle, and the MAVLink messages it sends to it (ArduPilot Rover).

Facts (FACTS.md "ArduPilot Rover"): modes by number (GUIDED 15, LOITER 5, HOLD 4...); a mode change is
COMMAND_LONG MAV_CMD_DO_SET_MODE (176) with param1 = 1 (custom mode enabled), param2 = the mode; arming
is MAV_CMD_COMPONENT_ARM_DISARM (400); telemetry rates are set with MAV_CMD_SET_MESSAGE_INTERVAL (511).
Velocity setpoints are SET_POSITION_TARGET_LOCAL_NED in MAV_FRAME_LOCAL_NED with type mask 3559
(velocity only) or 2535 (velocity + yaw). Conventions: NED metres and m/s; yaw in radians from north.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from koopguide.guidance.link import mavlink

ROVER_MODES = {
    "MANUAL": 0, "ACRO": 1, "STEERING": 3, "HOLD": 4, "LOITER": 5, "FOLLOW": 6, "SIMPLE": 7, "AUTO": 10,
    "RTL": 11, "SMART_RTL": 12, "GUIDED": 15, "INITIALISING": 16,
}
MODE_NAMES = {number: name for name, number in ROVER_MODES.items()}
GUIDED, LOITER, HOLD = ROVER_MODES["GUIDED"], ROVER_MODES["LOITER"], ROVER_MODES["HOLD"]

MASK_VELOCITY = 3559  # 0x0DE7: vx, vy used; position, vz, acceleration, yaw and yaw rate ignored
MASK_VELOCITY_YAW = 2535  # 0x09E7: velocity and yaw
MSG_LOCAL_POSITION_NED = 32
MSG_GLOBAL_POSITION_INT = 33
MSG_ATTITUDE = 30


def mode_name(number: int | None) -> str | None:
    if number is None:
        return None
    return MODE_NAMES.get(number, f"MODE_{number}")


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


def heartbeat() -> mavlink.MAVLink_message:
    """Our own HEARTBEAT: an onboard controller, not an autopilot."""
    return mavlink.MAVLink_heartbeat_message(
        mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE, 3
    )


def command_long(target: tuple[int, int], command: int, *params: float) -> mavlink.MAVLink_message:
    p = [*params, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0][:7]
    return mavlink.MAVLink_command_long_message(target[0], target[1], command, 0, *p)


def set_mode(target: tuple[int, int], mode: int) -> mavlink.MAVLink_message:
    return command_long(target, mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode)


def arm(target: tuple[int, int]) -> mavlink.MAVLink_message:
    return command_long(target, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)


def message_interval(target: tuple[int, int], message_id: int, rate_hz: float) -> mavlink.MAVLink_message:
    return command_long(target, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, message_id, 1e6 / rate_hz)


def velocity_setpoint(target: tuple[int, int], time_boot_ms: int, velocity_ned: np.ndarray,
                      yaw_rad: float | None) -> mavlink.MAVLink_message:
    """SET_POSITION_TARGET_LOCAL_NED: velocity only (3559), or velocity + yaw (2535) when ``yaw_rad`` is given."""
    vn, ve = (float(v) for v in velocity_ned)
    mask = MASK_VELOCITY if yaw_rad is None else MASK_VELOCITY_YAW
    return mavlink.MAVLink_set_position_target_local_ned_message(
        time_boot_ms & 0xFFFFFFFF, target[0], target[1], mavlink.MAV_FRAME_LOCAL_NED, mask,
        0.0, 0.0, 0.0, vn, ve, 0.0, 0.0, 0.0, 0.0, 0.0 if yaw_rad is None else float(yaw_rad), 0.0,
    )
