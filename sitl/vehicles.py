"""The vehicle family: how each kind of boat turns normalised commands into a body force tau.

All kinds share the hull and its equations of motion (sitl.vessel, Fossen (2021) ch. 6); they differ in
their actuators (Fossen (2021) ch. 9, control forces and moments). Pure functions, no I/O.

Conventions: the state is x = (N, E, psi, u_r, v_r, r, a_1..a_k) as in sitl.vessel, with the actuator
states a_i below; commands are normalised in [-1, 1]; tau = (X [N], Y [N], N [N m]) in body axes (x
forward, y to starboard, yaw clockwise seen from above). Every actuator follows its demand with a
first-order lag, a_dot = (a_cmd - a) / T.

- DIFF_THRUST, commands (port, stbd), actuators (n_port, n_stbd) [rev/s]:
      tau = (T_p + T_s, 0, l (T_p - T_s)),  T = k n|n| (k_fwd / k_rev)
  It turns on the spot (a pivot) with one thruster ahead and one astern.
- RUDDER, commands (throttle, rudder), actuators (n, delta) [rev/s, rad]: one centreline propeller with
  the pair's total thrust (k = 2 k_pair) and a rudder at x_R < 0 with linear lift in delta,
      Y_R = -Y_delta u_r |u_r| delta,  X_R = Y_R sin(delta),  N_R = x_R Y_R,
      tau = (T + X_R, Y_R, N_R)
  The rudder force grows with the speed through the water u_r; there is no slipstream term, so with
  no way through the water the boat cannot turn.
- VECTORED, commands (port, stbd, bow, stern), actuators (n_port, n_stbd, n_bow, n_stern) [rev/s]: the
  thruster pair plus tunnel thrusters at x = +x_L (bow) and x = -x_L (stern), symmetric thrust T_L,
      tau = (T_p + T_s, T_b + T_t, l (T_p - T_s) + x_L (T_b - T_t))
  It can push sideways (both tunnel thrusters the same way) and turn on the spot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sitl.config import VehicleKind, VesselConfig
from sitl.vessel import State, VesselParams, propeller_command, rigid_body_derivative, thrust

ACTUATOR_COUNT = {VehicleKind.DIFF_THRUST: 2, VehicleKind.RUDDER: 2, VehicleKind.VECTORED: 4}


@dataclass(frozen=True)
class RudderParams:
    max_angle_rad: float  # rudder deflection at full command [rad]
    time_constant_s: float  # rudder servo lag [s]
    lift_slope_kgpm: float  # Y_delta, sway force per (m/s)^2 per rad [kg/m]
    position_m: float  # x_R along the body x axis, negative = aft [m]
    k_forward: float  # single propeller, n >= 0 [N/(rev/s)^2]
    k_reverse: float  # single propeller, n < 0 [N/(rev/s)^2]


@dataclass(frozen=True)
class LateralParams:
    k: float  # tunnel thruster coefficient, either way [N/(rev/s)^2]
    lever_m: float  # x_L, distance of each tunnel thruster from the centre of gravity [m]


@dataclass(frozen=True)
class VehicleParams:
    kind: VehicleKind
    hull: VesselParams  # hull coefficients and the stern thruster pair
    rudder: RudderParams
    lateral: LateralParams

    @classmethod
    def from_config(cls, cfg: VesselConfig, kind: VehicleKind) -> VehicleParams:
        hull = VesselParams.from_config(cfg)
        r, lat = cfg.rudder, cfg.lateral_thrusters
        return cls(
            kind=kind,
            hull=hull,
            rudder=RudderParams(
                max_angle_rad=math.radians(r.max_angle_deg),
                time_constant_s=r.time_constant_s,
                lift_slope_kgpm=r.lift_slope_kgpm,
                position_m=r.position_m,
                k_forward=2.0 * hull.k_forward,
                k_reverse=2.0 * hull.k_reverse,
            ),
            lateral=LateralParams(k=lat.max_thrust_n / hull.n_max**2, lever_m=lat.lever_m),
        )

    @property
    def actuator_count(self) -> int:
        return ACTUATOR_COUNT[self.kind]


def initial_actuators(p: VehicleParams) -> tuple[float, ...]:
    """Actuator states at rest."""
    return (0.0,) * p.actuator_count


def actuator_demands(commands: tuple[float, ...], p: VehicleParams) -> tuple[float, ...]:
    """Demanded actuator states for normalised commands in [-1, 1] (saturated)."""
    if len(commands) != p.actuator_count:
        raise ValueError(f"{p.kind.value}: {p.actuator_count} commands expected, got {len(commands)}")
    if p.kind is VehicleKind.RUDDER:
        throttle, rudder = commands
        n = propeller_command(throttle, p.hull)
        return n, min(1.0, max(-1.0, rudder)) * p.rudder.max_angle_rad
    return tuple(propeller_command(c, p.hull) for c in commands)


def _rudder_thrust(n: float, p: VehicleParams) -> float:
    return (p.rudder.k_forward if n >= 0.0 else p.rudder.k_reverse) * n * abs(n)


def body_force(x: State, p: VehicleParams) -> tuple[float, float, float]:
    """tau = (X [N], Y [N], N [N m]) from the actuator states in x (see the module docstring)."""
    h = p.hull
    if p.kind is VehicleKind.RUDDER:
        n, delta = x[6], x[7]
        ur = x[3]
        side = -p.rudder.lift_slope_kgpm * ur * abs(ur) * delta  # Y_R, linear lift in delta
        return _rudder_thrust(n, p) + side * math.sin(delta), side, p.rudder.position_m * side
    t_port, t_stbd = thrust(x[6], h), thrust(x[7], h)
    surge, yaw = t_port + t_stbd, h.lever_m * (t_port - t_stbd)
    if p.kind is VehicleKind.DIFF_THRUST:
        return surge, 0.0, yaw
    k = p.lateral.k
    t_bow, t_stern = k * x[8] * abs(x[8]), k * x[9] * abs(x[9])
    return surge, t_bow + t_stern, yaw + p.lateral.lever_m * (t_bow - t_stern)


def derivative(x: State, demands: tuple[float, ...], vc_n: float, vc_e: float, p: VehicleParams) -> State:
    """x_dot for the state x, actuator demands and the current (vc_n, vc_e) at the boat [m/s]."""
    body = rigid_body_derivative(x, body_force(x, p), vc_n, vc_e, p.hull)
    lags = [p.hull.motor_time_constant_s] * p.actuator_count
    if p.kind is VehicleKind.RUDDER:
        lags[1] = p.rudder.time_constant_s
    rates = tuple((d - a) / lag for d, a, lag in zip(demands, x[6:], lags, strict=True))
    return (*body, *rates)


def thrusts(x: State, p: VehicleParams) -> tuple[float, ...]:
    """Thrust of each propeller [N]: (port, stbd), (centre,), or (port, stbd, bow, stern)."""
    if p.kind is VehicleKind.RUDDER:
        return (_rudder_thrust(x[6], p),)
    out = (thrust(x[6], p.hull), thrust(x[7], p.hull))
    if p.kind is VehicleKind.VECTORED:
        k = p.lateral.k
        out += (k * x[8] * abs(x[8]), k * x[9] * abs(x[9]))
    return out
