"""SpeedLag: how quickly a boat's way through the water follows what it is asked, learned from its speed.

Synthetic first-order stops and speed changes ahead and astern (with and without sensor noise), what does not count
as evidence, whether the boat goes astern at all (the sternway trial), and the real simulator's boats (the rudder
boat and one of twice the mass with a weak astern): told to stop under Rover's stop controller, the run-on
``u tau`` the estimate predicts against the one flown; asked a speed astern, the way gathered within a capture
manoeuvre's 2 s against the learned lag's prediction, and the sternway trial passed; whether speed 0 lets the boat
drift or holds its ground (the simulator's Rover stop controller against a kinematic boat without one).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from koopguide.guidance.estimation.speed_lag import (
    MAX_GAP_S,
    RELAX_S,
    REST_CURRENT_MPS,
    REST_S,
    REST_SETTLE_LAGS,
    TRIAL_S,
    TRIAL_SETTLE_S,
    WAY_ERROR_MPS,
    BoatLags,
    SpeedLag,
    SternwayTrial,
)
from koopguide.guidance.law.approach_path import STOP_GAIN
from tests.support import kinematic_rudder
from tests.support.open_water import current, fly, make_boat

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


def feed_astern(trial: SternwayTrial, sternway_mps: float, seconds: float, asked_mps: float = -0.12) -> None:
    """Ask ``asked_mps`` through the water every tick for ``seconds``; the boat gathers ``sternway_mps`` over 1 s."""
    for k in range(round(seconds / TICK_S) + 1):
        t = k * TICK_S
        trial.update(t, asked_mps, -sternway_mps * min(1.0, t))


def test_a_boat_that_gathers_no_sternway_when_asked_astern_is_judged_to_go_ahead_only() -> None:
    """A single thruster on a motor that does not reverse: asked astern, it lies in the water (stop 48)."""
    trial = SternwayTrial()
    feed_astern(trial, 0.0, TRIAL_SETTLE_S + TRIAL_S - 0.3)
    assert trial.goes_astern is None and trial.able  # not judged before the trial has been seen whole
    feed_astern(trial, 0.0, TRIAL_SETTLE_S + TRIAL_S + 0.2)
    assert trial.goes_astern is False and not trial.able


@pytest.mark.parametrize("sternway", [0.03, 0.05, 0.12])
def test_a_boat_that_goes_astern_however_weakly_passes_the_trial(sternway: float) -> None:
    trial = SternwayTrial()
    feed_astern(trial, sternway, TRIAL_SETTLE_S + TRIAL_S + 0.2)
    assert trial.goes_astern is True
    feed_astern(trial, 0.0, 10.0)  # judged once: a later stall (a wall, a line fouled) does not undo it
    assert trial.able


@pytest.mark.parametrize("asked", [None, 0.0, -0.015, 0.12])
def test_no_sternway_trial_without_a_request_astern(asked: float | None) -> None:
    """Speed 0, the creep cycle's back-down (about 0.015 m/s through the water), ahead, or no evidence (a wall):
    nothing to judge sternway by."""
    trial = SternwayTrial()
    feed_astern(trial, 0.0, 20.0, asked)
    assert trial.goes_astern is None and trial.able


def test_short_requests_astern_are_judged_only_on_their_settled_part() -> None:
    """Requests astern shorter than TRIAL_SETTLE_S (the way is still gathering) are no trial, however many."""
    trial = SternwayTrial()
    t = 0.0
    for _ in range(20):
        for asked in (-0.12,) * round((TRIAL_SETTLE_S - 0.3) / TICK_S) + (0.12,) * 10:
            trial.update(t, asked, 0.0)
            t += TICK_S
    assert trial.goes_astern is None


def test_the_simulators_weak_astern_hull_goes_astern() -> None:
    """The simulator's hull of twice the mass with 45% less thrust astern (the weakest astern in the family) is not
    taken for one that goes ahead only: asked 0.12 m/s astern from rest for 5 s, it passes the trial."""
    boat, flow = make_boat("rudder", overrides=HEAVY)
    trial = SternwayTrial()
    run = fly(boat, flow, TRIAL_SETTLE_S + TRIAL_S + 0.5, mask=VELOCITY_YAW, velocity=(-0.12, 0.0), yaw=0.0)
    for row in run[:: round(TICK_S / (run[1, 0] - run[0, 0]))]:
        trial.update(float(row[0]), -0.12, row[4] * math.cos(row[3]) + row[5] * math.sin(row[3]))
    assert trial.goes_astern is True


@pytest.mark.parametrize("lag_s", [2.0, 3.0, 4.0])
@pytest.mark.parametrize("asked", [0.05, 0.08, 0.12])
def test_a_boat_slow_to_gather_sternway_passes_the_trial_however_little_it_is_asked(lag_s: float, asked: float) -> None:
    """The sternway follows the request with the heavy hull's lag (2-3 s astern, estimation/speed_lag.py): asked only
    0.05 m/s, it gathers a mean of about 0.024 m/s over the trial. The heavy skid-steer boat of
    tests/harness/test_vehicle_missions.py, asked about 0.055 m/s astern by the station keeper, was once taken for one
    that goes ahead only on an absolute bar of 0.025 m/s, and then drifted 0.56 m off its goal (stop 49's CI)."""
    trial = SternwayTrial()
    for k in range(round((TRIAL_SETTLE_S + TRIAL_S + 0.2) / TICK_S) + 1):
        t = k * TICK_S
        trial.update(t, -asked, -asked * (1.0 - math.exp(-t / lag_s)))
    assert trial.goes_astern is True


@pytest.mark.parametrize("asked", [0.05, 0.12, 0.28])
def test_a_boat_that_gathers_no_sternway_is_judged_so_however_much_it_is_asked(asked: float) -> None:
    trial = SternwayTrial()
    feed_astern(trial, 0.0, TRIAL_SETTLE_S + TRIAL_S + 0.2, -asked)
    assert trial.goes_astern is False


def test_no_sternway_trial_while_the_boat_is_turned_toward_the_heading_asked() -> None:
    """A skid-steer boat asked astern 90 deg off its heading pivots first (Rover's WP_PIVOT_ANGLE), without way: that
    is no evidence against its astern. Within TRIAL_HEADING_RAD it is, and so is any request to a boat that does not
    pivot (a rudder boat asked astern 50 deg off its heading lies in the water all the same)."""
    for error_deg, verdict in ((90.0, None), (-45.0, None), (10.0, False), (None, False)):  # None: no pivots
        lags = BoatLags(1.0, 1.0)
        for k in range(round((TRIAL_SETTLE_S + TRIAL_S + 1.0) / TICK_S)):
            lags.update(k * TICK_S, -0.12, 0.0, 0.0, None if error_deg is None else math.radians(error_deg))
        assert lags.sternway.goes_astern is verdict


def feed_rest(
    lags: BoatLags,
    seconds: float,
    current_along: float,
    ground_along: float,
    asked: float | None = 0.0,
    current_trusted: bool = True,
) -> None:
    """Ask ``asked`` over ground along the heading every tick for ``seconds`` from rest, the boat moving over ground
    at ``ground_along`` along its heading, the current's component along it ``current_along`` (an estimate the helm
    trusts, or one in sheared water)."""
    for k in range(round(seconds / TICK_S) + 1):
        lags.update(k * TICK_S, asked, current_along, ground_along - current_along, None, current_trusted)


def test_a_boat_that_holds_its_ground_at_speed_0_is_learned_so() -> None:
    """An autopilot whose speed loop over ground runs on at 0 keeps way on against the current and stays where it
    is (tests/support/kinematic_rudder.py); judged once REST_S of it has been seen after its way had time to go."""
    settle = REST_SETTLE_LAGS * BoatLags(PRIOR_S, 1.0).stopping.lag_s
    lags = BoatLags(PRIOR_S, 1.0)
    feed_rest(lags, settle + REST_S - 0.3, -0.03, 0.0)
    assert not lags.rest.holds  # not judged before REST_S of it has been seen
    lags = BoatLags(PRIOR_S, 1.0)
    feed_rest(lags, settle + REST_S + 0.2, -0.03, 0.0)
    assert lags.rest.holds
    feed_rest(lags, 30.0, -0.03, -0.03)  # learned for good: a drift later does not unlearn it
    assert lags.rest.holds


@pytest.mark.parametrize("from_astern", [False, True])
@pytest.mark.parametrize("carried", [1.0, 0.6, 0.3])
def test_a_boat_the_current_carries_at_speed_0_is_never_taken_to_hold_its_ground(
    carried: float, from_astern: bool
) -> None:
    """Rover's stop controller puts the throttle off and the current carries the boat downstream (partly, on a hull
    that coasts on or a current estimate too strong), against the bow or from astern: however long it is watched. A
    boat that goes ahead only, the current from astern, is carried so too."""
    along = 0.03 if from_astern else -0.03
    lags = BoatLags(PRIOR_S, 1.0)
    feed_rest(lags, 60.0, along, carried * along)
    assert not lags.rest.holds


def test_a_boat_that_holds_its_ground_at_speed_0_with_the_current_from_astern_is_learned_so() -> None:
    """Held bow downstream (astern into the current), the autopilot that runs its speed loop on at 0 keeps way on
    astern and stays: a kinematic rudder boat held 0.35 m upstream of the goal so sat there for 20 s while the hold
    waited on a drift (stop 58). The same verdict as against the bow."""
    settle = REST_SETTLE_LAGS * BoatLags(PRIOR_S, 1.0).stopping.lag_s
    lags = BoatLags(PRIOR_S, 1.0)
    feed_rest(lags, settle + REST_S - 0.3, 0.03, 0.0)
    assert not lags.rest.holds
    lags = BoatLags(PRIOR_S, 1.0)
    feed_rest(lags, settle + REST_S + 0.2, 0.03, 0.0)
    assert lags.rest.holds


@pytest.mark.parametrize(
    ("current_along", "asked"),
    [(-0.5 * REST_CURRENT_MPS, 0.0), (0.5 * REST_CURRENT_MPS, 0.0), (-0.03, 0.05), (0.03, -0.05), (-0.03, None)],
)
def test_no_evidence_of_holding_the_ground_without_a_current_along_the_heading_at_speed_0(
    current_along: float, asked: float | None
) -> None:
    """Too little current along the heading to tell (either way), a speed asked, or no request (a wall): the boat
    that stays where it is shows nothing."""
    lags = BoatLags(PRIOR_S, 1.0)
    feed_rest(lags, 60.0, current_along, 0.0, asked)
    assert not lags.rest.holds


def test_in_sheared_water_a_boat_that_stays_at_speed_0_shows_nothing() -> None:
    """Where the water is sheared the estimate at the boat may be a current it is not in (the double gyre's: the
    simulator's rudder boat, carried by less than the estimate said, was once taken to hold its ground, and the
    capture search then waited on a drift that carried it off): no verdict either way while it is so."""
    lags = BoatLags(PRIOR_S, 1.0)
    feed_rest(lags, 60.0, -0.03, 0.0, current_trusted=False)
    assert not lags.rest.holds
    feed_rest(lags, 60.0, -0.03, 0.0)  # the same samples with a current the helm trusts: it holds its ground
    assert lags.rest.holds


@pytest.mark.parametrize("holds_ground", [False, True])
def test_speed_0_in_a_current_against_the_bow_tells_the_simulators_boat_from_one_that_holds_its_ground(
    monkeypatch: pytest.MonkeyPatch, holds_ground: bool
) -> None:
    """Asked speed 0 at its heading (velocity + yaw) in 0.03 m/s against its bow after a run at 0.15 m/s: the
    simulator's rudder boat (Rover's stop controller) drifts back, the kinematic boat without a stop controller
    holds its ground; what the helm learns from each, fed every tick as it is in a mission."""
    if holds_ground:
        kinematic_rudder.install(monkeypatch)
    boat, flow = make_boat("rudder", overrides=current(0.03, 180.0))  # toward S, the bow N
    fly(boat, flow, 6.0, mask=VELOCITY_YAW, velocity=(0.15, 0.0), yaw=0.0)
    run = fly(boat, flow, 20.0, mask=VELOCITY_YAW, velocity=(0.0, 0.0), yaw=0.0)
    lags = BoatLags(PRIOR_S, 1.0)
    every = round(TICK_S / (run[1, 0] - run[0, 0]))
    for row in run[::every]:
        h = np.array([math.cos(row[3]), math.sin(row[3])])
        c_along = float(np.array([-0.03, 0.0]) @ h)
        lags.update(float(row[0]), 0.0, c_along, float(row[4:6] @ h) - c_along)
    drift = float(run[-1, 1] - run[every * 60, 1])  # N over the last 14 s [m]
    assert (drift > -0.05) if holds_ground else (drift < -0.25)  # it stays, or goes with the current
    assert lags.rest.holds is holds_ground


def test_a_stopped_boat_s_way_left_dies_over_its_stopping_lag_from_what_it_had() -> None:
    """Speed 0 sent, the way the boat has left is bounded by the way it had then (known within WAY_ERROR_MPS) dying
    over the stopping lag: what the current estimate counts as noise along the heading when it reads the drift of a
    boat stopped in sheared water (stop 54). None while propelled, after a gap, or for a boat whose speed 0 holds its
    ground."""
    lags = BoatLags(PRIOR_S, 1.0)
    lags.update(0.0, 0.2, 0.0, 0.12)
    assert lags.way_left_mps is None  # propelled
    n = round(REST_SETTLE_LAGS * PRIOR_S / TICK_S)
    for k in range(n + 1):  # speed 0 for three of the prior's lags, the way dying at that lag
        lags.update(0.1 + k * TICK_S, 0.0, 0.0, 0.12 * math.exp(-k * TICK_S / PRIOR_S))
    lag, t = lags.stopping.lag_s, 0.1 + n * TICK_S
    assert lag == pytest.approx(PRIOR_S, rel=0.05)
    assert lags.way_left_mps == pytest.approx((0.12 + WAY_ERROR_MPS) * math.exp(-n * TICK_S / lag), rel=1e-9)
    assert lags.way_left_mps < 0.06 * (0.12 + WAY_ERROR_MPS)  # about 5% of it
    lags.update(t + 2 * MAX_GAP_S, 0.0, 0.0, 0.0)  # after a gap in telemetry speed 0 is watched anew
    assert lags.way_left_mps == pytest.approx(WAY_ERROR_MPS)
    lags.update(t + 2 * MAX_GAP_S + TICK_S, 0.1, 0.0, 0.0)
    assert lags.way_left_mps is None
    holds = BoatLags(PRIOR_S, 1.0)
    settle = REST_SETTLE_LAGS * holds.stopping.lag_s
    feed_rest(holds, settle + REST_S + 0.2, -0.03, 0.0)
    assert holds.rest.holds and holds.way_left_mps is None  # its autopilot keeps way on at 0: not adrift
