"""The capture search near the goal (law/capture.py): a boat that needs way gets onto its holding line.

An ideal rudder boat (Rover's semantics: it holds the commanded speed over ground along its heading, turns toward
the commanded heading at most at its speed through the water over its turning radius, the current carries it)
is driven by the search alone from poses near the goal where line-of-sight feedback stalls: beside the line and
facing along it, or across it.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from koopguide.guidance.law.capture import (
    CAPTURE_M,
    ENTRY_CROSS_M,
    ENTRY_RAD,
    MANEUVERS,
    MAX_RADIUS_M,
    MIN_RADIUS_M,
    SIM_DT_S,
    STEP_S,
    CaptureSearch,
    straight_run,
)
from koopguide.guidance.law.line_approach import FERRY_RAD
from koopguide.guidance.law.maneuver import unit, wrap_pi
from koopguide.mavlink.rover import MASK_VELOCITY_YAW
from tests.support import kinematic_rudder
from tests.support.open_water import fly as fly_boat
from tests.support.open_water import make_boat

ARRIVAL_M = 0.15  # the default arrival radius


def holds(p: np.ndarray, psi: float, axis: float) -> bool:
    """Within the bounds the hold takes a boat on at (law/line_approach.py): on the line, facing along it (either
    end), at the goal."""
    a = unit(axis)
    cross = float(p @ np.array([-a[1], a[0]]))
    off = abs(wrap_pi(psi - axis))
    return abs(cross) <= ENTRY_CROSS_M and min(off, math.pi - off) <= ENTRY_RAD and float(np.hypot(*p)) <= ARRIVAL_M


def fly(
    start: np.ndarray,
    heading: float,
    current: np.ndarray,
    radius_m: float,
    outside=None,
    limit_s: float = 60.0,
    until=None,
    axis: float | None = None,
    told: np.ndarray | None = None,
    point_only: bool = False,
    holds_ground: bool = False,
    astern: bool = True,
) -> tuple[list[tuple[float, np.ndarray, float]], float]:
    """Drive the ideal boat by the search alone from ``start`` (the goal at the origin, the line along the current,
    or north in still water, unless ``axis`` is given) for ``limit_s`` or until ``until(t, p, psi)``: its track
    (t, p, psi) and the largest speed asked. ``told``: the current the search is told (default: the one there);
    ``point_only``: the search's (sheared water: no line); ``holds_ground``: the boat holds its ground along its
    heading at speed 0 (no stop controller), and the search knows it; ``astern``: the boat goes astern (else its
    motor does not reverse), and the search knows it."""
    search = CaptureSearch(max_speed_mps=0.3)
    search.point_only, search.holds_at_rest, search.astern = point_only, holds_ground, astern
    still = float(np.hypot(*current)) == 0.0
    axis = (0.0 if still else math.atan2(-current[1], -current[0])) if axis is None else axis
    told = (None if still else current) if told is None else told
    p, psi, water, t, dt, fastest = start.astype(float), heading, 0.0, 0.0, 0.05, 0.0
    track = [(t, p, psi)]
    while t < limit_s and not (until is not None and until(t, p, psi)):
        m = search.command(t, p, np.zeros(2), psi, water, axis, told, radius_m, outside)
        fastest = max(fastest, abs(m.speed_mps))
        h = unit(psi)
        target = 0.0 if m.speed_mps == 0.0 and not holds_ground else m.speed_mps - float(current @ h)  # in the water
        target = target if astern else max(target, 0.0)
        water += (target - water) * dt / 1.0  # Rover's speed loop and the hull: about 1 s
        rate = abs(water) / radius_m
        psi = wrap_pi(psi + max(-rate * dt, min(rate * dt, wrap_pi(m.heading_rad - psi))))
        p = p + dt * (water * h + current)
        t += dt
        track.append((t, p, psi))
    return track, fastest


def capture(start: np.ndarray, heading: float, current: np.ndarray, radius_m: float) -> tuple[float | None, float]:
    """The time the ideal boat first holds (None: not within 60 s) and the largest speed asked."""
    axis = math.atan2(-current[1], -current[0]) if float(np.hypot(*current)) > 0 else 0.0
    track, fastest = fly(start, heading, current, radius_m, until=lambda t, p, psi: holds(p, psi, axis))
    t, p, psi = track[-1]
    return (t if holds(p, psi, axis) else None), fastest


@pytest.mark.parametrize("toward_deg", [0.0, 90.0, 180.0, 270.0])
@pytest.mark.parametrize("side", [-1.0, 1.0])
def test_a_boat_beside_its_line_facing_along_it_gets_onto_it(toward_deg: float, side: float) -> None:
    """0.25 m beside the current's line, bow upstream: where LOS feedback shuttled along the line for a minute."""
    current = 0.025 * unit(math.radians(toward_deg))
    upstream = math.radians(toward_deg) + math.pi
    a = unit(upstream)
    start = side * 0.25 * np.array([-a[1], a[0]])
    t, fastest = capture(start, upstream + math.radians(10.0), current, radius_m=1.3)
    assert t is not None and t < 45.0, t
    assert fastest <= 0.3 + 1e-9


@pytest.mark.parametrize("toward_deg", [45.0, 225.0])
def test_a_boat_across_its_line_near_the_goal_turns_onto_it(toward_deg: float) -> None:
    """Across the line 0.3 m from the goal: it has to turn the bow 90 deg in decimetres (ahead and astern)."""
    current = 0.025 * unit(math.radians(toward_deg))
    upstream = math.radians(toward_deg) + math.pi
    start = 0.3 * unit(upstream + math.pi / 2)
    t, _ = capture(start, upstream + math.pi / 2, current, radius_m=1.3)
    assert t is not None and t < 60.0, t


@settings(max_examples=60, deadline=None)
@given(
    n=st.floats(-CAPTURE_M, CAPTURE_M),
    e=st.floats(-CAPTURE_M, CAPTURE_M),
    heading=st.floats(-math.pi, math.pi),
    toward=st.sampled_from([None, 0.0, 90.0, 180.0, 270.0]),
)
def test_a_boat_that_goes_ahead_only_is_given_no_manoeuvre_astern(n, e, heading, toward) -> None:
    """A boat seen to gather no sternway (estimation/speed_lag.py): ahead or drifting, never astern."""
    current = np.zeros(2) if toward is None else 0.03 * unit(math.radians(toward))
    search = CaptureSearch(max_speed_mps=0.3)
    search.astern = False
    axis = 0.0 if toward is None else math.radians(toward) + math.pi
    m = search.command(0.0, np.array([n, e]), np.zeros(2), heading, 0.0, axis, current, 1.3, None)
    assert search.chosen[0] >= 0 and not m.astern


def test_in_still_water_it_holds_any_line_through_the_goal_it_is_given() -> None:
    t, _ = capture(np.array([0.2, 0.2]), math.radians(60.0), np.zeros(2), radius_m=1.2)
    assert t is not None and t < 45.0, t


def test_it_keeps_out_of_the_area_it_may_not_use() -> None:
    """The goal 0.15 m inside a wall to the east: every sequence that would cross it is worse than any that does
    not, so the boat never goes more than a few centimetres (one manoeuvre's overshoot of the model) beyond it."""
    current = 0.025 * unit(math.radians(45.0))  # toward NE: the current sets the boat onto the wall

    def outside(points: np.ndarray) -> np.ndarray:
        return np.maximum(np.atleast_2d(points)[:, 1] - 0.15, 0.0)

    track, _ = fly(np.array([0.1, 0.05]), 0.0, current, 1.3, outside, limit_s=40.0)
    worst = max(float(outside(p)[0]) for _, p, _ in track)
    assert worst < 0.05, worst


@settings(max_examples=60, deadline=None)
@given(
    n=st.floats(-CAPTURE_M, CAPTURE_M),
    e=st.floats(-CAPTURE_M, CAPTURE_M),
    heading=st.floats(-math.pi, math.pi),
    water=st.floats(-0.25, 0.25),
    toward=st.floats(0.0, 2 * math.pi),
    speed=st.floats(0.0, 0.08),
    radius=st.floats(0.5, 8.0),
)
def test_every_manoeuvre_is_finite_and_within_max_speed(n, e, heading, water, toward, speed, radius) -> None:
    """Whatever the pose, the current and the (possibly wild) turning-radius estimate: a finite heading, a speed
    over ground within max_speed, and one of the manoeuvres, held for STEP_S before the next search."""
    current = speed * unit(toward)
    search = CaptureSearch(max_speed_mps=0.3)
    axis = toward + math.pi
    m = search.command(0.0, np.array([n, e]), np.zeros(2), heading, water, axis, current, radius, None)
    assert math.isfinite(m.heading_rad) and abs(m.speed_mps) <= 0.3 + 1e-12
    assert search.chosen in MANEUVERS
    chosen = search.chosen
    search.command(
        STEP_S - 0.1, np.array([n, e]) + 0.1, np.zeros(2), heading + 1.0, -water, axis, current, radius, None
    )
    assert search.chosen == chosen  # held for its whole length


@settings(max_examples=60, deadline=None)
@given(
    heading=st.floats(-math.pi, math.pi),
    water=st.floats(-0.25, 0.25),
    target=st.floats(-0.2, 0.2),
    lag=st.floats(0.5, 4.0),
    cn=st.floats(-0.08, 0.08),
    ce=st.floats(-0.08, 0.08),
    seconds=st.sampled_from([2.0, 3.0]),
)
def test_the_searchs_straight_runs_summed_in_closed_form_are_its_euler_steps(
    heading, water, target, lag, cn, ce, seconds
) -> None:
    """The runs beyond the horizon (rudder amidships) are summed in closed form: the same boat, way and place as
    stepping the model ``SIM_DT_S`` at a time (the way follows its target with the lag; the boat moves by the way
    after each step along its heading, and by the current)."""
    c = np.array([cn, ce])
    pos, u = np.array([0.3, -0.2]), water
    for _ in range(round(seconds / SIM_DT_S)):
        u = u + (target - u) * (SIM_DT_S / lag)
        pos = pos + (u * unit(heading) + c) * SIM_DT_S
    got = straight_run(
        np.array([[0.3, -0.2]]), np.array([heading]), np.array([water]), np.array([target]), np.array([lag]), c, seconds
    )
    assert (
        np.allclose(got[0][0], pos, rtol=0.0, atol=1e-12)
        and got[1][0] == heading
        and math.isclose(got[2][0], u, abs_tol=1e-12)
    )


def test_a_hold_beside_the_line_short_of_arriving_gives_way_to_the_capture_search() -> None:
    """Holding 0.2 m beside the current's line (within the hold's 0.4 m hysteresis) the boat sat there for 90 s,
    never within the arrival radius (astern into the current, vortex, seed 16). Not yet arrived, the hold is given
    up for the capture search; once arrived, the hold's hysteresis stands."""
    from koopguide.guidance.law.line_approach import LineApproach

    current = np.array([0.018, 0.018])  # toward NE
    upstream = math.atan2(-current[1], -current[0])
    a = unit(upstream)
    beside = 0.2 * np.array([-a[1], a[0]]) + 0.02 * a
    outcomes = {}
    for arrived in (False, True):
        line = LineApproach(0.3, 0.5, 0.075, 0.15, 0.25)
        line.aim(np.zeros(2), np.zeros(2), upstream, current)
        line.command(0.02 * a, np.zeros(2), upstream, 1.3, current, t=0.0, arrived=arrived)  # on the line: holds
        assert line.holding
        line.command(beside, np.zeros(2), upstream, 1.3, current, t=0.1, arrived=arrived)
        outcomes[arrived] = (line.holding, line.capture.chosen is not None)
    assert outcomes[False] == (False, True)
    assert outcomes[True] == (True, False)


def test_a_hold_the_line_turned_away_from_short_of_arriving_gives_way_to_the_capture_search() -> None:
    """The hold takes a bow on within ENTRY_RAD of its line, but the current estimate may turn the line after that:
    holds that arrived 15-17 deg off it held 0.46-0.82 m p95 in a uniform current (rudder, stop 31). Not yet
    arrived, a bow 18 deg off the turned line is captured again; 12 deg off it is still held; once arrived, or on a
    still-water line, the hold's hysteresis stands."""
    from koopguide.guidance.law.line_approach import LineApproach

    current = np.array([-0.03, 0.0])  # toward S: the line's bow end north
    outcomes = {}
    for arrived, off_deg in ((False, 18.0), (False, 12.0), (True, 18.0)):
        line = LineApproach(0.3, 0.5, 0.075, 0.15, 0.25)
        line.aim(np.zeros(2), np.zeros(2), 0.0, current)
        line.command(np.array([-0.05, 0.0]), np.zeros(2), 0.0, 1.3, current, t=0.0, arrived=arrived)
        assert line.holding  # on the line, facing along it
        c = 0.03 * unit(math.radians(180.0 + off_deg))
        line.aim(np.zeros(2), np.zeros(2), 0.0, c)
        line.command(np.array([-0.05, 0.0]), np.zeros(2), 0.0, 1.3, c, t=0.1, arrived=arrived)
        outcomes[(arrived, off_deg)] = line.holding
    assert abs(math.degrees(wrap_pi(line.axis_rad))) == pytest.approx(18.0)
    assert outcomes == {(False, 18.0): False, (False, 12.0): True, (True, 18.0): True}
    still = LineApproach(0.3, 0.5, 0.075, 0.15, 0.25)  # a still-water line does not turn: the bow's swing is its own
    still.aim(np.array([-0.05, 0.0]), np.zeros(2), 0.0, None)
    still.command(np.array([-0.05, 0.0]), np.zeros(2), 0.0, 1.3, t=0.0, arrived=False)
    assert still.holding
    still.command(np.array([-0.05, 0.0]), np.zeros(2), math.radians(18.0), 1.3, t=0.1, arrived=False)
    assert still.holding


def test_a_boat_out_of_the_area_comes_back_in_first() -> None:
    """Pressed 0.25 m beyond the area's east edge by a current toward it (a tank's wall lies there), the boat is
    brought back inside before it settles on the line (at the area's edge, capture and planner took turns)."""
    current = 0.025 * unit(math.radians(60.0))

    def outside(points: np.ndarray) -> np.ndarray:
        return np.maximum(np.atleast_2d(points)[:, 1] - 0.15, 0.0)

    start = np.array([-0.2, 0.4])
    track, _ = fly(
        start, math.radians(-160.0), current, 1.3, outside, limit_s=40.0, until=lambda t, p, psi: not outside(p)[0]
    )
    back_in, p, _ = track[-1]
    assert float(outside(start)[0]) > 0.2
    assert float(outside(p)[0]) == 0.0 and back_in < 30.0, (p, back_in)


def test_a_boat_beside_its_line_bow_downstream_does_not_lie_there() -> None:
    """0.2 m beside the line with the bow downstream (vortex, seed 18): no sequence of four manoeuvres reaches the
    line from there, and without scoring where each one leads beyond the horizon the search drifted beside the line
    for a minute (every turn toward it scored worse than none)."""
    current = 0.027 * unit(math.radians(45.0))
    a = unit(math.radians(45.0))
    start = 0.2 * np.array([-a[1], a[0]]) - 0.08 * a
    t, _ = capture(start, math.radians(45.0), current, radius_m=1.45)
    assert t is not None and t < 45.0, t


@pytest.mark.parametrize("along", [0.2, 0.0, -0.2])
@pytest.mark.parametrize("bow_off_rad", [0.0, 0.3, -0.3])
def test_onto_a_still_water_line_across_the_current_the_search_drifts_its_model_on_the_current(
    along: float, bow_off_rad: float
) -> None:
    """In sheared water the line is the still-water one, which may lie across the current at the goal (the
    campaign's vortex: 0.025 m/s across the line the field's approach drew through the goal). The search's model
    boat drifts on the current estimate at the boat all the same, and gets the boat onto that line from 0.25 m
    upstream of it within seconds; a model in still water there is set off the line by every manoeuvre it plans:
    slower or not at all (4 of these 9 poses not within 60 s)."""
    current = 0.025 * unit(math.radians(45.0))  # toward NE
    axis = math.radians(-45.0)  # the line NW-SE through the goal, across the current
    a = unit(axis)
    start = -0.25 * np.array([-a[1], a[0]]) + along * a  # upstream of the line

    def held(t: float, p: np.ndarray, psi: float) -> bool:
        return holds(p, psi, axis)

    outcomes = []
    for told in (current, np.zeros(2)):
        track, _ = fly(start, axis + bow_off_rad, current, 1.3, axis=axis, told=told, until=held)
        t, p, psi = track[-1]
        outcomes.append(t if held(t, p, psi) else None)
    drifting, still = outcomes
    assert drifting is not None and drifting < 15.0, outcomes
    assert still is None or still > drifting, outcomes


@pytest.mark.parametrize("toward_deg", [0.0, 90.0, 180.0, 270.0])
def test_the_hold_takes_on_no_boat_that_would_creep_away_from_its_line(toward_deg: float) -> None:
    """In a current the hold turns the bow only while it creeps upstream (ahead with the bow upstream, astern with
    it downstream): a boat 5 cm beside the line whose creep would carry it farther off is left to the capture
    search; turned toward the line, or on it, it is taken on. From every side, ahead and astern."""
    from koopguide.guidance.law.line_approach import ENTRY_AWAY_RAD, LineApproach

    toward = math.radians(toward_deg)
    current = 0.03 * unit(toward)
    for bow, creep in ((wrap_pi(toward + math.pi), 1.0), (wrap_pi(toward), -1.0)):  # bow upstream: ahead
        a = unit(bow)
        right = np.array([-a[1], a[0]])
        taken = {}
        for cross, turn_deg in ((0.05, 4.8), (0.05, -4.8), (-0.05, 4.8), (-0.05, -4.8), (0.01, 4.8), (0.01, -4.8)):
            line = LineApproach(0.3, 0.5, 0.075, 0.15, 0.25)
            heading = wrap_pi(bow + math.radians(turn_deg))
            p = cross * right - 0.05 * creep * a  # just downstream of the goal
            line.aim(p, np.zeros(2), heading, current)
            assert line.axis_rad == pytest.approx(bow)
            line.command(p, np.zeros(2), heading, 1.3, current, t=0.0, arrived=False)
            taken[(cross, turn_deg)] = line.holding
        # creeping along its heading (astern: its reverse), the boat moves across the line toward its side
        away = {k: creep * math.copysign(1.0, k[0]) * k[1] > math.degrees(ENTRY_AWAY_RAD) for k in taken}
        assert taken == {k: not away[k] or abs(k[0]) <= 0.02 for k in taken}, (bow, taken)
        assert sum(not v for v in taken.values()) == 2


def test_the_capture_search_drifts_on_what_it_is_told_and_on_nothing_when_told_none() -> None:
    """``LineApproach.aim``'s drift: by default the line's current; None (shear seen at the boat now) is no drift,
    not "the line's current" (the helm then has no current for the line either, but the two must not be coupled)."""
    from koopguide.guidance.law.line_approach import LineApproach

    current = np.array([0.02, -0.01])
    line = LineApproach(0.3, 0.5, 0.075, 0.15, 0.25)
    line.aim(np.zeros(2), np.zeros(2), 0.0, current)
    assert line.drift is current
    line.aim(np.zeros(2), np.zeros(2), 0.0, current, None)
    assert line.drift is None
    drift = np.array([0.0, 0.03])
    line.aim(np.zeros(2), np.zeros(2), 0.0, None, drift)
    assert line.drift is drift and not line.in_current


def first_at_rest_within(
    track: list[tuple[float, np.ndarray, float]], current: np.ndarray, stop_s: float
) -> float | None:
    """The first time [s] the ideal boat lies within the arrival radius, and would stop within it as its way through
    the water runs on over ``stop_s`` along its heading (Helm.stops_within); None: never."""
    for (t0, p0, _), (t1, p1, psi1) in itertools.pairwise(track):
        h = unit(psi1)
        water = float((p1 - p0) @ h / (t1 - t0) - current @ h)  # ground = way along the heading + current
        if float(np.hypot(*p1)) <= ARRIVAL_M and float(np.hypot(*(p1 + water * stop_s * h))) <= ARRIVAL_M:
            return t1
    return None


@pytest.mark.parametrize("toward_deg", [0.0, 90.0, 180.0, 270.0])
def test_with_no_line_to_capture_the_search_brings_the_boat_to_rest_at_the_goal_whatever_its_heading(
    toward_deg: float,
) -> None:
    """Sheared water (``point_only``): no line to capture, and the boat arrives off its line once its way would stop
    it within the arrival radius (Helm.stops_within). From 0.35 m up- or downstream of the goal, bow toward it or
    away from it 20 deg either side, the search gets it there within 10 s, and sooner in all than lining it up on
    the current's line through the goal. (From across the current the search is myopic: a boat the current sets
    past the goal drifts out of its zone, and the planner brings it back from beyond CAPTURE_LEAVE_M.)"""
    current = 0.03 * unit(math.radians(toward_deg))
    axis = math.atan2(-current[1], -current[0])
    times, lined_up = [], []
    for bearing_deg in (0.0, 180.0):  # downstream, upstream
        for bow_deg in (160.0, 200.0, -20.0, 20.0):  # toward the goal, away from it
            start = 0.35 * unit(math.radians(toward_deg + bearing_deg))
            heading = math.radians(toward_deg + bearing_deg + bow_deg)
            track, fastest = fly(start, heading, current, 1.3, limit_s=20.0, point_only=True)
            times.append(first_at_rest_within(track, current, stop_s=1.0))
            assert times[-1] is not None and fastest <= 0.3 + 1e-9, (bearing_deg, bow_deg, times)
            line_track, _ = fly(start, heading, current, 1.3, until=lambda t, p, psi: holds(p, psi, axis))
            t, p, psi = line_track[-1]
            lined_up.append(t if holds(p, psi, axis) else 60.0)
    assert max(times) < 10.0, times
    assert sum(times) < sum(lined_up), (times, lined_up)


def test_a_boat_that_holds_its_ground_at_speed_0_is_modelled_so_and_turned_onto_its_line() -> None:
    """A rudder boat whose motor does not reverse and whose autopilot holds its ground at speed 0 (no stop
    controller), 0.37 m from the goal and 47 deg off its line in a current toward N (stop 49's trace): a search that
    drifted its model boat at speed 0 sent 0 for 20 s, and the boat crept across the goal still 47 deg off its line,
    held along its heading. Knowing (``holds_at_rest``), the search turns it to within the hold's take-on for a boat
    that goes ahead only (within CAPTURE_M, FERRY_RAD off its line: law/line_approach.py)."""
    current, axis = np.array([0.03, 0.0]), math.pi  # toward N: the bow's end of the line upstream (S)

    def taken_on(t: float, p: np.ndarray, psi: float) -> bool:
        return float(np.hypot(*p)) <= CAPTURE_M and abs(wrap_pi(psi - axis)) <= FERRY_RAD

    start, heading = np.array([-0.27, -0.25]), math.radians(133.0)
    track, fastest = fly(start, heading, current, 0.6, limit_s=20.0, until=taken_on, holds_ground=True, astern=False)
    t, p, psi = track[-1]
    assert taken_on(t, p, psi), (t, p.round(3).tolist(), math.degrees(psi))
    assert fastest <= 0.3


@pytest.mark.parametrize("kinematic", [False, True])
def test_the_search_models_the_circle_it_sees_the_boat_turn_on_in_its_own_manoeuvres(
    monkeypatch: pytest.MonkeyPatch, kinematic: bool
) -> None:
    """The simulator's rudder boat, 0.86 m at speed in a hard turn, turns on a far wider circle in a manoeuvre's 2 s
    at 0.12 m/s from the way it had (its rudder force grows with the speed squared; its rudder and yaw take time to
    come round): the search learns that circle from its own manoeuvres, not the one it was given. A kinematic boat
    that turns on its 1.2 m circle at any speed is seen on that one. Both fly the search's commands (velocity + yaw)
    beside a line through a goal 0.35 m to starboard, in still water."""
    if kinematic:
        kinematic_rudder.install(monkeypatch, radius_m=1.2)
    boat, flow = make_boat("rudder")  # at the origin, bow north
    search, goal, axis = CaptureSearch(max_speed_mps=0.3), np.array([0.0, 0.35]), 0.0
    for _ in range(200):  # 20 s
        truth = boat.truth()
        h = unit(truth.psi)
        water = float(np.array([truth.vn, truth.ve]) @ h)
        m = search.command(boat.t, np.array([truth.n, truth.e]), goal, truth.psi, water, axis, None, 0.86, None)
        v = m.velocity_ned
        fly_boat(boat, flow, 0.1, mask=MASK_VELOCITY_YAW, velocity=(float(v[0]), float(v[1])), yaw=m.heading_rad)
    assert search.radius_seen_m is not None
    if kinematic:
        assert search.radius_seen_m == pytest.approx(1.2, abs=0.15)
    else:
        assert 1.25 <= search.radius_seen_m <= MAX_RADIUS_M  # 0.86 m was what it was given


def test_before_a_circle_is_seen_the_search_widens_the_one_given_to_its_manoeuvres_speed() -> None:
    """A circle measured at 0.24 m/s is a rudder boat's at speed: at a manoeuvre's 0.12 m/s the search's model turns
    on one twice as wide (at low speed a rudder's circle widens in inverse proportion to the speed), never on a
    tighter one than given, within its clamps; once its own manoeuvres show a circle, that one."""
    search = CaptureSearch(max_speed_mps=0.3)
    assert search.model_radius_m(1.2, 0.12) == pytest.approx(1.2)  # no speed known: as given
    search.circle_speed_mps = 0.24
    assert search.model_radius_m(1.2, 0.12) == pytest.approx(2.4)
    assert search.model_radius_m(1.2, 0.3) == pytest.approx(1.2)  # faster than measured: as given
    assert search.model_radius_m(2.0, 0.12) == MAX_RADIUS_M and search.model_radius_m(0.3, 0.24) == MIN_RADIUS_M
    search.radius_seen_m = 1.7
    assert search.model_radius_m(1.2, 0.12) == 1.7
    search.forget()  # another boat
    assert search.radius_seen_m is None and search.model_radius_m(1.2, 0.12) == pytest.approx(2.4)
