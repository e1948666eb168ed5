"""The simulator's typed configuration: frozen dataclasses built from ``config/sitl.yaml``.

Defaults live only in ``config/sitl.yaml`` (``koopguide/defaults/sitl.yaml``); these classes carry the
types, the units and each number's interval, declared once in its type (``Annotated[float, Range(...)]``)
and checked while loading by :func:`koopguide.base.config.build`, NaN and infinity included.
``__post_init__`` checks only relations between keys. :func:`load` layers the shipped defaults, an
optional user file and explicit overrides, and rejects unknown, ill-typed or out-of-range keys with a
one-line :class:`koopguide.base.config.ConfigError` naming the key and the value seen.

The autopilot's parameters (:class:`AutopilotParams`) also carry their ArduPilot Rover names in the
field metadata; :mod:`sitl.parameters` serves them over PARAM_* and checks PARAM_SET against the same
intervals.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

from koopguide.base import config as config_loader
from koopguide.base.config import ConfigError, Range, check
from koopguide.mavlink.rover import SIMULATED_MODES

# Intervals shared by several keys (closed ends unless marked open).
Hertz = Annotated[float, Range(0.0, 1000.0, lo_open=True)]  # an update rate, (0, 1000] [Hz]
StreamHz = Annotated[float, Range(0.0, 1000.0)]  # a telemetry stream rate, 0 = off [Hz]
Lag = Annotated[float, Range(0.0, 60.0, lo_open=True)]  # a first-order actuator lag [s]
Correlation = Annotated[float, Range(0.0, 1e5, lo_open=True)]  # a Gauss-Markov correlation time, < ~1 day [s]
Speed = Annotated[float, Range(0.0, 20.0)]  # a water or boat speed [m/s]
SignedSpeed = Annotated[float, Range(-20.0, 20.0)]  # a speed scale whose sign sets a direction [m/s]
Coordinate = Annotated[float, Range(-5e4, 5e4)]  # a local NED coordinate, within 50 km of the origin [m]
Heading = Annotated[float, Range(-360.0, 360.0)]  # a compass angle [deg]
Length = Annotated[float, Range(0.0, 100.0, lo_open=True)]  # a hull dimension or lever [m]
Thrust = Annotated[float, Range(0.0, 1e5, lo_open=True)]  # an actuator force [N]
# Fossen (2021) ch. 6 hydrodynamic derivatives: added mass and damping oppose motion, so they are
# negative (a positive one would feed energy in); bounded at a generous multiple of the largest hull here.
AddedMass = Annotated[float, Range(-1e6, 0.0)]  # X_udot, Y_vdot [kg]; N_rdot [kg m^2]
LinearDamping = Annotated[float, Range(-1e7, 0.0, hi_open=True)]  # X_u, Y_v [kg/s]; N_r [kg m^2/s]
QuadraticDamping = Annotated[float, Range(-1e7, 0.0)]  # X_|u|u, Y_|v|v [kg/m]; N_|r|r [kg m^2]
Gain = Annotated[float, Range(0.0, 100.0)]  # an ArduPilot controller gain [its unit]
TurnRateCap = Annotated[float, Range(0.0, 1000.0, lo_open=True)]  # an ArduPilot turn-rate limit [deg/s]


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


#: The Rover modes (koopguide.mavlink.rover, the one table of mode numbers) that the simulator implements,
#: by name: the values ``autopilot.initial_mode`` may take.
SimulatedMode = enum.Enum("SimulatedMode", {m.name: m.name for m in SIMULATED_MODES})


@dataclass(frozen=True)
class HullConfig:
    mass_kg: Annotated[float, Range(0.0, 1e4, lo_open=True)]  # m, rigid-body mass [kg]
    yaw_inertia_kgm2: Annotated[float, Range(0.0, 1e6, lo_open=True)]  # I_z about body z through the CG [kg m^2]
    length_m: Length  # hull length overall [m]; also the wall contact margin (half of it)
    beam_m: Length  # hull width [m]; the wall contact margin across (half of it)
    added_mass_surge_kg: AddedMass  # X_udot [kg], negative by Fossen's sign convention
    added_mass_sway_kg: AddedMass  # Y_vdot [kg], negative
    added_inertia_yaw_kgm2: AddedMass  # N_rdot [kg m^2], negative
    linear_damping_surge_kgps: LinearDamping  # X_u [kg/s], negative
    linear_damping_sway_kgps: LinearDamping  # Y_v [kg/s], negative
    linear_damping_yaw_kgm2ps: LinearDamping  # N_r [kg m^2/s], negative
    quadratic_damping_surge_kgpm: QuadraticDamping  # X_|u|u [kg/m], negative or zero
    quadratic_damping_sway_kgpm: QuadraticDamping  # Y_|v|v [kg/m], negative or zero
    quadratic_damping_yaw_kgm2: QuadraticDamping  # N_|r|r [kg m^2], negative or zero


@dataclass(frozen=True)
class ThrusterConfig:
    max_rate_rps: Annotated[float, Range(0.0, 1000.0, lo_open=True)]  # n_max, propeller speed at full command [rev/s]
    max_forward_thrust_n: Thrust  # thrust of one thruster at +n_max [N]
    max_reverse_thrust_n: Annotated[float, Range(0.0, 1e5)]  # thrust magnitude of one thruster at -n_max [N]
    lateral_offset_m: Length  # l, each thruster's distance from the centre line [m]
    time_constant_s: Lag  # T_n, first-order motor lag [s]


@dataclass(frozen=True)
class RudderConfig:
    """The rudder boat: one centreline propeller with the pair's total thrust, and a stern rudder."""

    max_angle_deg: Annotated[float, Range(0.0, 60.0, lo_open=True)]  # rudder deflection at full command [deg]
    time_constant_s: Lag  # first-order lag of the rudder servo [s]
    lift_slope_kgpm: Annotated[float, Range(0.0, 1e5, lo_open=True)]  # Y_delta = 1/2 rho A_R C_L_alpha [kg/m]
    position_m: Annotated[float, Range(-100.0, 0.0, hi_open=True)]  # x_R along body x; aft, so negative [m]


@dataclass(frozen=True)
class LateralThrusterConfig:
    """The vectored boat's bow and stern tunnel thrusters (sway force and yaw moment)."""

    max_thrust_n: Thrust  # thrust of one tunnel thruster at full command, either way [N]
    lever_m: Length  # distance of each tunnel thruster from the centre of gravity along x [m]


@dataclass(frozen=True)
class VesselConfig:
    hull: HullConfig
    thrusters: ThrusterConfig
    rudder: RudderConfig
    lateral_thrusters: LateralThrusterConfig


@dataclass(frozen=True)
class UniformFlowConfig:
    speed_mps: Speed  # mean current speed [m/s]
    direction_deg: Heading  # compass direction the water flows toward (0 = north, 90 = east) [deg]
    drift_std_mps: Speed  # stationary std of the slow Gauss-Markov drift of each component [m/s]
    drift_time_constant_s: Correlation  # 1/mu of the Gauss-Markov drift [s]


@dataclass(frozen=True)
class VortexConfig:
    center_ned_m: tuple[Coordinate, Coordinate]  # vortex centre [N, E] in local NED [m]
    circulation_m2ps: Annotated[float, Range(-1e3, 1e3)]  # Gamma; positive = counter-clockwise from above [m^2/s]
    core_radius_m: Annotated[float, Range(0.0, 1e4, lo_open=True)]  # r_c of the Lamb-Oseen core [m]


@dataclass(frozen=True)
class DoubleGyreConfig:
    origin_ned_m: tuple[Coordinate, Coordinate]  # corner of the [0, 2s] x [0, s] domain in local NED [m]
    amplitude_mps: SignedSpeed  # A; the peak speed is about pi A (1 + 2 eps); negative turns the gyres back [m/s]
    epsilon: Annotated[float, Range(-1.0, 1.0)]  # eps, amplitude of the gyre boundary oscillation [-]
    omega_radps: Annotated[float, Range(-100.0, 100.0)]  # omega of the boundary oscillation [rad/s]
    scale_m: Annotated[float, Range(0.0, 1e4, lo_open=True)]  # s, the domain spans 2s north and s east [m]
    dissipation_per_s: Annotated[float, Range(0.0, 100.0)]  # mu of the -mu x term; 0 = divergence-free [1/s]


@dataclass(frozen=True)
class GustConfig:
    std_mps: Speed  # stationary std of each gust velocity component [m/s]
    time_constant_s: Correlation  # correlation time of the Ornstein-Uhlenbeck gusts [s]


@dataclass(frozen=True)
class FlowConfig:
    kinds: tuple[FlowKind, ...]  # flow components summed; [] or [none] for calm water
    uniform: UniformFlowConfig
    vortex: VortexConfig
    double_gyre: DoubleGyreConfig
    gusts: GustConfig

    def __post_init__(self) -> None:
        if FlowKind.NONE in self.kinds and len(self.kinds) > 1:
            raise ConfigError(
                f"flow.kinds: 'none' cannot be combined with other kinds, got {[k.value for k in self.kinds]}"
            )


@dataclass(frozen=True)
class WorldConfig:
    walls: bool  # confine the boats to the tank rectangle
    north_m: tuple[Coordinate, Coordinate]  # tank extent along north [min, max] in local NED [m]
    east_m: tuple[Coordinate, Coordinate]  # tank extent along east [min, max] in local NED [m]

    def __post_init__(self) -> None:
        for axis in ("north_m", "east_m"):
            lo, hi = getattr(self, axis)
            check(hi > lo, f"world.{axis}", [lo, hi], "[min, max] with max > min")


@dataclass(frozen=True)
class OriginConfig:
    latitude_deg: Annotated[float, Range(-90.0, 90.0)]  # geodetic latitude of the local NED origin [deg]
    longitude_deg: Annotated[float, Range(-180.0, 180.0)]  # geodetic longitude of the local NED origin [deg]
    altitude_m: Annotated[float, Range(-1e3, 1e4)]  # altitude of the water surface above mean sea level [m]


@dataclass(frozen=True)
class PositionSensorConfig:
    rate_hz: Hertz  # position/velocity fixes per second (motion capture or GPS) [Hz]
    noise_std_m: Annotated[float, Range(0.0, 100.0)]  # white position noise per axis [m]
    velocity_noise_std_mps: Speed  # white velocity noise per axis [m/s]
    latency_s: Annotated[float, Range(0.0, 10.0)]  # delay from measurement to availability [s]
    dropout_probability: Annotated[float, Range(0.0, 1.0, hi_open=True)]  # chance that a fix is lost [-]
    unhealthy_after_s: Annotated[float, Range(0.0, 3600.0, lo_open=True)]  # no fix this long -> unhealthy [s]


@dataclass(frozen=True)
class HeadingSensorConfig:
    noise_std_deg: Annotated[float, Range(0.0, 180.0)]  # white heading noise [deg]
    rate_noise_std_degps: Annotated[float, Range(0.0, 1000.0)]  # white yaw-rate noise [deg/s]


@dataclass(frozen=True)
class SensorConfig:
    position: PositionSensorConfig
    heading: HeadingSensorConfig


def ardupilot(name: str, *, integer: bool = False) -> dict[str, Any]:
    """Metadata of an :class:`AutopilotParams` field: its ArduPilot name, whether an enumeration."""
    return {"ardupilot": name, "integer": integer}


@dataclass(frozen=True)
class AutopilotParams:
    """Parameters served over PARAM_* under their ArduPilot Rover names (see sitl.autopilot).

    Each field's interval checks both the configuration and PARAM_SET (:mod:`sitl.parameters`); the
    field order is the PARAM_VALUE index. Intervals follow ArduPilot's documented ``@Range`` where that
    makes sense for a 0.4 m boat, widened for the gains (the defaults are tuned for this simulator's
    miniature hull, not for ArduPilot's), and narrowed where a value would make the controller divide
    by zero or drive astern (WP_SPEED >= 0, ATC_STR_RAT_MAX > 0).
    """

    # GUID_TIMEOUT: guided setpoint timeout [s]
    guid_timeout_s: Annotated[float, Range(0.1, 5.0)] = field(metadata=ardupilot("GUID_TIMEOUT"))
    # WP_SPEED: speed cap for guided/loiter/RTL [m/s]
    wp_speed_mps: Annotated[float, Range(0.0, 100.0)] = field(metadata=ardupilot("WP_SPEED"))
    # CRUISE_SPEED: speed reached at CRUISE_THROTTLE; 0 = no feed-forward [m/s]
    cruise_speed_mps: Annotated[float, Range(0.0, 100.0)] = field(metadata=ardupilot("CRUISE_SPEED"))
    # CRUISE_THROTTLE: throttle for CRUISE_SPEED [%]
    cruise_throttle_pct: Annotated[float, Range(0.0, 100.0)] = field(metadata=ardupilot("CRUISE_THROTTLE"))
    speed_p: Gain = field(metadata=ardupilot("ATC_SPEED_P"))  # speed error -> throttle [1/(m/s)]
    speed_i: Gain = field(metadata=ardupilot("ATC_SPEED_I"))  # integrated speed error -> throttle [1/m]
    steer_rate_ff: Gain = field(metadata=ardupilot("ATC_STR_RAT_FF"))  # turn rate -> steering [1/(rad/s)]
    steer_rate_p: Gain = field(metadata=ardupilot("ATC_STR_RAT_P"))  # turn-rate error -> steering [1/(rad/s)]
    steer_rate_i: Gain = field(metadata=ardupilot("ATC_STR_RAT_I"))  # integrated turn-rate error -> steering [1/rad]
    # ATC_STR_RAT_MAX: turn-rate cap [deg/s]
    steer_rate_max_degps: TurnRateCap = field(metadata=ardupilot("ATC_STR_RAT_MAX"))
    steer_angle_p: Gain = field(metadata=ardupilot("ATC_STR_ANG_P"))  # heading error -> desired turn rate [1/s]
    # WP_PIVOT_ANGLE: skid steering pivots beyond this heading error; 0 = never [deg]
    pivot_angle_deg: Annotated[float, Range(0.0, 360.0)] = field(metadata=ardupilot("WP_PIVOT_ANGLE"))
    # WP_PIVOT_RATE: turn-rate cap while pivoting [deg/s]
    pivot_rate_degps: TurnRateCap = field(metadata=ardupilot("WP_PIVOT_RATE"))
    # WP_RADIUS: a guided position target is reached within this distance [m]
    wp_radius_m: Annotated[float, Range(0.0, 1000.0)] = field(metadata=ardupilot("WP_RADIUS"))
    # LOIT_RADIUS: no correction inside this distance [m]
    loiter_radius_m: Annotated[float, Range(0.0, 20.0)] = field(metadata=ardupilot("LOIT_RADIUS"))
    # LOIT_SPEED_GAIN: distance beyond the radius -> speed [1/s]
    loiter_speed_gain: Annotated[float, Range(0.0, 5.0)] = field(metadata=ardupilot("LOIT_SPEED_GAIN"))
    # LOIT_TYPE: 0 forward or reverse, 1 forward only, 2 reverse only [-]
    loiter_type: Annotated[int, Range(0, 2)] = field(metadata=ardupilot("LOIT_TYPE", integer=True))
    # ATC_DECEL_MAX: deceleration used to place the stopping point [m/s^2]
    decel_max_mps2: Annotated[float, Range(0.0, 10.0, lo_open=True)] = field(metadata=ardupilot("ATC_DECEL_MAX"))


@dataclass(frozen=True)
class AutopilotConfig:
    initial_mode: SimulatedMode  # mode at boot (ArduPilot INITIAL_MODE)
    start_armed: bool  # boot armed (tests and scripted runs; ArduPilot boots disarmed)
    control_rate_hz: Hertz  # heading/speed controller rate [Hz]
    params: AutopilotParams


@dataclass(frozen=True)
class StreamRates:
    """MAVLink stream groups (REQUEST_DATA_STREAM ids) and their default rates per link, 0 = off [Hz]."""

    extended_status: StreamHz  # SYS_STATUS, GPS_RAW_INT [Hz]
    position: StreamHz  # GLOBAL_POSITION_INT, LOCAL_POSITION_NED [Hz]
    extra1: StreamHz  # ATTITUDE [Hz]
    extra2: StreamHz  # VFR_HUD [Hz]
    extra3: StreamHz  # SYSTEM_TIME, EKF_STATUS_REPORT [Hz]
    rc_channels: StreamHz  # SERVO_OUTPUT_RAW [Hz]


@dataclass(frozen=True)
class MavlinkConfig:
    endpoints: tuple[str, ...]  # udpout:/udpin:/udp:/tcpin:/tcp:HOST:PORT, as ArduPilot SITL users write them
    port_stride: Annotated[int, Range(0, 65535)]  # boat k (0-based) uses each endpoint's port + k * port_stride [-]
    heartbeat_hz: Hertz  # HEARTBEAT rate [Hz]
    streams: StreamRates
    signing_key: Path | None  # MAVLink 2 signing key file (docs/mavlink.md); null: unsigned, like a fresh autopilot

    def __post_init__(self) -> None:
        if not self.endpoints:
            raise ConfigError("mavlink.endpoints: at least one endpoint is needed, got []")


@dataclass(frozen=True)
class RecorderConfig:
    path: Path | None  # JSON-lines ground-truth log; null for none
    rate_hz: Hertz  # ground-truth records per second per boat [Hz]


@dataclass(frozen=True)
class SitlConfig:
    seed: Annotated[int, Range(0, 2**32 - 1)]  # seeds flow noise and sensor noise; same seed -> same run [-]
    count: Annotated[int, Range(1, 250)]  # number of boats, MAVLink system ids 1..count [-]
    speedup: Annotated[float, Range(0.0, 1000.0)]  # simulated seconds per wall second; 0 = as fast as possible [-]
    physics_rate_hz: Annotated[float, Range(100.0, 1000.0)]  # fixed RK4 step rate [Hz]
    # stop after this much simulated time (at most ~115 days); null runs until interrupted [s]
    duration_s: Annotated[float, Range(0.0, 1e7, lo_open=True)] | None
    # SYSTEM_TIME epoch at simulated t = 0; null = wall clock at start [s]
    unix_time_at_boot_s: Annotated[float, Range(0.0, 1e10)] | None
    start_poses: tuple[tuple[Coordinate, Coordinate, Heading], ...]  # per boat [N m, E m, heading deg]; [] = a row
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

    def __post_init__(self) -> None:
        if self.start_poses and len(self.start_poses) != self.count:
            raise ConfigError(
                f"start_poses: {len(self.start_poses)} poses given for count = {self.count} boats "
                "(give one [N, E, heading_deg] per boat, or [] for an automatic row)"
            )
        if self.vehicles and len(self.vehicles) != self.count:
            raise ConfigError(
                f"vehicles: {len(self.vehicles)} kinds given for count = {self.count} boats "
                "(give one kind per boat, or [] for all `vehicle`)"
            )
        # Everything else runs on physics steps: a faster rate would silently become the step rate.
        for key, rate in (
            ("autopilot.control_rate_hz", self.autopilot.control_rate_hz),
            ("sensors.position.rate_hz", self.sensors.position.rate_hz),
            ("recorder.rate_hz", self.recorder.rate_hz),
        ):
            check(rate <= self.physics_rate_hz, key, rate, f"<= physics_rate_hz ({self.physics_rate_hz:g} Hz)")
        # The walls keep the hull's centre half a length inside (sitl.world.Tank): the tank must be longer.
        length = self.vessel.hull.length_m
        for axis in ("north_m", "east_m"):
            lo, hi = getattr(self.world, axis)
            if self.world.walls and not hi - lo > length:
                raise ConfigError(
                    f"world.{axis}: [{lo:g}, {hi:g}] spans {hi - lo:g} m, not more than the hull "
                    f"(vessel.hull.length_m = {length:g} m); enlarge the tank or set world.walls: false"
                )


def load(user_file: str | Path | None = None, overrides: Mapping[str, Any] | None = None) -> SitlConfig:
    """The simulator configuration: shipped defaults, then ``user_file``, then ``overrides``; checked."""
    return config_loader.build(SitlConfig, config_loader.load_layers("sitl", user_file, overrides or {}))
