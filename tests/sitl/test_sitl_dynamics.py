"""Boat dynamics: the Fossen 3-DOF model with thrusters, integrated by RK4, against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitl.boat import Boat
from sitl.flow import Flow
from sitl.integrate import rk4_step
from sitl.vehicles import VehicleParams
from sitl.vessel import (
    propeller_command,
    state_derivative,
    steady_surge_speed,
    steady_turn_rate,
    thrust,
)
from sitl.world import Tank
from tests.support.sitl_gcs import sim_config

DT = 0.01


def make_boat(overrides=None, pose=(2.25, 1.5, 0.0)):
    cfg = sim_config({"world": {"walls": False}, **(overrides or {})})
    vehicle = VehicleParams.from_config(cfg.vessel, cfg.vehicle)
    flow = Flow(cfg.flow, np.random.default_rng(0))
    boat = Boat(1, cfg, vehicle, flow, Tank(cfg.world, 0.2), pose, np.random.default_rng(1))
    return boat, flow, vehicle.hull


def run(boat, flow, seconds, commands=None):
    """Step the boat with fixed thruster commands; returns the trajectory of states."""
    if commands is not None:
        boat.autopilot.commands = commands
    states = []
    for _ in range(round(seconds / DT)):
        boat.physics_step(boat.t, DT)
        flow.advance(DT)
        states.append((boat.t, *boat.state))
    return np.array(states)


def test_full_thrust_reaches_the_configured_top_speed_in_calm_water():
    boat, flow, p = make_boat()
    traj = run(boat, flow, 15.0, (1.0, 1.0))
    u = traj[:, 4]
    assert steady_surge_speed(p, 2 * 0.15) == pytest.approx(0.4)
    assert u[-1] == pytest.approx(0.4, abs=1e-3)  # 2 x 0.15 N against X_u = -0.75 kg/s
    # 63 % rise time ~ (m - X_udot) / |X_u| = 1.47 s, plus the motor lag
    t63 = traj[np.argmax(u >= 0.63 * u[-1]), 0]
    assert 1.3 < t63 < 1.7
    # columns: t, N, E, psi, u_r, v_r, r, n_port, n_stbd
    assert traj[-1, 2] == 1.5 and traj[-1, 3] == 0.0 and traj[-1, 5] == 0.0  # straight north, no sway


def test_reverse_thrust_is_weaker_than_forward():
    boat, flow, p = make_boat()
    traj = run(boat, flow, 15.0, (-1.0, -1.0))
    assert traj[-1, 4] == pytest.approx(-2 * 0.09 / 0.75, abs=1e-3)
    assert thrust(-p.n_max, p) == pytest.approx(-0.09) and thrust(p.n_max, p) == pytest.approx(0.15)


def test_thrust_is_proportional_to_command_and_saturates():
    _, _, p = make_boat()
    for c in (0.1, 0.5, 1.0):
        assert thrust(propeller_command(c, p), p) == pytest.approx(0.15 * c)
    assert propeller_command(3.0, p) == p.n_max


def test_differential_thrust_turns_to_starboard_at_the_balanced_rate():
    boat, flow, p = make_boat()
    traj = run(boat, flow, 30.0, (1.0, -1.0))  # port ahead, starboard astern: pure yaw moment
    r = traj[:, 6]
    moment = p.lever_m * (0.15 + 0.09)
    expected = steady_turn_rate(p, moment)  # N_r r + N_|r|r |r| r = l (T_port - T_stbd)
    assert r[-1] > 0  # clockwise seen from above = to starboard
    assert r[-1] == pytest.approx(expected, rel=0.02)
    assert math.degrees(expected) == pytest.approx(7.6, abs=0.2)
    # the forward/reverse asymmetry leaves a net surge force: the boat creeps ahead while turning
    assert traj[-1, 4] > 0


def test_motor_lag_is_first_order_with_the_configured_time_constant():
    boat, flow, p = make_boat()
    traj = run(boat, flow, 0.05, (1.0, 1.0))  # one time constant
    assert traj[-1, 7] == pytest.approx(p.n_max * (1 - math.exp(-1)), rel=0.01)


@pytest.mark.parametrize("direction_deg", [0.0, 135.0, 250.0])
def test_without_thrust_the_boat_drifts_at_exactly_the_current(direction_deg):
    current = {"flow": {"kinds": ["uniform"], "uniform": {"speed_mps": 0.12, "direction_deg": direction_deg}}}
    boat, flow, _ = make_boat(current, pose=(2.0, 1.0, math.radians(40.0)))
    boat.state = (*boat.state[:3], 0.2, -0.05, 0.1, 0.0, 0.0)  # moving and turning through the water
    run(boat, flow, 20.0, (0.0, 0.0))
    truth = boat.truth()
    a = math.radians(direction_deg)
    assert truth.vn == pytest.approx(0.12 * math.cos(a), abs=1e-6)
    assert truth.ve == pytest.approx(0.12 * math.sin(a), abs=1e-6)
    assert abs(boat.state[3]) < 1e-6 and abs(boat.state[4]) < 1e-6  # at rest relative to the water


def test_rk4_step_is_fourth_order():
    def f(t, x):
        return (x[1], -x[0])  # harmonic oscillator, exact solution cos t

    def error(h):
        x = (1.0, 0.0)
        for k in range(round(1.0 / h)):
            x = rk4_step(f, k * h, x, h)
        return abs(x[0] - math.cos(1.0))

    ratio = error(0.1) / error(0.05)
    assert 14.0 < ratio < 18.0  # 2^4


def test_state_derivative_is_kinematics_plus_current():
    _, _, p = make_boat()
    x = (0.0, 0.0, math.pi / 2, 0.3, 0.0, 0.0, 0.0, 0.0)  # heading east at 0.3 m/s through the water
    d = state_derivative(x, 0.0, 0.0, 0.1, 0.0, p)  # current 0.1 m/s north
    assert d[0] == pytest.approx(0.1) and d[1] == pytest.approx(0.3)
    assert d[3] == pytest.approx(-0.75 * 0.3 / 1.1)  # X_u u_r / (m - X_udot)
