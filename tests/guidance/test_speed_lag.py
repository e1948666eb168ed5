"""SpeedLag: how quickly a boat's way through the water follows what it is asked, learned from its speed.

Synthetic first-order stops and speed changes ahead and astern (with and without sensor noise), what does not count
as evidence, and the real simulator's boats (the rudder boat and one of twice the mass with a weak astern): told to
stop under Rover's stop controller, the run-on ``u tau`` the estimate predicts against the one flown; asked a speed
astern, the way gathered within a capture manoeuvre's 2 s against the learned lag's prediction.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from koopguide.guidance.estimation.speed_lag import MAX_GAP_S, RELAX_S, SpeedLag
from koopguide.guidance.law.approach_path import STOP_GAIN
from tests.support.open_water import fly, make_boat

TICK_S = 0.1  # the service's command period [s]
PRIOR_S = 1.0 / STOP_GAIN  # the stopping time the helm assumes before it has seen a stop [s]
VELOCITY_YAW = 2535  # type mask: velocity + yaw (heading and speed, docs/rover.md)
HEAVY = {
    "vessel": {
        "hull": {"mass_kg": 2.0, "yaw_inertia_kgm2": 0.02},
        "thrusters": {"max_forward_thrust_n": 0.12, "max_reverse_thrust_n": 0.05},
    }
}


def feed_decay(
    est: SpeedLag, tau_s: float, u0: float, seconds: float, t0: float = 0.0, noise=None, target: float = 0.0
) -> float:
    """A first-order response from u0 toward ``target`` (0: a stop), u = target + (u0 - target) exp(-t / tau),
    sampled every tick with that target asked throughout; returns the last time."""
    t = t0
    for k in range(round(seconds / TICK_S) + 1):
        t = t0 + k * TICK_S
        u = target + (u0 - target) * math.exp(-(t - t0) / tau_s)
        est.update(t, target, u + (0.0 if noise is None else float(noise.normal(0.0, 0.004))))
    return t


def test_a_boat_never_seen_to_stop_is_taken_to_stop_as_the_simulators_do() -> None:
    est = SpeedLag(PRIOR_S)
    assert est.lag_s == pytest.approx(PRIOR_S)
    for k in range(100):  # driving, never told to stop: no evidence
        est.update(k * TICK_S, None, 0.2 * math.exp(-k * TICK_S / 3.0))
    assert est.lag_s == pytest.approx(PRIOR_S)


@settings(max_examples=40, deadline=None)
@given(tau=st.floats(0.7, 5.0), u0=st.floats(0.12, 0.3), sign=st.sampled_from([1.0, -1.0]))
def test_a_first_order_stop_is_fitted_ahead_and_astern(tau: float, u0: float, sign: float) -> None:
    est = SpeedLag(PRIOR_S)
    t = 0.0
    for _ in range(5):  # five stops, each followed by a run told to go (evidence well beyond the prior's)
        t = feed_decay(est, tau, sign * u0, 4.0 * tau, t0=t) + TICK_S
        for _ in range(20):
            est.update(t, None, sign * u0)
            t += TICK_S
    assert est.lag_s == pytest.approx(tau, rel=0.15)


@settings(max_examples=40, deadline=None)
@given(tau=st.floats(0.5, 5.0), target=st.floats(0.1, 0.25), sign=st.sampled_from([1.0, -1.0]))
def test_the_lag_toward_a_speed_asked_ahead_or_astern_is_fitted(tau: float, target: float, sign: float) -> None:
    """Asked a speed (ahead or astern) from rest, then stopped and asked again: the lag toward the speed is the
    time constant of the way gathered, whatever the speed asked (the prior's 1 s is outweighed)."""
    est = SpeedLag(1.0)
    t = 0.0
    for _ in range(4):
        t = feed_decay(est, tau, 0.0, 3.0 * tau, t0=t, target=sign * target) + TICK_S
        est.update(t, None, 0.0)  # another request (a stop): no evidence, the window breaks
        t += 1.0
    assert est.lag_s == pytest.approx(tau, rel=0.15)


def test_sensor_noise_does_not_bias_the_fit() -> None:
    rng = np.random.default_rng(3)
    for tau in (1.2, 3.0):
        est = SpeedLag(PRIOR_S)
        t = 0.0
        for _ in range(6):
            t = feed_decay(est, tau, 0.2, 8.0, t0=t, noise=rng) + 1.0
        assert est.lag_s == pytest.approx(tau, rel=0.2)


def test_a_gap_in_telemetry_breaks_the_window_and_old_evidence_fades() -> None:
    est = SpeedLag(PRIOR_S)
    est.update(0.0, 0.0, 0.2)
    est.update(0.1 + 2.0 * MAX_GAP_S, 0.0, 0.01)  # a fast "stop" across a gap is no evidence
    assert est.lag_s == pytest.approx(PRIOR_S)
    feed_decay(est, 4.0, 0.25, 12.0, t0=5.0)
    slow = est.lag_s
    assert slow > 3.0
    est.update(5.0 + 12.0 + 10.0 * RELAX_S, None, 0.0)  # long after: back toward the prior
    est.update(5.0 + 12.0 + 10.0 * RELAX_S + TICK_S, None, 0.0)
    assert abs(est.lag_s - PRIOR_S) < 0.05 * abs(slow - PRIOR_S)


def run_on(overrides: dict | None) -> tuple[float, float]:
    """A rudder boat in still water at 0.2 m/s ahead, then told speed 0 (Rover's stop controller): the stopping
    time learned from its speed through the water every tick, and the distance it ran on against u0 * tau."""
    boat, flow = make_boat("rudder", overrides=overrides)
    fly(boat, flow, 15.0, mask=VELOCITY_YAW, velocity=(0.2, 0.0), yaw=0.0)
    stop = fly(boat, flow, 20.0, mask=VELOCITY_YAW, velocity=(0.0, 0.0), yaw=0.0)
    est = SpeedLag(PRIOR_S)
    every = round(TICK_S / (stop[1, 0] - stop[0, 0]))
    for row in stop[::every]:
        u = row[4] * math.cos(row[3]) + row[5] * math.sin(row[3])  # no current: ground = water
        est.update(float(row[0]), 0.0, u)
    u0 = float(stop[0, 4])
    ran = float(np.hypot(stop[-1, 1] - stop[0, 1], stop[-1, 2] - stop[0, 2]))
    return est.lag_s, ran / u0


def test_the_simulators_boats_run_on_as_their_learned_stopping_time_predicts() -> None:
    light_tau, light_ran = run_on(None)
    heavy_tau, heavy_ran = run_on(HEAVY)
    assert heavy_ran > 1.4 * light_ran  # the heavy hull with a weak astern runs on much further
    assert heavy_tau > 1.4 * light_tau  # ... and the estimate sees it
    for tau, ran in ((light_tau, light_ran), (heavy_tau, heavy_ran)):
        assert tau == pytest.approx(ran, rel=0.35)  # u0 tau is the run-on, within the model's error


def sternway(overrides: dict | None) -> tuple[float, float, float]:
    """A rudder boat at rest in still water asked 0.12 m/s astern (velocity + yaw, a capture manoeuvre's speed) for
    2 s at a time, stopped between: the astern lag learned from its speed through the water every tick, the way it
    gathered in the first 2 s, and the way a first-order lag of that time constant predicts."""
    boat, flow = make_boat("rudder", overrides=overrides)
    est = SpeedLag(1.0)
    gathered = None
    for _ in range(3):
        run = fly(boat, flow, 2.0, mask=VELOCITY_YAW, velocity=(-0.12, 0.0), yaw=0.0)
        every = round(TICK_S / (run[1, 0] - run[0, 0]))
        for row in run[::every]:
            est.update(float(row[0]), -0.12, row[4] * math.cos(row[3]) + row[5] * math.sin(row[3]))
        gathered = float(run[-1, 4]) if gathered is None else gathered
        est.update(float(run[-1, 0]) + TICK_S, None, 0.0)
        fly(boat, flow, 8.0, mask=VELOCITY_YAW, velocity=(0.0, 0.0), yaw=0.0)  # to rest
    predicted = -0.12 * (1.0 - math.exp(-2.0 / est.lag_s))
    return est.lag_s, gathered, predicted


def test_a_hull_slow_to_gather_sternway_is_learned_so() -> None:
    """The capture search's model boat takes the lag astern from this fit (law/capture.py): the heavy hull with a
    weak astern gathers far less sternway in a manoeuvre's 2 s, and its learned lag says so."""
    light_lag, light_way, light_predicted = sternway(None)
    heavy_lag, heavy_way, heavy_predicted = sternway(HEAVY)
    assert abs(heavy_way) < 0.75 * abs(light_way)  # the weak astern: less sternway in 2 s
    assert heavy_lag > 1.5 * light_lag  # ... and the estimate sees it
    for way, predicted in ((light_way, light_predicted), (heavy_way, heavy_predicted)):
        assert way < 0.0
        assert predicted == pytest.approx(way, abs=0.02)  # the first-order model's way after 2 s
