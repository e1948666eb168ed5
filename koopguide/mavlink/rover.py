"""ArduPilot Rover's MAVLink vocabulary: mode numbers, SET_POSITION_TARGET type masks, message builders.

Facts (docs/mavlink.md, ArduPilot Rover): modes by number (HEARTBEAT.custom_mode, MAV_CMD_DO_SET_MODE
param2); a mode change is COMMAND_LONG MAV_CMD_DO_SET_MODE (176) with param1 = 1 (custom mode enabled),
param2 = the mode; arming is MAV_CMD_COMPONENT_ARM_DISARM (400); telemetry rates are set with
MAV_CMD_SET_MESSAGE_INTERVAL (511). Velocity setpoints are SET_POSITION_TARGET_LOCAL_NED in
MAV_FRAME_LOCAL_NED with type mask 3559 (velocity only) or 2535 (velocity + yaw).
Conventions: NED metres and m/s; yaw in radians from north, clockwise seen from above.
Used by both the guidance service and the simulator: this is the one copy.
"""

from __future__ import annotations

import enum
import math
import struct
from collections.abc import Sequence

from koopguide.mavlink.wire import mavlink


class RoverMode(enum.IntEnum):
    """ArduPilot Rover custom_mode numbers."""

    MANUAL = 0
    ACRO = 1
    STEERING = 3
    HOLD = 4
    LOITER = 5
    FOLLOW = 6
    SIMPLE = 7
    AUTO = 10
    RTL = 11
    SMART_RTL = 12
    GUIDED = 15
    INITIALISING = 16


MODE_NUMBERS = {mode.name: int(mode) for mode in RoverMode}
MODE_NAMES = {number: name for name, number in MODE_NUMBERS.items()}
#: The modes the bundled simulator implements (and the service uses).
SIMULATED_MODES = (RoverMode.MANUAL, RoverMode.HOLD, RoverMode.LOITER, RoverMode.GUIDED, RoverMode.RTL)
MANUAL, HOLD, LOITER, GUIDED, RTL = (int(m) for m in SIMULATED_MODES)

# POSITION_TARGET_TYPEMASK bits of SET_POSITION_TARGET_*: a set bit means "ignore this field".
POS_IGNORE = 0x7  # X, Y, Z
VEL_IGNORE = 0x38  # VX, VY, VZ
VZ_IGNORE = 0x20
ACC_IGNORE = 0x1C0  # AX, AY, AZ
YAW_IGNORE = 0x400
YAW_RATE_IGNORE = 0x800
MASK_VELOCITY = POS_IGNORE | VZ_IGNORE | ACC_IGNORE | YAW_IGNORE | YAW_RATE_IGNORE  # 3559 = 0x0DE7
MASK_VELOCITY_YAW = MASK_VELOCITY & ~YAW_IGNORE  # 2535 = 0x09E7: velocity and yaw

MSG_ATTITUDE = mavlink.MAVLINK_MSG_ID_ATTITUDE  # 30
MSG_LOCAL_POSITION_NED = mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED  # 32
MSG_GLOBAL_POSITION_INT = mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT  # 33

Target = tuple[int, int]  # (target_system, target_component)


def mode_name(number: int | None) -> str | None:
    """The Rover name of a custom_mode number (``MODE_<n>`` if Rover has none); None stays None."""
    if number is None:
        return None
    return MODE_NAMES.get(number, f"MODE_{number}")


def is_autopilot_heartbeat(msg: object) -> bool:
    """A HEARTBEAT from an autopilot (not a ground station or companion, whose autopilot is INVALID)."""
    return msg.get_type() == "HEARTBEAT" and msg.autopilot != mavlink.MAV_AUTOPILOT_INVALID  # type: ignore[attr-defined]


def heartbeat() -> mavlink.MAVLink_message:
    """A companion's HEARTBEAT: an onboard controller, not an autopilot."""
    return mavlink.MAVLink_heartbeat_message(
        mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE, 3
    )


def command_long(target: Target, command: int, *params: float) -> mavlink.MAVLink_message:
    p = [*params, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0][:7]
    return mavlink.MAVLink_command_long_message(target[0], target[1], command, 0, *p)


def set_mode(target: Target, mode: int) -> mavlink.MAVLink_message:
    return command_long(target, mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode)


def arm(target: Target) -> mavlink.MAVLink_message:
    return command_long(target, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)


def message_interval(target: Target, message_id: int, rate_hz: float) -> mavlink.MAVLink_message:
    return command_long(target, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, message_id, 1e6 / rate_hz)


def float32_toward_zero(x: float) -> float:
    """``x`` as a float32 (how MAVLink carries it), rounded toward zero instead of to nearest: never larger."""
    y = struct.unpack("<f", struct.pack("<f", abs(x)))[0]
    if y > abs(x):  # one float32 step down
        y = struct.unpack("<f", struct.pack("<I", struct.unpack("<I", struct.pack("<f", y))[0] - 1))[0]
    return math.copysign(y, x)


def velocity_setpoint(
    target: Target, time_boot_ms: int, velocity_ned: Sequence[float], yaw_rad: float | None
) -> mavlink.MAVLink_message:
    """SET_POSITION_TARGET_LOCAL_NED: velocity (N, E) [m/s] only (3559), or with yaw [rad] (2535).

    With yaw, Rover holds heading ``yaw`` at the speed |v| over ground along it, astern when the sent vx is
    negative (GCS_MAVLink_Rover.cpp; docs/rover.md). The velocity goes as it is (a true NED vector, which
    a vehicle that follows velocities reads the same way) whenever the sign of its north component already
    says ahead or astern rightly; otherwise as (+-|v|, 0), the sign that of its component along the yaw.
    """
    vn, ve = (float(v) for v in velocity_ned)
    mask = MASK_VELOCITY if yaw_rad is None else MASK_VELOCITY_YAW
    if yaw_rad is not None:
        along = vn * math.cos(yaw_rad) + ve * math.sin(yaw_rad)
        if (vn < 0.0) != (along < 0.0) and math.hypot(vn, ve) > 0.0:
            vn, ve = math.copysign(float32_toward_zero(math.hypot(vn, ve)), along), 0.0  # no faster on the wire
    return mavlink.MAVLink_set_position_target_local_ned_message(
        time_boot_ms & 0xFFFFFFFF, target[0], target[1], mavlink.MAV_FRAME_LOCAL_NED, mask,
        0.0, 0.0, 0.0, vn, ve, 0.0, 0.0, 0.0, 0.0, 0.0 if yaw_rad is None else float(yaw_rad), 0.0,
    )  # fmt: skip
