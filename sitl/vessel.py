"""Boat parameters and equations of motion: a 3-DOF manoeuvring model in Fossen's form.

Conventions (this module, all pure functions, no I/O):
  state x = (N, E, psi, u_r, v_r, r, actuators...), a tuple of floats (sitl.vehicles lists the actuator
  states per vehicle kind; the differential-thrust boat's are n = (n_port, n_stbd)):
    eta  = (N, E, psi): position in local NED [m], heading from north, clockwise seen from above [rad]
    nu_r = (u_r, v_r, r): velocity relative to the water in the body frame (surge forward, sway to
           starboard) [m/s], and yaw rate [rad/s]; nu = nu_r + nu_c is the velocity over ground
    n    = (n_port, n_stbd): propeller speeds [rev/s]
  current (flow) V_c = (V_cN, V_cE) in NED [m/s]; nu_c = (R(psi)^T V_c, 0) in the body frame.

Model (Fossen 2021, Handbook of Marine Craft Hydrodynamics and Motion Control, 2nd ed., ch. 6,
3-DOF manoeuvring model with the relative velocity nu_r = nu - nu_c):
    eta_dot = R(psi) (nu_r + nu_c)
    M nu_r_dot + C(nu_r) nu_r + D(nu_r) nu_r = tau,     M = M_RB + M_A
with the centre of gravity at the body origin (x_g = 0) and diagonal M, so that
    M = diag(m - X_udot, m - Y_vdot, I_z - N_rdot)
    C(nu_r) = C_RB + C_A = [[0, 0, -M22 v_r], [0, 0, M11 u_r], [M22 v_r, -M11 u_r, 0]]
    D(nu_r) = -diag(X_u + X_|u|u |u_r|, Y_v + Y_|v|v |v_r|, N_r + N_|r|r |r|)
The body force tau comes from the vehicle's actuators (sitl.vehicles); the default differential-thrust
boat has two stern thrusters at y = -l (port) and y = +l (starboard):
    T_i = k n_i |n_i|, k = k_fwd for n_i >= 0 else k_rev
    tau = (T_port + T_stbd, 0, l (T_port - T_stbd))
    n_i_dot = (n_cmd_i - n_i) / T_n      (first-order motor lag; n_cmd saturated at +-n_max)
With no thrust nu_r decays to zero, so the boat drifts at exactly the current.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sitl.config import VesselConfig

State = tuple[float, ...]  # (N, E, psi, u_r, v_r, r, actuator states...); 8 entries for diff thrust


@dataclass(frozen=True)
class VesselParams:
    """Coefficients of the equations of motion, derived once from the configuration."""

    m11: float  # M11 = m - X_udot [kg]
    m22: float  # M22 = m - Y_vdot [kg]
    m33: float  # M33 = I_z - N_rdot [kg m^2]
    x_u: float  # X_u [kg/s], negative
    y_v: float  # Y_v [kg/s], negative
    n_r: float  # N_r [kg m^2/s], negative
    x_uu: float  # X_|u|u [kg/m], <= 0
    y_vv: float  # Y_|v|v [kg/m], <= 0
    n_rr: float  # N_|r|r [kg m^2], <= 0
    k_forward: float  # thrust coefficient for n >= 0 [N/(rev/s)^2]
    k_reverse: float  # thrust coefficient for n < 0 [N/(rev/s)^2]
    n_max: float  # propeller speed saturation [rev/s]
    lever_m: float  # l, lateral offset of each thruster [m]
    motor_time_constant_s: float  # T_n [s]
    length_m: float  # hull length [m]
    beam_m: float  # hull beam [m]

    @classmethod
    def from_config(cls, cfg: VesselConfig) -> VesselParams:
        h, t = cfg.hull, cfg.thrusters
        m11 = h.mass_kg - h.added_mass_surge_kg
        m22 = h.mass_kg - h.added_mass_sway_kg
        m33 = h.yaw_inertia_kgm2 - h.added_inertia_yaw_kgm2
        for name, value in (("M11", m11), ("M22", m22), ("M33", m33)):
            if not value > 0:
                raise ValueError(f"vessel.hull: mass matrix entry {name} = {value} must be positive")
        return cls(
            m11=m11,
            m22=m22,
            m33=m33,
            x_u=h.linear_damping_surge_kgps,
            y_v=h.linear_damping_sway_kgps,
            n_r=h.linear_damping_yaw_kgm2ps,
            x_uu=h.quadratic_damping_surge_kgpm,
            y_vv=h.quadratic_damping_sway_kgpm,
            n_rr=h.quadratic_damping_yaw_kgm2,
            k_forward=t.max_forward_thrust_n / t.max_rate_rps**2,
            k_reverse=t.max_reverse_thrust_n / t.max_rate_rps**2,
            n_max=t.max_rate_rps,
            lever_m=t.lateral_offset_m,
            motor_time_constant_s=t.time_constant_s,
            length_m=h.length_m,
            beam_m=h.beam_m,
        )


def thrust(n: float, p: VesselParams) -> float:
    """Thrust of one propeller turning at n [rev/s]: T = k n |n| with forward/reverse asymmetry [N]."""
    return (p.k_forward if n >= 0.0 else p.k_reverse) * n * abs(n)


def propeller_command(command: float, p: VesselParams) -> float:
    """Propeller speed demand [rev/s] for a normalised command in [-1, 1] (saturated).

    The square root makes steady thrust proportional to the command (ArduPilot's MOT_THST_EXPO = 1):
    command 1 -> full forward thrust, -1 -> full reverse thrust.
    """
    c = min(1.0, max(-1.0, command))
    return math.copysign(p.n_max * math.sqrt(abs(c)), c)


def rigid_body_derivative(
    x: tuple[float, ...], tau: tuple[float, float, float], vc_n: float, vc_e: float, p: VesselParams
) -> tuple[float, float, float, float, float, float]:
    """(eta_dot, nu_r_dot) for the first six state entries, a body force tau = (X [N], Y [N], N [N m]).

    Fossen (2021) ch. 6: eta_dot = R(psi) nu, M nu_r_dot = tau - C(nu_r) nu_r - D(nu_r) nu_r.
    """
    psi, ur, vr, r = x[2], x[3], x[4], x[5]
    c = math.cos(psi)
    s = math.sin(psi)
    # nu = nu_r + nu_c, with nu_c = R(psi)^T V_c (irrotational current, no yaw component)
    u = ur + c * vc_n + s * vc_e
    v = vr - s * vc_n + c * vc_e
    tx, ty, tn = tau
    # M nu_r_dot = tau - C(nu_r) nu_r + (linear + quadratic damping terms, which are negative)
    ur_dot = (tx + p.m22 * vr * r + (p.x_u + p.x_uu * abs(ur)) * ur) / p.m11
    vr_dot = (ty - p.m11 * ur * r + (p.y_v + p.y_vv * abs(vr)) * vr) / p.m22
    r_dot = (tn - (p.m22 - p.m11) * ur * vr + (p.n_r + p.n_rr * abs(r)) * r) / p.m33
    return (c * u - s * v, s * u + c * v, r, ur_dot, vr_dot, r_dot)


def state_derivative(
    x: State, n_cmd_port: float, n_cmd_stbd: float, vc_n: float, vc_e: float, p: VesselParams
) -> State:
    """x_dot of the differential-thrust boat for propeller demands [rev/s] and the current [m/s].

    tau = (T_port + T_stbd, 0, l (T_port - T_stbd)); n_i_dot = (n_cmd_i - n_i) / T_n.
    """
    n1, n2 = x[6], x[7]
    t1 = thrust(n1, p)
    t2 = thrust(n2, p)
    body = rigid_body_derivative(x, (t1 + t2, 0.0, p.lever_m * (t1 - t2)), vc_n, vc_e, p)
    return (
        *body,
        (n_cmd_port - n1) / p.motor_time_constant_s,
        (n_cmd_stbd - n2) / p.motor_time_constant_s,
    )


def ground_velocity(x: State, vc_n: float, vc_e: float) -> tuple[float, float]:
    """Velocity over ground in NED (V_N, V_E) [m/s]: R(psi) nu_r + V_c."""
    psi, ur, vr = x[2], x[3], x[4]
    c = math.cos(psi)
    s = math.sin(psi)
    return c * ur - s * vr + vc_n, s * ur + c * vr + vc_e


def body_velocity(x: State, vc_n: float, vc_e: float) -> tuple[float, float]:
    """Velocity over ground in the body frame (u, v) [m/s]: nu_r + nu_c."""
    psi = x[2]
    c = math.cos(psi)
    s = math.sin(psi)
    return x[3] + c * vc_n + s * vc_e, x[4] - s * vc_n + c * vc_e


def steady_surge_speed(p: VesselParams, thrust_total_n: float) -> float:
    """Calm-water speed where surge damping balances a constant total thrust [m/s] (for checks)."""
    if p.x_uu == 0.0:
        return -thrust_total_n / p.x_u
    # -(X_u + X_|u|u u) u = T for u >= 0: X_|u|u u^2 + X_u u + T = 0
    a, b, c = -p.x_uu, -p.x_u, -thrust_total_n
    return (-b + math.sqrt(b * b - 4 * a * c)) / (2 * a)


def steady_turn_rate(p: VesselParams, moment_nm: float) -> float:
    """Yaw rate where yaw damping balances a constant moment with no surge/sway [rad/s] (for checks)."""
    if p.n_rr == 0.0:
        return -moment_nm / p.n_r
    a, b, c = -p.n_rr, -p.n_r, -abs(moment_nm)
    return math.copysign((-b + math.sqrt(b * b - 4 * a * c)) / (2 * a), moment_nm)
