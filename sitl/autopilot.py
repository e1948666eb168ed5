"""Rover-like autopilot logic: modes, arming, guided targets, home, and which controller runs.

Pure logic, no I/O: the MAVLink endpoint decodes messages into calls here, and sends what this module
queues (``statustexts``, home changes). It follows ArduPilot Rover (boat) where a guidance service meets
it: mode numbers, arming, the guided timeout that stops the boat and loiters (``mode_guided.cpp``),
HOLD (thrusters off, the boat drifts), LOITER (drift inside LOIT_RADIUS, drive back outside), RTL
(loiter at home), and a speed cap (WP_SPEED). Setpoint rules live in sitl.guided, the controllers and
each vehicle kind's mixer in sitl.steering, the parameters and their ranges in sitl.parameters.

Conventions: positions (N, E) in local NED [m], velocities in NED [m/s], headings from north,
clockwise seen from above [rad], yaw rates [rad/s], times in simulated seconds. Controller outputs are
normalised actuator commands in [-1, 1] in the vehicle kind's order (sitl.vehicles).
"""

from __future__ import annotations

import enum
import math

from koopguide.mavlink.rover import MODE_NAMES, MODE_NUMBERS  # Rover mode numbers
from sitl.config import AutopilotConfig, SimulatedMode, VehicleKind
from sitl.guided import (  # noqa: F401 - re-exported: the names sitl.inbound and the tests use
    Frame,
    GuidedTarget,
    Navigation,
    SetpointRejected,
    TargetKind,
    interpret_position_target,
)
from sitl.parameters import ParamStore
from sitl.steering import ControllerState, Steering

SUPPORTED_MODES = frozenset(MODE_NUMBERS[m.value] for m in SimulatedMode)
MODES_NEEDING_POSITION = frozenset(MODE_NUMBERS[m] for m in ("LOITER", "GUIDED", "RTL"))
AUTOPILOT_MODES = frozenset(MODE_NUMBERS[m] for m in ("AUTO", "GUIDED", "LOITER", "RTL", "SMART_RTL"))
MANUAL_INPUT_MODES = frozenset(MODE_NUMBERS[m] for m in ("MANUAL", "ACRO", "STEERING"))
HOME_MAX_DISTANCE_M = 50_000.0  # ArduPilot refuses a home this far from the EKF origin [m]


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


class Autopilot:
    """Mode, arming and guided logic for one boat of a given kind, and its controllers."""

    def __init__(self, cfg: AutopilotConfig, home: tuple[float, float], kind: VehicleKind):
        self.kind = kind
        self.params = ParamStore(cfg.params)
        self.mode = MODE_NUMBERS[cfg.initial_mode.value]
        self.armed = cfg.start_armed
        self.home = home  # (N, E) [m]
        self.home_changed = True  # HOME_POSITION to send
        self.statustexts: list[tuple[Severity, str]] = []
        self.target: GuidedTarget | None = None
        self.target_time = 0.0  # when the target was last set [s]
        self.target_reached = False  # a POSITION target was reached (or passed): loiter about it
        self.target_origin = (0.0, 0.0)  # where the boat was when it got the POSITION target [m]
        self.hold_point: tuple[float, float] | None = None  # LOITER/stopped-GUIDED/RTL point [m]
        self.steering = Steering(kind, self.params)
        self.commands: tuple[float, ...] = self.steering.zero()  # latest actuator commands in [-1, 1]

    @property
    def control(self) -> ControllerState:
        """The controllers' integrators and last outputs (for telemetry and the recorder)."""
        return self.steering.state

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
            self.steering.reset(nav.psi)
            self.hold_point = self.stopping_point(nav)
        return MavResult.ACCEPTED

    def arm(self, arm: bool, force: bool, nav: Navigation) -> MavResult:
        """Arm (pre-arm: a position estimate) or disarm; arming also sets home here."""
        if not arm:
            if self.armed:
                self.say(Severity.INFO, "Throttle disarmed")
            self.armed = False
            self.steering.reset()
            return MavResult.ACCEPTED
        if self.armed:
            return MavResult.ACCEPTED
        if not nav.position_ok and not force:
            self.say(Severity.CRITICAL, "PreArm: Need Position Estimate")
            return MavResult.FAILED
        self.armed = True
        self.steering.reset(nav.psi)
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

    def set_home(self, n: float, e: float) -> MavResult:
        """Move home to (n, e) [m]; refused (FAILED, nothing changes) if not finite or too far away."""
        if not (math.isfinite(n) and math.isfinite(e)) or math.hypot(n, e) > HOME_MAX_DISTANCE_M:
            self.say(Severity.WARNING, f"Home ({n:.6g}, {e:.6g}) m refused: not a valid location")
            return MavResult.FAILED
        self.home = (n, e)
        self.home_changed = True
        return MavResult.ACCEPTED

    def set_guided_target(self, target: GuidedTarget, t: float, here: tuple[float, float] = (0.0, 0.0)) -> bool:
        """Accept a finite target only in GUIDED and armed (ArduPilot ignores it otherwise)."""
        if self.mode != MODE_NUMBERS["GUIDED"] or not self.armed or not target.is_finite():
            return False
        old = self.target
        if old is None or (old.kind, old.n, old.e) != (target.kind, target.n, target.e):
            self.target_reached = False  # a new destination (a resent one keeps its progress)
            self.target_origin = here
        self.target = target
        self.target_time = t
        return True

    def say(self, severity: Severity, text: str) -> None:
        self.statustexts.append((severity, text))

    def _arrived(self, point: tuple[float, float], nav: Navigation) -> bool:
        """Within WP_RADIUS of ``point``, or past it along the track from where the target was given."""
        dn, de = point[0] - nav.n, point[1] - nav.e
        if math.hypot(dn, de) <= self.params.get("WP_RADIUS"):
            return True
        track_n, track_e = point[0] - self.target_origin[0], point[1] - self.target_origin[1]
        return track_n * dn + track_e * de < 0.0  # the point is behind, seen along the track

    # ---- control ------------------------------------------------------------------------------
    def update(self, nav: Navigation, dt: float) -> tuple[float, ...]:
        """Actuator commands in [-1, 1] (sitl.vehicles order) for this control step of dt [s]."""
        commands = self._run(nav, dt)
        if not all(math.isfinite(c) for c in commands):  # never act on NaN: stop, and say so
            self.say(Severity.CRITICAL, "Controller output not finite, thrusters stopped")
            self.steering.reset(nav.psi if math.isfinite(nav.psi) else None)
            commands = self.steering.zero()
        self.commands = commands
        return commands

    def _run(self, nav: Navigation, dt: float) -> tuple[float, ...]:
        p = self.params
        steering = self.steering
        if not self.armed or self.mode in (MODE_NUMBERS["MANUAL"], MODE_NUMBERS["HOLD"]):
            steering.reset(nav.psi)
            return steering.zero()
        timeout = p.get("GUID_TIMEOUT")
        guided = self.mode == MODE_NUMBERS["GUIDED"]
        target = self.target
        stale = nav.t - self.target_time > timeout
        if guided and target is not None and target.kind != TargetKind.POSITION and stale:
            self.say(Severity.WARNING, f"target not received last {timeout:.1f} secs, stopping")
            self.target = target = None
            self.hold_point = self.stopping_point(nav)  # a boat loiters where it can stop
        loiter_radius = p.get("LOIT_RADIUS")
        if guided and target is not None:
            if target.kind == TargetKind.HEADING_SPEED:
                return steering.heading_speed(target.heading_rad, target.speed_mps, nav, dt)
            if target.kind == TargetKind.TURN_RATE_SPEED:
                return steering.turn_rate_speed(target.turn_rate_radps, target.speed_mps, nav, dt)
            # a position: drive there (within WP_RADIUS), then loiter about it (mode_guided.cpp)
            point = (target.n, target.e)
            if not self.target_reached and math.hypot(point[0] - nav.n, point[1] - nav.e) <= p.get("WP_RADIUS"):
                self.target_reached = True
            radius = loiter_radius if self.target_reached else p.get("WP_RADIUS")
            return steering.hold(point, target.speed_mps, radius, nav, dt)
        point = self.home if self.mode == MODE_NUMBERS["RTL"] else self.hold_point
        if point is None:
            point = self.hold_point = (nav.n, nav.e)
        return steering.hold(point, p.get("WP_SPEED"), loiter_radius, nav, dt)
