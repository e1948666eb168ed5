"""Rover-like autopilot logic: modes, arming, guided targets, and the heading/speed controller.

Pure logic, no I/O: the MAVLink endpoint decodes messages into calls here, and sends what this module
queues (``statustexts``, home changes). It follows ArduPilot Rover (boat) where a guidance service meets
it: mode numbers, arming, SET_POSITION_TARGET_* type-mask and frame rules, the guided timeout that
stops the boat and holds position, HOLD (thrusters off, the boat drifts), LOITER (holds a point against
the current), RTL (holds home), and a speed cap (WP_SPEED).

Conventions: positions (N, E) in local NED [m], velocities in NED [m/s], headings from north,
clockwise seen from above [rad], yaw rates [rad/s], times in simulated seconds. Controller outputs are
normalised thruster commands in [-1, 1] (port, starboard); steering > 0 turns to starboard.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass

from koopguide.mavlink.rover import (  # Rover mode numbers; POSITION_TARGET_TYPEMASK bits (set = ignore)
    ACC_IGNORE,
    MODE_NAMES,
    MODE_NUMBERS,
    POS_IGNORE,
    VEL_IGNORE,
    YAW_IGNORE,
    YAW_RATE_IGNORE,
)
from sitl.config import AutopilotConfig, AutopilotParams, RoverMode
from sitl.sensors import wrap_pi

SUPPORTED_MODES = frozenset(MODE_NUMBERS[m.value] for m in RoverMode)
MODES_NEEDING_POSITION = frozenset(MODE_NUMBERS[m] for m in ("LOITER", "GUIDED", "RTL"))
AUTOPILOT_MODES = frozenset(MODE_NUMBERS[m] for m in ("AUTO", "GUIDED", "LOITER", "RTL", "SMART_RTL"))
MANUAL_INPUT_MODES = frozenset(MODE_NUMBERS[m] for m in ("MANUAL", "ACRO", "STEERING"))

# The parameters served over PARAM_*: ArduPilot name -> AutopilotParams field.
PARAM_FIELDS = {
    "GUID_TIMEOUT": "guid_timeout_s",
    "WP_SPEED": "wp_speed_mps",
    "CRUISE_SPEED": "cruise_speed_mps",
    "CRUISE_THROTTLE": "cruise_throttle_pct",
    "ATC_SPEED_P": "speed_p",
    "ATC_SPEED_I": "speed_i",
    "ATC_STR_RAT_FF": "steer_rate_ff",
    "ATC_STR_RAT_P": "steer_rate_p",
    "ATC_STR_RAT_I": "steer_rate_i",
    "ATC_STR_RAT_MAX": "steer_rate_max_degps",
    "ATC_STR_ANG_P": "steer_angle_p",
    "LOIT_RADIUS": "loiter_radius_m",
    "LOIT_SPEED_GAIN": "loiter_speed_gain",
    "LOIT_TYPE": "loiter_type",
    "ATC_DECEL_MAX": "decel_max_mps2",
}


class MavResult(enum.IntEnum):
    """MAV_RESULT values used in COMMAND_ACK."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4


class Severity(enum.IntEnum):
    """MAV_SEVERITY values used in STATUSTEXT."""

    CRITICAL = 2
    ERROR = 3
    WARNING = 4
    NOTICE = 5
    INFO = 6


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


PIVOT_ANGLE_RAD = math.radians(60.0)  # WP_PIVOT_ANGLE: turn in place beyond this heading error
REVERSE_HYSTERESIS_RAD = math.radians(30.0)  # loiter flips forward/reverse only past 90 deg + this

LOCAL_FRAMES = frozenset({Frame.LOCAL_NED, Frame.LOCAL_OFFSET_NED, Frame.BODY_NED, Frame.BODY_OFFSET_NED})
BODY_FRAMES = frozenset({Frame.BODY_NED, Frame.BODY_OFFSET_NED})


class ParamStore:
    """The autopilot's live parameters by ArduPilot name, in a fixed order (PARAM_VALUE index)."""

    def __init__(self, params: AutopilotParams):
        self._values = {name: float(getattr(params, field)) for name, field in PARAM_FIELDS.items()}
        self.names = tuple(PARAM_FIELDS)

    def get(self, name: str) -> float:
        return self._values[name]

    def set(self, name: str, value: float) -> bool:
        """Set a known parameter (finite values only); False for an unknown name or bad value."""
        if name not in self._values or not math.isfinite(value):
            return False
        self._values[name] = struct.unpack("<f", struct.pack("<f", value))[0]  # stored as float32, as sent
        return True

    def __contains__(self, name: object) -> bool:
        return name in self._values

    def snapshot(self) -> AutopilotParams:
        return AutopilotParams(**{field: self._values[name] for name, field in PARAM_FIELDS.items()})


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
    speed_mps: float = 0.0  # desired forward speed over ground [m/s]
    heading_rad: float = 0.0  # desired heading [rad] (HEADING_SPEED)
    turn_rate_radps: float = 0.0  # desired yaw rate [rad/s] (TURN_RATE_SPEED)
    n: float = 0.0  # destination north [m] (POSITION)
    e: float = 0.0  # destination east [m] (POSITION)


class SetpointRejected(ValueError):
    """A SET_POSITION_TARGET_* message that ArduPilot Rover would ignore; the text says why."""


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
    BODY_NED, BODY_OFFSET_NED. Raises SetpointRejected for acceleration bits, unknown frames and
    unsupported field combinations.
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
        x, y = position
        if body:
            x, y = c * x - s * y, s * x + c * y
        if frame == Frame.LOCAL_NED:
            return GuidedTarget(TargetKind.POSITION, speed_mps=speed_cap, n=x, e=y)
        return GuidedTarget(TargetKind.POSITION, speed_mps=speed_cap, n=nav.n + x, e=nav.e + y)
    yaw_offset = nav.psi if body else 0.0
    if not vel_ignore:
        vx, vy = velocity
        if body:
            vx, vy = c * vx - s * vy, s * vx + c * vy
        speed = min(math.hypot(vx, vy), speed_cap)
        if yaw_ignore and yaw_rate_ignore:
            heading = math.atan2(vy, vx) if speed > 1e-6 else nav.psi
            return GuidedTarget(TargetKind.HEADING_SPEED, speed_mps=speed, heading_rad=heading)
        if not yaw_ignore and yaw_rate_ignore:
            return GuidedTarget(
                TargetKind.HEADING_SPEED, speed_mps=speed, heading_rad=wrap_pi(yaw + yaw_offset)
            )
        if yaw_ignore and not yaw_rate_ignore:
            return GuidedTarget(TargetKind.TURN_RATE_SPEED, speed_mps=speed, turn_rate_radps=yaw_rate)
    elif not yaw_ignore and yaw_rate_ignore:
        return GuidedTarget(TargetKind.HEADING_SPEED, speed_mps=0.0, heading_rad=wrap_pi(yaw + yaw_offset))
    elif yaw_ignore and not yaw_rate_ignore:
        return GuidedTarget(TargetKind.TURN_RATE_SPEED, speed_mps=0.0, turn_rate_radps=yaw_rate)
    raise SetpointRejected(f"Guided: type_mask {type_mask} combination not supported, ignored")


@dataclass
class ControllerState:
    """Integrators and the last commands of the heading/speed controller."""

    steer_integral: float = 0.0
    speed_integral: float = 0.0
    desired_heading: float | None = None  # [rad]
    desired_speed: float = 0.0  # [m/s]
    throttle: float = 0.0  # [-1, 1]
    steering: float = 0.0  # [-1, 1]
    reversing: bool = False  # loiter is backing toward its point


class Autopilot:
    """Mode, arming and guided logic for one boat, and its controller."""

    def __init__(self, cfg: AutopilotConfig, home: tuple[float, float]):
        self.params = ParamStore(cfg.params)
        self.mode = MODE_NUMBERS[cfg.initial_mode.value]
        self.armed = cfg.start_armed
        self.home = home  # (N, E) [m]
        self.home_changed = True  # HOME_POSITION to send
        self.statustexts: list[tuple[Severity, str]] = []
        self.target: GuidedTarget | None = None
        self.target_time = 0.0  # when the target was last set [s]
        self.hold_point: tuple[float, float] | None = None  # LOITER/stopped-GUIDED/RTL point [m]
        self.control = ControllerState()
        self.commands = (0.0, 0.0)  # latest thruster commands (port, starboard) in [-1, 1]

    # ---- mode and arming -------------------------------------------------------------------
    @property
    def mode_name(self) -> str:
        return MODE_NAMES.get(self.mode, str(self.mode))

    def set_mode(self, mode: int, nav: Navigation) -> MavResult:
        """Change mode; ArduPilot answers a failed change with FAILED and a STATUSTEXT."""
        if mode not in SUPPORTED_MODES:
            name = MODE_NAMES.get(mode, f"mode {mode}")
            self.say(Severity.WARNING, f"Mode change to {name} failed: not available in this simulator")
            return MavResult.FAILED
        if mode in MODES_NEEDING_POSITION and not nav.position_ok:
            self.say(Severity.WARNING, f"Mode change to {MODE_NAMES[mode]} failed: requires position")
            return MavResult.FAILED
        if mode != self.mode:
            self.mode = mode
            self.target = None
            self.control = ControllerState(desired_heading=nav.psi)
            self.hold_point = self.stopping_point(nav)
        return MavResult.ACCEPTED

    def arm(self, arm: bool, force: bool, nav: Navigation) -> MavResult:
        """Arm (pre-arm: a position estimate) or disarm; arming also sets home here."""
        if not arm:
            if self.armed:
                self.say(Severity.INFO, "Throttle disarmed")
            self.armed = False
            self.control = ControllerState()
            return MavResult.ACCEPTED
        if self.armed:
            return MavResult.ACCEPTED
        if not nav.position_ok and not force:
            self.say(Severity.CRITICAL, "PreArm: Need Position Estimate")
            return MavResult.FAILED
        self.armed = True
        self.control = ControllerState(desired_heading=nav.psi)
        self.hold_point = (nav.n, nav.e)
        self.target = None
        self.home = (nav.n, nav.e)
        self.home_changed = True
        self.say(Severity.INFO, "Throttle armed")
        return MavResult.ACCEPTED

    def stopping_point(self, nav: Navigation) -> tuple[float, float]:
        """Where the boat can stop decelerating at ATC_DECEL_MAX: position + v |v| / (2 a) [m]."""
        decel = max(self.params.get("ATC_DECEL_MAX"), 1e-3)
        speed = math.hypot(nav.vn, nav.ve)
        k = speed / (2.0 * decel)
        return nav.n + k * nav.vn, nav.e + k * nav.ve

    def set_home(self, n: float, e: float) -> None:
        self.home = (n, e)
        self.home_changed = True

    def set_guided_target(self, target: GuidedTarget, t: float) -> bool:
        """Accept a target only in GUIDED and armed (ArduPilot ignores it otherwise)."""
        if self.mode != MODE_NUMBERS["GUIDED"] or not self.armed:
            return False
        self.target = target
        self.target_time = t
        return True

    def say(self, severity: Severity, text: str) -> None:
        self.statustexts.append((severity, text))

    # ---- control ------------------------------------------------------------------------------
    def update(self, nav: Navigation, dt: float) -> tuple[float, float]:
        """Thruster commands (port, starboard) in [-1, 1] for this control step of dt [s]."""
        p = self.params
        ctl = self.control
        if not self.armed or self.mode in (MODE_NUMBERS["MANUAL"], MODE_NUMBERS["HOLD"]):
            self.control = ControllerState(desired_heading=nav.psi)
            self.commands = (0.0, 0.0)
            return self.commands
        timeout = p.get("GUID_TIMEOUT")
        if (
            self.mode == MODE_NUMBERS["GUIDED"]
            and self.target is not None
            and self.target.kind != TargetKind.POSITION
            and nav.t - self.target_time > timeout
        ):
            self.say(Severity.WARNING, f"target not received last {timeout:.1f} secs, stopping")
            self.target = None
            self.hold_point = self.stopping_point(nav)  # a boat holds position where it can stop
        target = self.target
        if self.mode == MODE_NUMBERS["GUIDED"] and target is not None:
            if target.kind == TargetKind.HEADING_SPEED:
                steering = self._steer_to_heading(target.heading_rad, nav, dt)
                throttle = self._throttle(target.speed_mps, nav, dt)
            elif target.kind == TargetKind.TURN_RATE_SPEED:
                ctl.desired_heading = None
                steering = self._steer_rate(target.turn_rate_radps, nav, dt)
                throttle = self._throttle(target.speed_mps, nav, dt)
            else:
                steering, throttle = self._hold((target.n, target.e), target.speed_mps, nav, dt)
        else:
            point = self.home if self.mode == MODE_NUMBERS["RTL"] else self.hold_point
            if point is None:
                point = self.hold_point = (nav.n, nav.e)
            steering, throttle = self._hold(point, p.get("WP_SPEED"), nav, dt)
        # Skid-steer mix; when throttle and steering together saturate, both are scaled back fairly.
        saturation = abs(throttle) + abs(steering)
        if saturation > 1.0:
            throttle /= saturation
            steering /= saturation
        ctl.throttle, ctl.steering = throttle, steering
        self.commands = (throttle + steering, throttle - steering)
        return self.commands

    def _hold(
        self, point: tuple[float, float], speed_cap: float, nav: Navigation, dt: float
    ) -> tuple[float, float]:
        """ArduPilot Rover loiter: head for the point (forward or reverse) outside LOIT_RADIUS.

        Within LOIT_RADIUS the heading is held and the speed is zero. Outside it the boat turns toward
        the point (pivoting while it faces away) at a speed growing with the distance, so in a current it
        settles facing upstream a little outside the radius, where its speed balances the current.
        """
        p = self.params
        dn, de = point[0] - nav.n, point[1] - nav.e
        distance = math.hypot(dn, de)
        radius = p.get("LOIT_RADIUS")
        ctl = self.control
        if distance <= radius:
            heading = ctl.desired_heading if ctl.desired_heading is not None else nav.psi
            speed = 0.0
        else:
            speed = min((distance - radius) * p.get("LOIT_SPEED_GAIN"), speed_cap)
            heading = math.atan2(de, dn)
            error = wrap_pi(heading - nav.psi)
            loiter_type = round(p.get("LOIT_TYPE"))
            if loiter_type == 0:  # ArduPilot: reverse when the point is behind; hysteresis keeps it from chattering
                flip = math.pi / 2 + REVERSE_HYSTERESIS_RAD  # the current direction is kept up to 120 deg off
                reversing = abs(error) > flip if not ctl.reversing else abs(wrap_pi(error + math.pi)) <= flip
                if reversing != ctl.reversing:
                    ctl.speed_integral = 0.0  # the speed loop's integrator belongs to the old direction
                    ctl.reversing = reversing
            else:
                ctl.reversing = loiter_type == 2
            if ctl.reversing:
                heading = wrap_pi(heading + math.pi)
                error = wrap_pi(heading - nav.psi)
                speed = -speed
            speed *= max(math.cos(error), 0.0) if abs(error) <= PIVOT_ANGLE_RAD else 0.0  # skid steer pivots
        return self._steer_to_heading(heading, nav, dt), self._throttle(speed, nav, dt)

    def _steer_to_heading(self, heading: float, nav: Navigation, dt: float) -> float:
        """Heading error -> desired turn rate (ATC_STR_ANG_P, capped at ATC_STR_RAT_MAX) -> steering."""
        p = self.params
        self.control.desired_heading = heading
        rate_max = math.radians(p.get("ATC_STR_RAT_MAX"))
        rate = min(rate_max, max(-rate_max, p.get("ATC_STR_ANG_P") * wrap_pi(heading - nav.psi)))
        return self._steer_rate(rate, nav, dt)

    def _steer_rate(self, rate: float, nav: Navigation, dt: float) -> float:
        """Turn-rate PI with feed-forward (ATC_STR_RAT_FF/P/I); the integrator stops at saturation."""
        p = self.params
        ctl = self.control
        error = rate - nav.r
        out = p.get("ATC_STR_RAT_FF") * rate + p.get("ATC_STR_RAT_P") * error + ctl.steer_integral
        if abs(out) < 1.0 or out * error < 0:
            ctl.steer_integral += p.get("ATC_STR_RAT_I") * error * dt
        return min(1.0, max(-1.0, out))

    def _throttle(self, speed: float, nav: Navigation, dt: float) -> float:
        """Forward speed over ground PI with CRUISE_SPEED/CRUISE_THROTTLE feed-forward."""
        p = self.params
        ctl = self.control
        ctl.desired_speed = speed
        forward = nav.vn * math.cos(nav.psi) + nav.ve * math.sin(nav.psi)
        error = speed - forward
        feed_forward = speed / p.get("CRUISE_SPEED") * p.get("CRUISE_THROTTLE") / 100.0
        out = feed_forward + p.get("ATC_SPEED_P") * error + ctl.speed_integral
        if abs(out) < 1.0 or out * error < 0:
            ctl.speed_integral += p.get("ATC_SPEED_I") * error * dt
        return min(1.0, max(-1.0, out))
