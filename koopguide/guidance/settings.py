"""The guidance service's typed configuration: frozen dataclasses built from ``config/guidance.yaml``.

Defaults live only in ``config/guidance.yaml`` (``koopguide/defaults/guidance.yaml``); these classes carry
the types, the units (in the field names) and each number's interval (in its type, checked while
loading: :mod:`koopguide.base.config`); ``__post_init__`` checks only relations between keys.
:func:`load` merges defaults, the user's file and command-line overrides and raises
:class:`koopguide.base.config.ConfigError` naming the key for anything unknown, ill-typed or out of
range - before the service opens any link.
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

from koopguide.base import config
from koopguide.base.config import FiniteFloat, Range, check

VEHICLE_ID = re.compile(r"^[A-Za-z0-9_-]{1,64}$")  # a zenoh key segment: no / * $ # ?
MAX_RATE_HZ = 50.0
Rate = Annotated[float, Range(0.0, MAX_RATE_HZ, lo_open=True)]  # [Hz]
SystemId = Annotated[int, Range(1, 255)]
ComponentId = Annotated[int, Range(0, 255)]
Seconds = Annotated[float, Range(0.0, 3600.0, lo_open=True)]  # a positive duration up to an hour [s]
Speed = Annotated[float, Range(0.0, 20.0)]  # a boat's speed [m/s]
Distance = Annotated[float, Range(0.0, 1000.0)]  # [m]


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
    target_system: SystemId
    target_component: ComponentId
    source_system: SystemId
    source_component: ComponentId
    heartbeat_hz: Rate
    position_rate_hz: Rate
    link_timeout_s: Seconds
    reconnect_min_s: Seconds
    reconnect_max_s: Seconds
    command_retry_s: Seconds
    signing_key: Path | None  # MAVLink 2 signing key file (docs/mavlink.md); null: unsigned, trust the link

    def __post_init__(self) -> None:
        check(
            self.reconnect_max_s >= self.reconnect_min_s,
            "mavlink.reconnect_max_s",
            self.reconnect_max_s,
            f">= reconnect_min_s ({self.reconnect_min_s})",
        )


@dataclass(frozen=True)
class FrameSettings:
    goal_ned: tuple[FiniteFloat, FiniteFloat]  # [m]
    goal_latlon: tuple[Annotated[float, Range(-90.0, 90.0)], Annotated[float, Range(-180.0, 180.0)]] | None  # [deg]
    scale: Annotated[float, Range(0.0, 1e6, lo_open=True)]  # metres per model unit
    heading_deg: Annotated[float, Range(-360.0, 360.0)]  # compass heading of model +x


@dataclass(frozen=True)
class CommandSettings:
    rate_hz: Rate
    max_speed_mps: Annotated[float, Range(0.0, 20.0, lo_open=True)]
    min_speed_mps: Speed
    turn_speed_mps: Speed  # a boat that needs way to turn (a rudder boat) keeps at least this while turning
    approach_speed_mps: Speed  # ... and drives its planned approach at this speed through the water (at most)
    probe_turn_s: Annotated[float, Range(0.0, 30.0)]  # at the start, ask a turn in place this long at most (0: off)
    turn_slowdown: bool
    current_compensation: bool
    lookahead_m: Distance
    with_yaw: bool
    lead_s: Annotated[float, Range(0.0, 5.0)]
    domain_margin: Annotated[float, Range(0.0, 10.0)]
    turning_room_m: Distance  # a boat that needs way to turn may use this much beyond the domain (not the geofence)
    speed_grid: Annotated[int, Range(8, 512)]

    def __post_init__(self) -> None:
        check(
            self.min_speed_mps <= self.max_speed_mps,
            "command.min_speed_mps",
            self.min_speed_mps,
            f"0 .. max_speed_mps ({self.max_speed_mps})",
        )
        check(
            self.approach_speed_mps >= self.turn_speed_mps,
            "command.approach_speed_mps",
            self.approach_speed_mps,
            f"at least turn_speed_mps ({self.turn_speed_mps})",
        )


@dataclass(frozen=True)
class ArrivalSettings:
    radius_m: Annotated[float, Range(0.0, 1000.0, lo_open=True)]
    on_arrival: ArrivalAction
    station_gain: Annotated[float, Range(0.0, 100.0, lo_open=True)]  # [1/s]
    capture_radius_m: Distance
    approach_radius_m: Distance
    facing_deg: Annotated[float, Range(0.0, 90.0, lo_open=True, hi_open=True)]
    settle_radius_m: Distance
    settle_timeout_s: Annotated[float, Range(0.0, 3600.0)]
    reacquire_radius_m: Distance  # arrived -> guiding again beyond this distance from the goal [m]
    integral_gain_per_s2: Annotated[float, Range(0.0, 100.0)]  # station keeping: integral of the error [1/s^2]
    integral_limit_mps: Speed  # anti-windup: the integral term's largest speed [m/s]
    min_approach_mps: Speed  # no cap (approach, turn slowdown) slows the boat below this outside radius_m [m/s]

    def __post_init__(self) -> None:
        check(
            self.approach_radius_m >= self.radius_m,
            "arrival.approach_radius_m",
            self.approach_radius_m,
            f">= radius_m ({self.radius_m})",
        )
        check(
            self.settle_radius_m <= self.radius_m,
            "arrival.settle_radius_m",
            self.settle_radius_m,
            f"0 .. radius_m ({self.radius_m})",
        )
        check(
            self.reacquire_radius_m > self.radius_m,
            "arrival.reacquire_radius_m",
            self.reacquire_radius_m,
            f"> radius_m ({self.radius_m})",
        )


@dataclass(frozen=True)
class EstimatorSettings:
    position_std_m: Annotated[float, Range(0.0, 100.0, lo_open=True)]
    velocity_std_mps: Annotated[float, Range(0.0, 100.0, lo_open=True)]
    accel_std_mps2: Annotated[float, Range(0.0, 100.0, lo_open=True)]
    gate_chi2: Annotated[float, Range(0.0, 1e6, lo_open=True)]
    reset_after_rejections: Annotated[int, Range(1, 1000)]
    max_dt_s: Seconds
    current_prior_std_mps: Annotated[float, Range(0.0, 20.0, lo_open=True)]
    current_walk_mps_per_sqrt_s: Annotated[float, Range(0.0, 10.0)]
    current_shear_mps_per_sqrt_m: Annotated[float, Range(0.0, 10.0)]  # the current's change along the route
    current_shear_onset_mps: Annotated[float, Range(0.0, 10.0, lo_open=True)]  # ... once the slip shows it
    current_max_turn_dps: Annotated[float, Range(0.0, 360.0, lo_open=True)]


@dataclass(frozen=True)
class FailsafeSettings:
    stale_after_s: Seconds
    outside_domain: OutsideDomain
    # ((N_min, N_max), (E_min, E_max)) [m]
    geofence_ned: tuple[tuple[FiniteFloat, FiniteFloat], tuple[FiniteFloat, FiniteFloat]] | None
    on_exit: ExitMode
    zero_with_yaw: bool  # zero-velocity commands carry the current heading as yaw (mask 2535): no pivot north
    stall_s: Seconds  # guiding with less than stall_progress_m of progress along the field for this long [s]
    stall_progress_m: Annotated[float, Range(0.0, 1000.0, lo_open=True)]  # ... switches to direct pursuit [m]
    heartbeat_gap_s: Seconds  # a vehicle heartbeat gap this long (wall) re-requests the telemetry streams [s]

    def __post_init__(self) -> None:
        if self.geofence_ned is not None:
            for axis, (lo, hi) in zip("NE", self.geofence_ned, strict=True):
                check(lo < hi, "failsafe.geofence_ned", self.geofence_ned, f"[min, max] with min < max on {axis}")


@dataclass(frozen=True)
class LimitSettings:
    """Physical bounds on every input (issue 11): anything outside is rejected, counted and logged."""

    max_speed_mps: Annotated[float, Range(0.0, 100.0, lo_open=True)]  # a faster vehicle is not physical [m/s]
    max_position_m: Annotated[float, Range(0.0, 1e6, lo_open=True)]  # |N| or |E| beyond this [m]
    max_jump_m: Annotated[float, Range(0.0, 1e4, lo_open=True)]  # a fix this far (+ max speed x time) is a teleport [m]
    max_turn_rate_dps: Annotated[float, Range(0.0, 3600.0, lo_open=True)]  # |yaw rate| above this [deg/s]
    max_current_mps: Annotated[float, Range(0.0, 100.0, lo_open=True)]  # a current estimate above this is reset [m/s]
    clock_window_s: Seconds  # a stamp this far ahead of the vehicle clock (plus elapsed time) is rejected [s]
    clock_confirm: Annotated[int, Range(1, 100)]  # ... unless this many consecutive stamps agree: a restart
    teleport_hold_s: Seconds  # hold this long (vehicle time) after the last teleported fix [s]
    teleport_confirm_s: Seconds  # a jumped position that stays this long with no fix at the old place is taken [s]
    log_every_s: Seconds  # at most one rejection log line per kind this often (wall) [s]


@dataclass(frozen=True)
class StatusSettings:
    rate_hz: Rate
    field_grid: Annotated[int, Range(2, 200)]
    control_token_file: Path | None  # the operator's shared token (docs/dashboard.md); null: control disabled


@dataclass(frozen=True)
class FleetSettings:
    """Separation from other boats heard on zenoh (docs/fleet.md; koopguide.guidance.law.separation)."""

    enabled: bool  # filter the command to keep min_separation_m from the other vehicles' statuses
    min_separation_m: Annotated[float, Range(0.0, 100.0, lo_open=True)]  # never closer to another boat [m]
    slot_separation_m: Annotated[float, Range(0.0, 100.0, lo_open=True)]  # rendezvous slots this far apart [m]
    barrier_gain_per_s: Annotated[float, Range(0.0, 100.0, lo_open=True)]  # CBF alpha: closing rate per m^2 [1/s]
    neighbour_timeout_s: Annotated[float, Range(0.0, 60.0, lo_open=True)]  # forget a boat not heard for this long [s]

    def __post_init__(self) -> None:
        check(
            self.slot_separation_m >= self.min_separation_m,
            "fleet.slot_separation_m",
            self.slot_separation_m,
            f">= min_separation_m ({self.min_separation_m})",
        )


@dataclass(frozen=True)
class GuidanceConfig:
    vehicle_id: str
    arm: bool
    allow_uncertified: bool  # guide with a model that failed or lacks its convergence certificate (warned)
    mavlink: MavlinkSettings
    frame: FrameSettings
    command: CommandSettings
    arrival: ArrivalSettings
    estimator: EstimatorSettings
    failsafe: FailsafeSettings
    limits: LimitSettings
    status: StatusSettings
    fleet: FleetSettings

    def __post_init__(self) -> None:
        check(
            bool(VEHICLE_ID.match(self.vehicle_id)), "vehicle_id", self.vehicle_id, "1-64 characters of A-Z a-z 0-9 _ -"
        )
        check(
            self.limits.max_speed_mps >= self.command.max_speed_mps,
            "limits.max_speed_mps",
            self.limits.max_speed_mps,
            f">= command.max_speed_mps ({self.command.max_speed_mps})",
        )


def load(user_file: str | Path | None = None, overrides: dict[str, Any] | None = None) -> GuidanceConfig:
    """Defaults, then ``user_file``, then ``overrides`` (nested like the YAML), checked."""
    return config.build(GuidanceConfig, config.load_layers("guidance", user_file, overrides or {}))
