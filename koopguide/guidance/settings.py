"""The guidance service's typed configuration: frozen dataclasses built from ``config/guidance.yaml``.

Defaults live only in ``config/guidance.yaml``; these classes carry the types, the units (in the field
names) and the range checks. :func:`load` merges defaults, the user's file and command-line overrides
and raises :class:`koopguide.base.config.ConfigError` naming the key for anything unknown, ill-typed or out
of range - before the service opens any link.
"""

from __future__ import annotations

import enum
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from koopguide.base import config
from koopguide.base.config import ConfigError

VEHICLE_ID = re.compile(r"^[A-Za-z0-9_-]{1,64}$")  # a zenoh key segment: no / * $ # ?
MAX_RATE_HZ = 50.0


class ArrivalAction(enum.Enum):
    LOITER = "loiter"  # the autopilot's LOITER holds position against a current
    HOLD = "hold"  # the autopilot's HOLD: motors stop (a boat drifts)
    STATION_KEEP = "station_keep"  # keep steering onto the goal, crabbing into the current


class OutsideDomain(enum.Enum):
    HOLD = "hold"
    CLAMP = "clamp"


class ExitMode(enum.Enum):
    LOITER = "loiter"
    HOLD = "hold"


@dataclass(frozen=True)
class MavlinkSettings:
    endpoint: str
    target_system: int
    target_component: int
    source_system: int
    source_component: int
    heartbeat_hz: float
    position_rate_hz: float
    link_timeout_s: float
    reconnect_min_s: float
    reconnect_max_s: float
    command_retry_s: float

    def __post_init__(self) -> None:
        for name in ("target_system", "source_system"):
            _check(1 <= getattr(self, name) <= 255, f"mavlink.{name}", getattr(self, name), "1 .. 255")
        for name in ("target_component", "source_component"):
            _check(0 <= getattr(self, name) <= 255, f"mavlink.{name}", getattr(self, name), "0 .. 255")
        for name in ("heartbeat_hz", "position_rate_hz", "link_timeout_s", "reconnect_min_s", "command_retry_s"):
            _positive(self, "mavlink", name)
        _check(self.reconnect_max_s >= self.reconnect_min_s, "mavlink.reconnect_max_s", self.reconnect_max_s,
               f">= reconnect_min_s ({self.reconnect_min_s})")


@dataclass(frozen=True)
class FrameSettings:
    goal_ned: tuple[float, float]  # [m]
    goal_latlon: tuple[float, float] | None  # [deg]
    scale: float  # metres per model unit
    heading_deg: float  # compass heading of model +x

    def __post_init__(self) -> None:
        _finite(self, "frame", "goal_ned", "scale", "heading_deg")
        _positive(self, "frame", "scale")
        if self.goal_latlon is not None:
            lat, lon = self.goal_latlon
            _check(-90 <= lat <= 90 and -180 <= lon <= 180, "frame.goal_latlon", self.goal_latlon,
                   "latitude -90 .. 90 and longitude -180 .. 180 degrees")


@dataclass(frozen=True)
class CommandSettings:
    rate_hz: float
    max_speed_mps: float
    min_speed_mps: float
    turn_slowdown: bool
    current_compensation: bool
    lookahead_m: float
    with_yaw: bool
    lead_s: float
    domain_margin: float
    speed_grid: int

    def __post_init__(self) -> None:
        _finite(self, "command", "rate_hz", "max_speed_mps", "min_speed_mps", "lead_s", "domain_margin", "lookahead_m")
        _check(0 < self.rate_hz <= MAX_RATE_HZ, "command.rate_hz", self.rate_hz, f"0 < rate <= {MAX_RATE_HZ:g}")
        _positive(self, "command", "max_speed_mps")
        _check(0 <= self.min_speed_mps <= self.max_speed_mps, "command.min_speed_mps", self.min_speed_mps,
               f"0 .. max_speed_mps ({self.max_speed_mps})")
        for name in ("lead_s", "domain_margin", "lookahead_m"):
            _check(getattr(self, name) >= 0, f"command.{name}", getattr(self, name), ">= 0")
        _check(self.speed_grid >= 8, "command.speed_grid", self.speed_grid, ">= 8")


@dataclass(frozen=True)
class ArrivalSettings:
    radius_m: float
    on_arrival: ArrivalAction
    station_gain: float
    capture_radius_m: float
    approach_radius_m: float
    facing_deg: float
    settle_radius_m: float
    settle_timeout_s: float
    reacquire_radius_m: float  # arrived -> guiding again beyond this distance from the goal [m]
    integral_gain_per_s2: float  # station keeping: integral of the position error [1/s^2]
    integral_limit_mps: float  # anti-windup: the integral term's largest speed [m/s]
    min_approach_mps: float  # no cap (approach, turn slowdown) slows the boat below this outside radius_m [m/s]

    def __post_init__(self) -> None:
        _positive(self, "arrival", "radius_m", "station_gain")
        _finite(self, "arrival", "reacquire_radius_m", "integral_gain_per_s2", "integral_limit_mps", "min_approach_mps")
        _check(self.reacquire_radius_m > self.radius_m, "arrival.reacquire_radius_m", self.reacquire_radius_m,
               f"> radius_m ({self.radius_m})")
        for name in ("integral_gain_per_s2", "integral_limit_mps", "min_approach_mps"):
            _check(getattr(self, name) >= 0, f"arrival.{name}", getattr(self, name), ">= 0")
        _finite(self, "arrival", "capture_radius_m", "approach_radius_m", "facing_deg", "settle_radius_m",
                "settle_timeout_s")
        _check(self.capture_radius_m >= 0, "arrival.capture_radius_m", self.capture_radius_m, ">= 0")
        _check(self.approach_radius_m >= self.radius_m, "arrival.approach_radius_m", self.approach_radius_m,
               f">= radius_m ({self.radius_m})")
        _check(0 < self.facing_deg < 90, "arrival.facing_deg", self.facing_deg, "0 < angle < 90")
        _check(0 <= self.settle_radius_m <= self.radius_m, "arrival.settle_radius_m", self.settle_radius_m,
               f"0 .. radius_m ({self.radius_m})")
        _check(self.settle_timeout_s >= 0, "arrival.settle_timeout_s", self.settle_timeout_s, ">= 0")


@dataclass(frozen=True)
class EstimatorSettings:
    position_std_m: float
    velocity_std_mps: float
    accel_std_mps2: float
    gate_chi2: float
    reset_after_rejections: int
    max_dt_s: float
    current_prior_std_mps: float
    current_walk_mps_per_sqrt_s: float
    current_max_turn_dps: float

    def __post_init__(self) -> None:
        _positive(self, "estimator", "position_std_m", "velocity_std_mps", "accel_std_mps2", "gate_chi2", "max_dt_s",
                  "current_prior_std_mps", "current_max_turn_dps")
        _finite(self, "estimator", "current_walk_mps_per_sqrt_s")
        _check(self.current_walk_mps_per_sqrt_s >= 0, "estimator.current_walk_mps_per_sqrt_s",
               self.current_walk_mps_per_sqrt_s, ">= 0")
        _check(self.reset_after_rejections >= 1, "estimator.reset_after_rejections", self.reset_after_rejections,
               ">= 1")


@dataclass(frozen=True)
class FailsafeSettings:
    stale_after_s: float
    outside_domain: OutsideDomain
    geofence_ned: tuple[tuple[float, float], tuple[float, float]] | None  # ((N_min, N_max), (E_min, E_max)) [m]
    on_exit: ExitMode
    zero_with_yaw: bool  # zero-velocity commands carry the current heading as yaw (mask 2535): no pivot north
    stall_s: float  # guiding with less than stall_progress_m of progress along the field for this long [s]
    stall_progress_m: float  # ... switches to direct pursuit of the goal (degraded) [m]
    heartbeat_gap_s: float  # a vehicle heartbeat gap this long (wall) re-requests the telemetry streams [s]

    def __post_init__(self) -> None:
        _positive(self, "failsafe", "stale_after_s", "stall_s", "stall_progress_m", "heartbeat_gap_s")
        if self.geofence_ned is not None:
            for axis, (lo, hi) in zip("NE", self.geofence_ned, strict=True):
                _check(math.isfinite(lo) and math.isfinite(hi) and lo < hi, "failsafe.geofence_ned", self.geofence_ned,
                       f"finite [min, max] with min < max on {axis}")


@dataclass(frozen=True)
class LimitSettings:
    """Physical bounds on every input (issue 11): anything outside is rejected, counted and logged."""

    max_speed_mps: float  # a reported, estimated or implied vehicle speed above this is not physical [m/s]
    max_position_m: float  # |N| or |E| beyond this [m]
    max_jump_m: float  # a fix this far (plus max_speed_mps x elapsed time) from the estimate is a teleport [m]
    max_turn_rate_dps: float  # |yaw rate| above this [deg/s]
    max_current_mps: float  # a current estimate above this is reset [m/s]
    clock_window_s: float  # a stamp this far ahead of the vehicle clock (plus elapsed time) is rejected [s]
    clock_confirm: int  # ... unless this many consecutive stamps agree: then the clock restarts (reboot/jump)
    teleport_hold_s: float  # hold this long (vehicle time) after the last teleported fix [s]
    teleport_confirm_s: float  # a jumped position that stays this long with no fix at the old place is taken [s]
    log_every_s: float  # at most one rejection log line per kind this often (wall) [s]

    def __post_init__(self) -> None:
        _positive(self, "limits", "max_speed_mps", "max_position_m", "max_jump_m", "max_turn_rate_dps",
                  "max_current_mps", "clock_window_s", "teleport_hold_s", "teleport_confirm_s", "log_every_s")
        _check(1 <= self.clock_confirm <= 100, "limits.clock_confirm", self.clock_confirm, "1 .. 100")


@dataclass(frozen=True)
class StatusSettings:
    rate_hz: float
    field_grid: int

    def __post_init__(self) -> None:
        _check(0 < self.rate_hz <= MAX_RATE_HZ, "status.rate_hz", self.rate_hz, f"0 < rate <= {MAX_RATE_HZ:g}")
        _check(2 <= self.field_grid <= 200, "status.field_grid", self.field_grid, "2 .. 200")


@dataclass(frozen=True)
class GuidanceConfig:
    vehicle_id: str
    arm: bool
    mavlink: MavlinkSettings
    frame: FrameSettings
    command: CommandSettings
    arrival: ArrivalSettings
    estimator: EstimatorSettings
    failsafe: FailsafeSettings
    limits: LimitSettings
    status: StatusSettings

    def __post_init__(self) -> None:
        _check(bool(VEHICLE_ID.match(self.vehicle_id)), "vehicle_id", self.vehicle_id,
               "1-64 characters of A-Z a-z 0-9 _ -")
        _check(self.limits.max_speed_mps >= self.command.max_speed_mps, "limits.max_speed_mps",
               self.limits.max_speed_mps, f">= command.max_speed_mps ({self.command.max_speed_mps})")


def load(user_file: str | Path | None = None, overrides: dict[str, Any] | None = None) -> GuidanceConfig:
    """Defaults, then ``user_file``, then ``overrides`` (nested like the YAML), checked."""
    try:
        return config.build(GuidanceConfig, config.load_layers("guidance", user_file, overrides or {}))
    except (TypeError, ValueError) as exc:  # a range check raised while building
        if isinstance(exc, ConfigError):
            raise
        raise ConfigError(str(exc)) from None


def _check(ok: bool, key: str, value: Any, expected: str) -> None:
    if not ok:
        raise ConfigError(f"{key}: {value!r} is out of range (expected {expected})")


def _positive(obj: Any, section: str, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        _check(math.isfinite(value) and value > 0, f"{section}.{name}", value, "a finite number > 0")


def _finite(obj: Any, section: str, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        values = value if isinstance(value, tuple) else (value,)
        _check(all(math.isfinite(v) for v in values), f"{section}.{name}", value, "finite numbers")

