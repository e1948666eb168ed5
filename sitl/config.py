"""The simulator's typed configuration: frozen dataclasses built from ``config/sitl.yaml``.

Defaults live only in ``config/sitl.yaml``; these classes carry the types and the units. Build one with
:func:`load`, which layers the shipped defaults, an optional user file and explicit overrides, and
rejects unknown or ill-typed keys with :class:`koopguide.base.config.ConfigError` naming the key.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from koopguide.base import config as config_loader
from koopguide.base.config import ConfigError


class FlowKind(enum.Enum):
    """A flow component; several compose by summing their velocities."""

    NONE = "none"
    UNIFORM = "uniform"
    VORTEX = "vortex"
    DOUBLE_GYRE = "double_gyre"
    GUSTS = "gusts"


class VehicleKind(enum.Enum):
    """How a boat is propelled and steered (sitl.vehicles)."""

    DIFF_THRUST = "diff_thrust"  # two fixed stern thrusters, skid steering, pivot turns
    RUDDER = "rudder"  # one centreline thruster and a rudder: no steering without way through the water
    VECTORED = "vectored"  # the thruster pair plus bow and stern tunnel thrusters: can thrust sideways


class RoverMode(enum.Enum):
    """ArduPilot Rover mode numbers (HEARTBEAT custom_mode) that the simulator can enter."""

    MANUAL = "MANUAL"
    HOLD = "HOLD"
    LOITER = "LOITER"
    GUIDED = "GUIDED"
    RTL = "RTL"


@dataclass(frozen=True)
class HullConfig:
    mass_kg: float  # m, rigid-body mass [kg]
    yaw_inertia_kgm2: float  # I_z about the body z axis through the centre of gravity [kg m^2]
    length_m: float  # hull length overall [m]; also the wall contact margin (half of it)
    beam_m: float  # hull width [m]; the wall contact margin across (half of it)
    added_mass_surge_kg: float  # X_udot [kg], negative by Fossen's sign convention
    added_mass_sway_kg: float  # Y_vdot [kg], negative
    added_inertia_yaw_kgm2: float  # N_rdot [kg m^2], negative
    linear_damping_surge_kgps: float  # X_u [kg/s], negative
    linear_damping_sway_kgps: float  # Y_v [kg/s], negative
    linear_damping_yaw_kgm2ps: float  # N_r [kg m^2/s], negative
    quadratic_damping_surge_kgpm: float  # X_|u|u [kg/m], negative or zero
    quadratic_damping_sway_kgpm: float  # Y_|v|v [kg/m], negative or zero
    quadratic_damping_yaw_kgm2: float  # N_|r|r [kg m^2], negative or zero


@dataclass(frozen=True)
class ThrusterConfig:
    max_rate_rps: float  # n_max, propeller speed at full command [rev/s]
    max_forward_thrust_n: float  # thrust of one thruster at +n_max [N]
    max_reverse_thrust_n: float  # thrust magnitude of one thruster at -n_max [N]
    lateral_offset_m: float  # l, each thruster's distance from the centre line [m]
    time_constant_s: float  # T_n, first-order motor lag [s]


@dataclass(frozen=True)
class RudderConfig:
    """The rudder boat: one centreline propeller with the pair's total thrust, and a stern rudder."""

    max_angle_deg: float  # rudder deflection at full steering command [deg]
    time_constant_s: float  # first-order lag of the rudder servo [s]
    lift_slope_kgpm: float  # Y_delta = 1/2 rho A_R C_L_alpha: sway force per (m/s)^2 and rad [kg/m]
    position_m: float  # x_R, rudder position along the body x axis (negative = aft) [m]


@dataclass(frozen=True)
class LateralThrusterConfig:
    """The vectored boat's bow and stern tunnel thrusters (sway force and yaw moment)."""

    max_thrust_n: float  # thrust of one tunnel thruster at full command, either way [N]
    lever_m: float  # distance of each tunnel thruster from the centre of gravity along x [m]


@dataclass(frozen=True)
class VesselConfig:
    hull: HullConfig
    thrusters: ThrusterConfig
    rudder: RudderConfig
    lateral_thrusters: LateralThrusterConfig


@dataclass(frozen=True)
class UniformFlowConfig:
    speed_mps: float  # mean current speed [m/s]
    direction_deg: float  # compass direction the water flows toward (0 = north, 90 = east) [deg]
    drift_std_mps: float  # stationary std of the slow Gauss-Markov drift of each component [m/s]
    drift_time_constant_s: float  # 1/mu of the Gauss-Markov drift [s]


@dataclass(frozen=True)
class VortexConfig:
    center_ned_m: tuple[float, float]  # vortex centre [N, E] in local NED [m]
    circulation_m2ps: float  # Gamma; positive = counter-clockwise seen from above [m^2/s]
    core_radius_m: float  # r_c of the Lamb-Oseen core [m]


@dataclass(frozen=True)
class DoubleGyreConfig:
    origin_ned_m: tuple[float, float]  # corner of the [0, 2s] x [0, s] domain in local NED [m]
    amplitude_mps: float  # A; the peak speed is about pi A (1 + 2 eps) [m/s]
    epsilon: float  # eps, amplitude of the gyre boundary oscillation [-]
    omega_radps: float  # omega of the boundary oscillation [rad/s]
    scale_m: float  # s, the domain spans 2s along north and s along east [m]
    dissipation_per_s: float  # mu of the -mu x dissipation term; 0 keeps the flow divergence-free [1/s]


@dataclass(frozen=True)
class GustConfig:
    std_mps: float  # stationary std of each gust velocity component [m/s]
    time_constant_s: float  # correlation time of the Ornstein-Uhlenbeck gusts [s]


@dataclass(frozen=True)
class FlowConfig:
    kinds: tuple[FlowKind, ...]  # flow components summed; [] or [none] for calm water
    uniform: UniformFlowConfig
    vortex: VortexConfig
    double_gyre: DoubleGyreConfig
    gusts: GustConfig


@dataclass(frozen=True)
class WorldConfig:
    walls: bool  # confine the boats to the tank rectangle
    north_m: tuple[float, float]  # tank extent along north [min, max] in local NED [m]
    east_m: tuple[float, float]  # tank extent along east [min, max] in local NED [m]


@dataclass(frozen=True)
class OriginConfig:
    latitude_deg: float  # geodetic latitude of the local NED origin [deg]
    longitude_deg: float  # geodetic longitude of the local NED origin [deg]
    altitude_m: float  # altitude of the water surface above mean sea level [m]


@dataclass(frozen=True)
class PositionSensorConfig:
    rate_hz: float  # position/velocity fixes per second (motion capture or GPS) [Hz]
    noise_std_m: float  # white position noise per axis [m]
    velocity_noise_std_mps: float  # white velocity noise per axis [m/s]
    latency_s: float  # delay from measurement to availability [s]
    dropout_probability: float  # chance that a fix is lost [-]
    unhealthy_after_s: float  # no fix for this long -> position unhealthy, pre-arm fails [s]


@dataclass(frozen=True)
class HeadingSensorConfig:
    noise_std_deg: float  # white heading noise [deg]
    rate_noise_std_degps: float  # white yaw-rate noise [deg/s]


@dataclass(frozen=True)
class SensorConfig:
    position: PositionSensorConfig
    heading: HeadingSensorConfig


@dataclass(frozen=True)
class AutopilotParams:
    """Parameters served over PARAM_* under their ArduPilot Rover names (see sitl.autopilot)."""

    guid_timeout_s: float  # GUID_TIMEOUT: guided setpoint timeout [s]
    wp_speed_mps: float  # WP_SPEED: speed cap for guided/loiter/RTL [m/s]
    cruise_speed_mps: float  # CRUISE_SPEED: speed reached at CRUISE_THROTTLE [m/s]
    cruise_throttle_pct: float  # CRUISE_THROTTLE: throttle for CRUISE_SPEED [%]
    speed_p: float  # ATC_SPEED_P: speed error -> throttle [1/(m/s)]
    speed_i: float  # ATC_SPEED_I: integrated speed error -> throttle [1/m]
    steer_rate_ff: float  # ATC_STR_RAT_FF: turn rate -> steering [1/(rad/s)]
    steer_rate_p: float  # ATC_STR_RAT_P: turn-rate error -> steering [1/(rad/s)]
    steer_rate_i: float  # ATC_STR_RAT_I: integrated turn-rate error -> steering [1/rad]
    steer_rate_max_degps: float  # ATC_STR_RAT_MAX: turn-rate cap [deg/s]
    steer_angle_p: float  # ATC_STR_ANG_P: heading error -> desired turn rate [1/s]
    pivot_angle_deg: float  # WP_PIVOT_ANGLE: skid steering pivots beyond this heading error; 0 = never [deg]
    pivot_rate_degps: float  # WP_PIVOT_RATE: turn-rate cap while pivoting [deg/s]
    wp_radius_m: float  # WP_RADIUS: a guided position target is reached within this distance [m]
    loiter_radius_m: float  # LOIT_RADIUS: no correction inside this distance [m]
    loiter_speed_gain: float  # LOIT_SPEED_GAIN: distance beyond the radius -> speed [1/s]
    loiter_type: float  # LOIT_TYPE: 0 forward or reverse, 1 forward only, 2 reverse only [-]
    decel_max_mps2: float  # ATC_DECEL_MAX: deceleration used to place the stopping point [m/s^2]


@dataclass(frozen=True)
class AutopilotConfig:
    initial_mode: RoverMode  # mode at boot (ArduPilot INITIAL_MODE)
    start_armed: bool  # boot armed (tests and scripted runs; ArduPilot boots disarmed)
    control_rate_hz: float  # heading/speed controller rate [Hz]
    params: AutopilotParams


@dataclass(frozen=True)
class StreamRates:
    """MAVLink stream groups (REQUEST_DATA_STREAM ids) and their default rates per link [Hz]."""

    extended_status: float  # SYS_STATUS, GPS_RAW_INT [Hz]
    position: float  # GLOBAL_POSITION_INT, LOCAL_POSITION_NED [Hz]
    extra1: float  # ATTITUDE [Hz]
    extra2: float  # VFR_HUD [Hz]
    extra3: float  # SYSTEM_TIME, EKF_STATUS_REPORT [Hz]
    rc_channels: float  # SERVO_OUTPUT_RAW [Hz]


@dataclass(frozen=True)
class MavlinkConfig:
    endpoints: tuple[str, ...]  # udpout:/udpin:/udp:/tcpin:/tcp:HOST:PORT, as ArduPilot SITL users write them
    port_stride: int  # boat k (0-based) uses each endpoint's port + k * port_stride; 0 shares [-]
    heartbeat_hz: float  # HEARTBEAT rate [Hz]
    streams: StreamRates
    signing_key: Path | None  # MAVLink 2 signing key file (docs/mavlink.md); null: unsigned, like a fresh autopilot


@dataclass(frozen=True)
class RecorderConfig:
    path: Path | None  # JSON-lines ground-truth log; null for none
    rate_hz: float  # ground-truth records per second per boat [Hz]


@dataclass(frozen=True)
class SitlConfig:
    seed: int  # seeds flow noise and sensor noise; same seed -> same run [-]
    count: int  # number of boats, system ids 1..count [-]
    speedup: float  # simulated seconds per wall second; 0 runs as fast as possible [-]
    physics_rate_hz: float  # fixed RK4 step rate [Hz]
    duration_s: float | None  # stop after this much simulated time; null runs until interrupted [s]
    unix_time_at_boot_s: float | None  # SYSTEM_TIME epoch at simulated t = 0; null = wall clock at start [s]
    start_poses: tuple[tuple[float, float, float], ...]  # per boat [N m, E m, heading deg]; [] = a row
    vehicle: VehicleKind  # the kind of every boat not listed in ``vehicles``
    vehicles: tuple[VehicleKind, ...]  # per boat (system ids 1..count); [] = all ``vehicle``
    vessel: VesselConfig
    flow: FlowConfig
    world: WorldConfig
    origin: OriginConfig
    sensors: SensorConfig
    autopilot: AutopilotConfig
    mavlink: MavlinkConfig
    recorder: RecorderConfig


def load(user_file: str | Path | None = None, overrides: Mapping[str, Any] | None = None) -> SitlConfig:
    """The simulator configuration: shipped defaults, then ``user_file``, then ``overrides``."""
    data = config_loader.load_layers("sitl", user_file, overrides or {})
    cfg = config_loader.build(SitlConfig, data)
    validate(cfg)
    return cfg


def validate(cfg: SitlConfig) -> None:
    """Reject well-typed but unusable values, naming the key and the value seen."""
    positive = {
        "count": cfg.count,
        "physics_rate_hz": cfg.physics_rate_hz,
        "vessel.hull.mass_kg": cfg.vessel.hull.mass_kg,
        "vessel.hull.yaw_inertia_kgm2": cfg.vessel.hull.yaw_inertia_kgm2,
        "vessel.thrusters.max_rate_rps": cfg.vessel.thrusters.max_rate_rps,
        "vessel.thrusters.time_constant_s": cfg.vessel.thrusters.time_constant_s,
        "sensors.position.rate_hz": cfg.sensors.position.rate_hz,
        "autopilot.control_rate_hz": cfg.autopilot.control_rate_hz,
        "mavlink.heartbeat_hz": cfg.mavlink.heartbeat_hz,
        "recorder.rate_hz": cfg.recorder.rate_hz,
        "flow.double_gyre.scale_m": cfg.flow.double_gyre.scale_m,
        "flow.vortex.core_radius_m": cfg.flow.vortex.core_radius_m,
    }
    for key, value in positive.items():
        if not value > 0:
            raise ConfigError(f"{key}: must be positive, got {value!r}")
    if cfg.count > 250:
        raise ConfigError(f"count: at most 250 boats (MAVLink system ids), got {cfg.count}")
    if cfg.speedup < 0:
        raise ConfigError(f"speedup: must be >= 0 (0 = as fast as possible), got {cfg.speedup!r}")
    if cfg.physics_rate_hz < 100:
        raise ConfigError(f"physics_rate_hz: must be >= 100 Hz, got {cfg.physics_rate_hz!r}")
    if cfg.start_poses and len(cfg.start_poses) != cfg.count:
        raise ConfigError(
            f"start_poses: {len(cfg.start_poses)} poses given for count = {cfg.count} boats "
            "(give one [N, E, heading_deg] per boat, or [] for an automatic row)"
        )
    if cfg.vehicles and len(cfg.vehicles) != cfg.count:
        raise ConfigError(
            f"vehicles: {len(cfg.vehicles)} kinds given for count = {cfg.count} boats "
            "(give one kind per boat, or [] for all `vehicle`)"
        )
    rudder, lateral = cfg.vessel.rudder, cfg.vessel.lateral_thrusters
    for key, value in (
        ("vessel.rudder.time_constant_s", rudder.time_constant_s),
        ("vessel.rudder.lift_slope_kgpm", rudder.lift_slope_kgpm),
        ("vessel.lateral_thrusters.max_thrust_n", lateral.max_thrust_n),
        ("vessel.lateral_thrusters.lever_m", lateral.lever_m),
    ):
        if not value > 0:
            raise ConfigError(f"{key}: must be positive, got {value!r}")
    if not 0.0 < rudder.max_angle_deg <= 60.0:
        raise ConfigError(f"vessel.rudder.max_angle_deg: must be in (0, 60] deg, got {rudder.max_angle_deg!r}")
    if not rudder.position_m < 0:
        raise ConfigError(f"vessel.rudder.position_m: the rudder must be aft (negative), got {rudder.position_m!r}")
    from sitl.parameters import check_config_params  # here: sitl.parameters imports this module

    check_config_params(cfg.autopilot.params)
    dropout = cfg.sensors.position.dropout_probability
    if not 0.0 <= dropout < 1.0:
        raise ConfigError(f"sensors.position.dropout_probability: must be in [0, 1), got {dropout!r}")
    if FlowKind.NONE in cfg.flow.kinds and len(cfg.flow.kinds) > 1:
        raise ConfigError(f"flow.kinds: 'none' cannot be combined with other kinds, got {_values(cfg.flow.kinds)}")
    for axis in ("north_m", "east_m"):
        lo, hi = getattr(cfg.world, axis)
        if not hi > lo:
            raise ConfigError(f"world.{axis}: max must exceed min, got [{lo}, {hi}]")
    if not cfg.mavlink.endpoints:
        raise ConfigError("mavlink.endpoints: at least one endpoint is needed")


def _values(kinds: tuple[FlowKind, ...]) -> list[str]:
    return [k.value for k in kinds]
