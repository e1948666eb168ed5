"""GUIDED-mode setpoints: how ArduPilot Rover reduces SET_POSITION_TARGET_* to a target, and its checks.

Pure functions, no I/O. The rules follow Rover's ``GCS_MAVLink_Rover.cpp``
(handle_set_position_target_local_ned / _global_int) and ``mode_guided.cpp``:

- any acceleration bit in use: the message is ignored (with a STATUSTEXT);
- a position given: drive there (velocity ignored); LOCAL_NED is absolute, the OFFSET/BODY frames are
  relative to the boat, BODY frames rotated by its heading;
- velocity only (type mask 3559): desired heading atan2(vy, vx), desired speed |v| clamped to WP_SPEED.
  So a ZERO velocity means heading NORTH (atan2(0, 0) = 0) at speed 0; in BODY frames the heading is
  relative to the boat's (zero velocity keeps it);
- velocity + yaw (2535): heading = yaw, speed = |v| clamped, negative when the sent vx < 0 (reverse);
- velocity + yaw rate (1511): turn rate and speed (the same sign rule);
- yaw only: that heading at speed 0; yaw rate only: that turn rate at speed 0.
The speed is over ground along the heading (sitl.steering holds it).

Sanity checks (ArduPilot's ``check_latlng`` and the rule "never act on NaN"): a NaN or infinite value in
any field the type mask uses, or a position farther than MAX_TARGET_DISTANCE_M from the origin, makes
the whole message ignored (SetpointRejected). A bad setpoint never becomes a speed.

Conventions: positions (N, E) in local NED [m], velocities in NED or body axes [m/s], headings from
north, clockwise seen from above [rad], yaw rates [rad/s], times in simulated seconds.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from koopguide.mavlink.rover import ACC_IGNORE, POS_IGNORE, VEL_IGNORE, YAW_IGNORE, YAW_RATE_IGNORE  # type mask bits
from sitl.sensors import wrap_pi

MAX_TARGET_DISTANCE_M = 50_000.0  # a position farther than this from the origin is refused [m]


class Frame(enum.IntEnum):
    """MAV_FRAME values that SET_POSITION_TARGET_* may use."""

    GLOBAL = 0
    LOCAL_NED = 1
    GLOBAL_RELATIVE_ALT = 3
    GLOBAL_INT = 5
    GLOBAL_RELATIVE_ALT_INT = 6
    LOCAL_OFFSET_NED = 7
    BODY_NED = 8
    BODY_OFFSET_NED = 9
    GLOBAL_TERRAIN_ALT = 10
    GLOBAL_TERRAIN_ALT_INT = 11


LOCAL_FRAMES = frozenset({Frame.LOCAL_NED, Frame.LOCAL_OFFSET_NED, Frame.BODY_NED, Frame.BODY_OFFSET_NED})
BODY_FRAMES = frozenset({Frame.BODY_NED, Frame.BODY_OFFSET_NED})


@dataclass(frozen=True)
class Navigation:
    """The autopilot's estimate of its boat (from sitl.sensors), at time t."""

    t: float  # [s]
    n: float  # [m]
    e: float  # [m]
    vn: float  # [m/s]
    ve: float  # [m/s]
    psi: float  # [rad]
    r: float  # [rad/s]
    position_ok: bool  # a recent position fix exists


class TargetKind(enum.Enum):
    HEADING_SPEED = "heading_speed"
    TURN_RATE_SPEED = "turn_rate_speed"
    POSITION = "position"


@dataclass(frozen=True)
class GuidedTarget:
    """A guided-mode target as ArduPilot Rover reduces SET_POSITION_TARGET_* to it."""

    kind: TargetKind
    speed_mps: float = 0.0  # desired speed over ground along the heading, negative = reverse [m/s]
    heading_rad: float = 0.0  # desired heading [rad] (HEADING_SPEED)
    turn_rate_radps: float = 0.0  # desired yaw rate [rad/s] (TURN_RATE_SPEED)
    n: float = 0.0  # destination north [m] (POSITION)
    e: float = 0.0  # destination east [m] (POSITION)

    def is_finite(self) -> bool:
        values = (self.speed_mps, self.heading_rad, self.turn_rate_radps, self.n, self.e)
        return all(math.isfinite(v) for v in values)


class SetpointRejected(ValueError):
    """A SET_POSITION_TARGET_* message that ArduPilot Rover would ignore; the text says why."""


def _require_finite(what: str, *values: float) -> None:
    if not all(math.isfinite(v) for v in values):
        shown = ", ".join(repr(v) for v in values)
        raise SetpointRejected(f"Guided: {what} not finite ({shown}), setpoint ignored")


def interpret_position_target(
    type_mask: int,
    frame: int,
    position: tuple[float, float],
    velocity: tuple[float, float],
    yaw: float,
    yaw_rate: float,
    nav: Navigation,
    speed_cap: float,
) -> GuidedTarget:
    """Reduce a SET_POSITION_TARGET_LOCAL_NED to a guided target, with ArduPilot Rover's rules.

    ``position`` and ``velocity`` are (x, y) as sent [m], [m/s]; frames LOCAL_NED, LOCAL_OFFSET_NED,
    BODY_NED, BODY_OFFSET_NED; ``speed_cap`` is WP_SPEED [m/s]. Raises SetpointRejected for
    acceleration bits, unknown frames, unsupported field combinations and non-finite or far values.
    """
    if frame not in LOCAL_FRAMES:
        raise SetpointRejected(f"SET_POSITION_TARGET frame {frame} not supported, ignored")
    pos_ignore = type_mask & POS_IGNORE == POS_IGNORE
    vel_ignore = type_mask & VEL_IGNORE == VEL_IGNORE
    acc_ignore = type_mask & ACC_IGNORE == ACC_IGNORE
    yaw_ignore = bool(type_mask & YAW_IGNORE)
    yaw_rate_ignore = bool(type_mask & YAW_RATE_IGNORE)
    if not acc_ignore:
        raise SetpointRejected(f"Guided: acceleration target not supported (type_mask {type_mask}), ignored")
    body = frame in BODY_FRAMES
    c, s = math.cos(nav.psi), math.sin(nav.psi)
    if not pos_ignore:  # a position overrides any velocity
        _require_finite("position", *position)
        x, y = position
        if body:
            x, y = c * x - s * y, s * x + c * y
        n, e = (x, y) if frame == Frame.LOCAL_NED else (nav.n + x, nav.e + y)
        if math.hypot(n, e) > MAX_TARGET_DISTANCE_M:
            raise SetpointRejected(
                f"Guided: position ({n:.6g}, {e:.6g}) m is beyond {MAX_TARGET_DISTANCE_M:g} m, ignored"
            )
        return GuidedTarget(TargetKind.POSITION, speed_mps=speed_cap, n=n, e=e)
    if not vel_ignore:
        _require_finite("velocity", *velocity)
    if not yaw_ignore:
        _require_finite("yaw", yaw)
    if not yaw_rate_ignore:
        _require_finite("yaw rate", yaw_rate)
    yaw_offset = nav.psi if body else 0.0
    if not vel_ignore:
        vx, vy = velocity
        speed = min(math.hypot(vx, vy), speed_cap)
        if yaw_ignore and yaw_rate_ignore:  # velocity only: always forward, heading along it
            heading = wrap_pi(math.atan2(vy, vx) + yaw_offset)  # atan2(0, 0) = 0: north (LOCAL frames)
            return GuidedTarget(TargetKind.HEADING_SPEED, speed_mps=speed, heading_rad=heading)
        if vx < 0:  # with a yaw or a yaw rate, the sent x velocity's sign chooses forward or reverse
            speed = -speed
        if not yaw_ignore and yaw_rate_ignore:
            return GuidedTarget(TargetKind.HEADING_SPEED, speed_mps=speed, heading_rad=wrap_pi(yaw + yaw_offset))
        if yaw_ignore and not yaw_rate_ignore:
            return GuidedTarget(TargetKind.TURN_RATE_SPEED, speed_mps=speed, turn_rate_radps=yaw_rate)
    elif not yaw_ignore and yaw_rate_ignore:
        return GuidedTarget(TargetKind.HEADING_SPEED, speed_mps=0.0, heading_rad=wrap_pi(yaw + yaw_offset))
    elif yaw_ignore and not yaw_rate_ignore:
        return GuidedTarget(TargetKind.TURN_RATE_SPEED, speed_mps=0.0, turn_rate_radps=yaw_rate)
    raise SetpointRejected(f"Guided: type_mask {type_mask} combination not supported, ignored")
