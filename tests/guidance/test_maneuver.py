"""Heading-and-speed commands for any boat (law/maneuver.py, law/line_approach.py, estimation/turning.py) and
their encoding on the wire (mavlink/rover.py): pure functions, property-based where the claim is general.

Conventions: NED [m], [m/s]; headings [rad] from north.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from koopguide.guidance import settings as guidance_settings
from koopguide.guidance.estimation.turning import RATE_FLOOR, TurnAbility
from koopguide.guidance.law.approach_path import MIN_SPEED_MPS as PATH_MIN_SPEED_MPS
from koopguide.guidance.law.approach_path import STEP_M, STOP_GAIN, ApproachPath
from koopguide.guidance.law.capture import ENTRY_RAD
from koopguide.guidance.law.command import CURRENT_MIN_MPS
from koopguide.guidance.law.creep_cycle import BACK_MARGIN_MPS, CREEP_M, CREEP_MPS, HOLD_WAY_MPS
from koopguide.guidance.law.edge_reversal import EDGE_LEG_M
from koopguide.guidance.law.line_approach import LineApproach
from koopguide.guidance.law.maneuver import (
    ASTERN_RAD,
    CHASE_S,
    DRIFT_ENTER,
    DRIFT_LEAVE,
    HOLDING_ASTERN_RAD,
    MIN_SPEED_MPS,
    Maneuver,
    ManeuverPlanner,
    within_speed,
    wrap_pi,
)
from koopguide.mavlink.rover import MASK_VELOCITY_YAW, float32_toward_zero, velocity_setpoint

angles = st.floats(-math.pi, math.pi, allow_nan=False)
speeds = st.floats(0.01, 0.3, allow_nan=False)
currents = st.just(0.0) | st.floats(1.01 * CURRENT_MIN_MPS, 0.05)  # below CURRENT_MIN_MPS an estimate is noise

FERRY_RAD = math.radians(guidance_settings.load().arrival.facing_deg)  # the shipped ferry-glide angle (Helm)


def unit(angle: float) -> np.ndarray:
    return np.array([math.cos(angle), math.sin(angle)])


def pivoting() -> TurnAbility:
    return TurnAbility()  # until seen otherwise, a boat turns in place


def rudder() -> TurnAbility:
    ability = TurnAbility()
    ability.needs_way = True
    return ability


def rover_ground_velocity(heading: float, speed: float, current: np.ndarray) -> np.ndarray:
    """What ArduPilot Rover makes good for heading + signed speed: the speed over ground along the heading
    is held, the current's component across the heading is not corrected; a speed of exactly 0 is the stop
    controller, throttle off, and the boat drifts with the current (docs/rover.md)."""
    if speed == 0.0:
        return current
    h = unit(heading)
    n = np.array([-h[1], h[0]])
    return speed * h + float(current @ n) * n


@settings(max_examples=300, deadline=None)
@given(direction=angles, speed=speeds, c_dir=angles, c_speed=currents)
def test_on_course_the_command_makes_good_exactly_the_wanted_ground_velocity(direction, speed, c_dir, c_speed) -> None:
    v, c = speed * unit(direction), c_speed * unit(c_dir)
    planner = ManeuverPlanner(max_speed_mps=1.0, way_mps=0.15, ferry_rad=FERRY_RAD)
    first = planner.plan(v, 0.0, c, pivoting())
    m = planner.plan(v, first.heading_rad, c, pivoting())  # the boat now faces the commanded heading
    made_good = rover_ground_velocity(m.heading_rad, m.speed_mps, c)
    if abs(float(v @ unit(m.heading_rad))) >= MIN_SPEED_MPS:  # not the tiny holding speed
        assert np.allclose(made_good, v, atol=1e-9)
    if c_speed == 0.0:
        assert (m.speed_mps < 0) == m.astern  # in still water astern is backward over ground
    assert float(np.hypot(*m.velocity_ned)) == pytest.approx(abs(m.speed_mps))


@settings(max_examples=300, deadline=None)
@given(direction=angles, heading=angles, speed=speeds)
def test_ahead_or_astern_needs_no_turn_beyond_the_astern_angle(direction, heading, speed) -> None:
    planner = ManeuverPlanner(max_speed_mps=1.0, way_mps=0.15, ferry_rad=FERRY_RAD)
    m = planner.plan(speed * unit(direction), heading, None, pivoting())
    assert abs(wrap_pi(m.heading_rad - heading)) <= ASTERN_RAD + 1e-9
    assert m.astern == (abs(wrap_pi(direction - heading)) > ASTERN_RAD)
    travel = unit(m.heading_rad) * math.copysign(1.0, m.speed_mps)
    assert float(travel @ unit(direction)) == pytest.approx(1.0)  # it goes the wanted way, bow first or not


def test_astern_has_hysteresis_so_a_goal_abeam_does_not_flip_it_every_command() -> None:
    planner = ManeuverPlanner(max_speed_mps=1.0, way_mps=0.15, ferry_rad=FERRY_RAD)
    behind = unit(math.radians(170.0)) * 0.1
    assert planner.plan(behind, 0.0, None, pivoting()).astern
    abeam_aft = unit(math.radians(110.0)) * 0.1  # ahead would need 110 deg: astern (70 deg) is kept
    assert planner.plan(abeam_aft, 0.0, None, pivoting()).astern
    forward = unit(math.radians(40.0)) * 0.1  # astern would need 140 deg > 120: ahead again
    assert not planner.plan(forward, 0.0, None, pivoting()).astern


@settings(max_examples=300, deadline=None)
@given(
    heading=angles,
    c_dir=angles,
    c_speed=st.floats(1.01 * CURRENT_MIN_MPS, 0.1),
    wanted=st.floats(0.0, 0.3),
    w_dir=angles,
)
def test_keeping_station_in_a_current_the_hull_stays_on_its_line_at_the_nearer_end(
    heading, c_dir, c_speed, wanted, w_dir
) -> None:
    """Whatever ground velocity the station keeper wants (even the current's own, where the water velocity
    vanishes and its direction is noise), a boat holding in a current is sent a heading within the ferry angle of
    the current's line, bow upstream or downstream, whichever turns it less (past HOLDING_ASTERN_RAD)."""
    ferry = math.radians(30.0)
    planner = ManeuverPlanner(max_speed_mps=0.3, way_mps=0.15, ferry_rad=ferry)
    c = c_speed * unit(c_dir)
    m = planner.plan(wanted * unit(w_dir), heading, c, pivoting(), distance_m=0.1, holding=True)
    upstream = c_dir + math.pi
    off_line = abs(wrap_pi(m.heading_rad - upstream))
    off_line = min(off_line, math.pi - off_line)  # the hull's line, either end
    assert off_line <= ferry + 1e-9
    to_upstream = abs(wrap_pi(upstream - heading))
    if to_upstream < math.pi - HOLDING_ASTERN_RAD - 1e-6:
        assert not m.astern and abs(wrap_pi(m.heading_rad - upstream)) <= ferry + 1e-9
    elif to_upstream > HOLDING_ASTERN_RAD + 1e-6:
        assert m.astern and abs(wrap_pi(m.heading_rad - upstream - math.pi)) <= ferry + 1e-9
    assert abs(wrap_pi(m.heading_rad - heading)) <= HOLDING_ASTERN_RAD + ferry + 1e-9
    assert abs(m.speed_mps) <= 0.3 + 1e-12 and math.isfinite(m.speed_mps)


def test_keeping_station_the_ferry_angle_sets_the_boat_across_the_current_the_way_it_is_wanted() -> None:
    """Rover holds the ground speed along the heading; the current's component across a hull turned delta off its
    line sets the boat sideways at |c| sin delta: toward the side the station keeper asks for, ahead or astern."""
    c = np.array([0.0, 0.03])  # toward the east: upstream is west
    for heading in (-math.pi / 2 + 0.2, math.pi / 2 - 0.2):  # bow upstream (ahead), bow downstream (astern)
        for north in (0.02, -0.02):
            planner = ManeuverPlanner(max_speed_mps=0.3, way_mps=0.15, ferry_rad=FERRY_RAD)
            m = planner.plan(np.array([north, 0.0]), heading, c, pivoting(), holding=True)
            assert m.astern == (heading > 0)
            made_good = rover_ground_velocity(m.heading_rad, m.speed_mps, c)
            assert made_good[0] * north > 0  # it is set the way it should go
            assert abs(made_good[1]) < 0.01  # ... and held against the current


@settings(max_examples=300, deadline=None)
@given(
    heading=angles,
    c_dir=angles,
    c_speed=st.floats(1.01 * CURRENT_MIN_MPS, 0.1),
    w_frac=st.floats(0.0, 0.999 * DRIFT_ENTER),
    w_dir=angles,
)
def test_making_for_a_point_at_nearly_the_currents_velocity_a_boat_drifts_on_its_line_as_it_lies(
    heading, c_dir, c_speed, w_frac, w_dir
) -> None:
    """A goal just downstream: the ground velocity wanted is nearly the current's, and the water velocity w that
    remains turns with every tick. A boat that turns in place is not turned after it (bow downstream, the
    simulator's boat pivoted after it 0.3 m short of the goal for 25 s): its hull goes onto the current's line at
    the nearer end, as when it keeps station, and what it makes good is off the wanted ground velocity by less than
    |w| (the part of w across the hull, which Rover does not correct)."""
    ferry = math.radians(30.0)
    planner = ManeuverPlanner(max_speed_mps=0.3, way_mps=0.15, ferry_rad=ferry)
    c = c_speed * unit(c_dir)
    v = c + w_frac * c_speed * unit(w_dir)
    m = planner.plan(v, heading, c, pivoting(), distance_m=0.3)
    assert planner.drifting
    upstream = c_dir + math.pi
    off_line = abs(wrap_pi(m.heading_rad - upstream))
    assert min(off_line, math.pi - off_line) <= ferry + 1e-9  # on the line, either end
    to_upstream = abs(wrap_pi(upstream - heading))
    if to_upstream > HOLDING_ASTERN_RAD + 1e-6:  # bow downstream already: it stays so, stern to the current
        assert m.astern and abs(wrap_pi(m.heading_rad - heading)) <= math.pi - HOLDING_ASTERN_RAD + ferry + 1e-9
    m = planner.plan(v, m.heading_rad, c, pivoting(), distance_m=0.3)  # once it lies so
    if abs(float(v @ unit(m.heading_rad))) >= MIN_SPEED_MPS:
        made_good = rover_ground_velocity(m.heading_rad, m.speed_mps, c)
        assert float(np.hypot(*(made_good - v))) <= w_frac * c_speed + 1e-9


def test_drifting_onto_a_point_has_hysteresis_and_is_for_boats_that_turn_in_place_near_a_point() -> None:
    c = np.array([-0.03, 0.0])  # toward the south
    across = unit(math.pi / 2)  # w across the current, east
    planner = ManeuverPlanner(max_speed_mps=0.3, way_mps=0.15, ferry_rad=FERRY_RAD)
    between = 0.5 * (DRIFT_ENTER + DRIFT_LEAVE)
    for frac, drifting in [(0.5 * DRIFT_ENTER, True), (between, True), (1.1 * DRIFT_LEAVE, False)]:
        planner.plan(c + frac * 0.03 * across, math.pi, c, pivoting(), distance_m=0.3)
        assert planner.drifting == drifting, frac
    planner.plan(c + between * 0.03 * across, math.pi, c, pivoting(), distance_m=0.3)
    assert not planner.drifting  # between the two: it does not begin to drift
    planner = ManeuverPlanner(max_speed_mps=0.3, way_mps=0.15, ferry_rad=FERRY_RAD)
    m = planner.plan(c + 0.1 * 0.03 * across, math.pi, c, pivoting())  # following the field, no point: along w
    assert not planner.drifting and abs(wrap_pi(m.heading_rad - math.atan2(across[1], across[0]))) < 1e-9
    planner.plan(c + 0.1 * 0.03 * across, math.pi, c, rudder(), distance_m=0.3)  # a rudder boat has its line approach
    assert not planner.drifting


@settings(max_examples=200, deadline=None)
@given(error=st.floats(0.05, math.radians(119.0)), distance=st.floats(0.05, 1.0), rate=st.floats(0.05, 0.5))
def test_a_boat_that_turns_in_place_is_slowed_until_its_turning_circle_reaches_the_point(error, distance, rate) -> None:
    ability = pivoting()
    ability.turn_rate = rate
    planner = ManeuverPlanner(max_speed_mps=0.3, way_mps=0.15, ferry_rad=FERRY_RAD)
    m = planner.plan(unit(error) * 0.3, 0.0, None, ability, distance_m=distance)
    heading_error = abs(wrap_pi(m.heading_rad))
    radius = abs(m.speed_mps) / rate  # the circle it turns on at this speed [m]
    if abs(m.speed_mps) > MIN_SPEED_MPS:
        assert radius <= distance / (2.0 * math.sin(heading_error)) + 1e-9  # it can still reach the point
    assert abs(m.speed_mps) <= 0.3 * max(math.cos(heading_error), 0.0) + MIN_SPEED_MPS + 1e-12


@settings(max_examples=200, deadline=None)
@given(error=st.floats(math.radians(16.0), math.radians(119.0)), wanted=st.floats(0.001, 0.3))
def test_a_boat_that_needs_way_keeps_way_while_it_turns(error, wanted) -> None:
    planner = ManeuverPlanner(max_speed_mps=0.3, way_mps=0.15, ferry_rad=FERRY_RAD)
    m = planner.plan(unit(error) * wanted, 0.0, None, rudder())
    assert abs(m.speed_mps) >= 0.15 - 1e-12


def test_turn_ability_tells_a_pivoting_boat_from_one_that_needs_way() -> None:
    asked = math.radians(90.0)
    skid = TurnAbility()
    for k in range(40):  # at a standstill, turning at 7 deg/s toward a heading 90 deg off
        skid.update(0.05 * k, asked, 0.0, math.radians(7.0))
    assert skid.pivot_seen and not skid.needs_way and skid.turn_rate == pytest.approx(math.radians(7.0))
    boat = TurnAbility()
    for k in range(30):  # 1.5 s stuck: not yet
        boat.update(0.05 * k, asked, 0.01, math.radians(0.5))
    assert not boat.needs_way
    for k in range(30, 60):
        boat.update(0.05 * k, asked, 0.01, math.radians(0.5))
    assert boat.needs_way and boat.turn_rate == pytest.approx(RATE_FLOOR)
    for k in range(60, 100):  # turning at 0.2 m/s at 8 deg/s: a circle of 1.43 m
        boat.update(0.05 * k, asked, 0.2, math.radians(8.0))
    assert boat.radius_m == pytest.approx(0.2 / math.radians(8.0), rel=0.2)
    assert boat.radius_speed_mps == pytest.approx(0.2)  # the speed the circle was measured at
    for k in range(100, 140):  # a wider circle at a lower speed keeps the tighter one and its speed
        boat.update(0.05 * k, asked, 0.1, math.radians(2.0))
    assert boat.radius_m == pytest.approx(0.2 / math.radians(8.0), rel=0.2) and boat.radius_speed_mps == 0.2
    reversing = TurnAbility()  # passing through zero speed while still turning is not a turn in place
    for k, u in enumerate(np.linspace(0.15, -0.15, 12)):
        reversing.update(0.05 * k, asked, float(u), math.radians(6.0))
    assert not reversing.pivot_seen


@pytest.mark.parametrize("current", [None, np.array([0.03, 0.0])])
def test_line_approach_backs_down_onto_the_goal_and_steers_onto_the_line(current) -> None:
    line = LineApproach(max_speed_mps=0.3, gain_per_s=0.5, settle_m=0.05, way_mps=0.15, approach_mps=0.15)
    goal = np.zeros(2)
    p = np.array([-0.5, 0.2])  # 0.5 m south of the goal, 0.2 m east of it
    line.aim(p, goal, heading_rad=math.pi, current_ned=current)  # the boat faces south
    m = line.command(p, goal, heading_rad=math.pi, radius_m=0.8, current_ned=current)
    travel = -unit(m.heading_rad)  # astern: it moves opposite its bow
    assert m.astern and m.speed_mps < 0
    assert float(travel @ (goal - p)) > 0  # toward the goal
    if current is None:  # still water: the line from the boat to the goal, bow the way it already faces
        assert abs(wrap_pi(line.axis_rad - math.atan2(-0.2, 0.5) - math.pi)) < 1e-9
    else:  # a current toward the north: bow upstream (south); the goal lies downstream, so astern
        assert abs(wrap_pi(line.axis_rad - math.pi)) < 1e-9
        assert travel[1] < 0  # ... and drifting west, back onto the line through the goal
        assert abs(wrap_pi(m.heading_rad - math.pi)) < math.radians(30.0)  # bow still about upstream


@settings(max_examples=300, deadline=None)
@given(vn=st.floats(-1.0, 1.0), ve=st.floats(-1.0, 1.0), yaw=angles)
def test_a_setpoint_with_yaw_is_read_by_rover_as_astern_exactly_when_it_points_behind(vn, ve, yaw) -> None:
    msg = velocity_setpoint((1, 1), 0, (vn, ve), yaw)
    assert msg.type_mask == MASK_VELOCITY_YAW and msg.yaw == pytest.approx(yaw)
    assert math.hypot(msg.vx, msg.vy) == pytest.approx(math.hypot(vn, ve), rel=1e-6, abs=1e-6)  # float32 wire
    along = vn * math.cos(yaw) + ve * math.sin(yaw)
    if abs(along) > 1e-6 and abs(vn) > 1e-6:
        assert (msg.vx < 0) == (along < 0)  # Rover: a negative vx with yaw means astern
    if (vn < 0) == (along < 0):  # where both readings agree, the true NED vector goes (a velocity follower's)
        assert (msg.vx, msg.vy) == (pytest.approx(vn, abs=1e-6), pytest.approx(ve, abs=1e-6))


def wire(x: float) -> float:
    """``x`` as MAVLink carries it (float32, rounded to nearest)."""
    return float(np.float32(x))


@settings(max_examples=500, deadline=None)
@given(
    heading=angles,
    ratio=st.one_of(st.just(1.0), st.floats(0.0, 3.0)),
    top=st.one_of(st.just(0.3), st.floats(0.01, 5.0)),
    yaw=st.one_of(st.none(), angles),
)
def test_no_setpoint_is_over_max_speed_even_by_a_rounding_neither_computed_nor_on_the_wire(
    heading: float, ratio: float, top: float, yaw: float | None
) -> None:
    """A velocity along any heading at up to 3 x max_speed (exactly max_speed half the time: 0.3 m/s along 167 of
    3600 headings is 0.30000000000000004 long), shortened by ``within_speed``: never longer than max_speed, as
    computed nor as sent (MAVLink's float32, with or without the yaw that turns it into +-|v| north), the same
    direction, and no shorter than asked beyond a float32 rounding."""
    v = ratio * top * unit(heading)
    vn, ve = within_speed(v, top)
    assert math.hypot(vn, ve) <= top
    assert math.hypot(wire(vn), wire(ve)) <= top
    msg = velocity_setpoint((1, 1), 0, (vn, ve), yaw)
    assert math.hypot(wire(msg.vx), wire(msg.vy)) <= top
    asked = min(float(np.hypot(*v)), top)
    assert math.hypot(vn, ve) == pytest.approx(asked, rel=1e-6, abs=1e-12)
    assert abs(vn * v[1] - ve * v[0]) <= 1e-6 * top * top  # along the velocity asked


def test_float32_toward_zero_is_a_float32_never_larger_than_asked() -> None:
    for x in (0.3, -0.3, 0.1, 1.0, 0.0, -1e-9, 123.456):
        y = float32_toward_zero(x)
        assert (
            wire(y) == y
            and abs(y) <= abs(x)
            and abs(x) - abs(y) <= 1.2e-7 * abs(x)
            and math.copysign(1, y) == math.copysign(1, x)
        )


def test_ahead_goes_as_velocity_only_and_astern_or_a_hold_with_the_yaw() -> None:
    from koopguide.guidance.helm import Helm
    from koopguide.guidance.law.maneuver import Maneuver

    helm = Helm.__new__(Helm)  # only the conversion is exercised
    helm.asked_heading, helm.t = None, None
    v, yaw = helm._maneuver(Maneuver(0.5, 0.1, False))
    assert yaw is None and np.allclose(v, 0.1 * unit(0.5))
    v, yaw = helm._maneuver(Maneuver(0.5, -0.1, True))
    assert yaw == 0.5 and np.allclose(v, -0.1 * unit(0.5))
    v, yaw = helm._maneuver(Maneuver(0.5, 0.0, True))
    assert yaw == 0.5 and np.allclose(v, 0.0)


def test_line_approach_k_turns_toward_one_heading_ahead_then_astern_about_where_it_began() -> None:
    """At the goal, facing across the current's line: legs ahead and astern in turn, both toward the same heading
    (the autopilot reverses the rudder astern, so both legs turn the bow the same way)."""
    line = LineApproach(max_speed_mps=0.3, gain_per_s=0.5, settle_m=0.05, way_mps=0.15, approach_mps=0.15)
    goal, current, heading = np.zeros(2), np.array([0.03, 0.0]), math.pi / 2  # current toward N, bow E
    line.aim(goal, goal, heading, current)
    first = line.command(goal, goal, heading, radius_m=1.3, current_ned=current)
    assert abs(wrap_pi(line.axis_rad)) < 1e-9 or abs(wrap_pi(line.axis_rad - math.pi)) < 1e-9  # along the current
    assert not first.astern and first.speed_mps >= 0.15  # way on: the rudder turns the boat only with it
    p = np.array([0.0, 0.35])  # the leg went 0.35 m ahead (east), past the leash
    line.aim(p, goal, heading, current)
    second = line.command(p, goal, heading, radius_m=1.3, current_ned=current, water_mps=0.0)
    assert second.astern and second.speed_mps <= -0.15
    assert abs(wrap_pi(second.heading_rad - first.heading_rad)) < math.radians(25.0)  # the same way round


def test_line_approach_reverses_before_the_area_edge_and_lets_the_current_carry_it_where_the_rudder_would_err() -> None:
    line = LineApproach(max_speed_mps=0.3, gain_per_s=0.5, settle_m=0.05, way_mps=0.15, approach_mps=0.15)
    goal = np.zeros(2)
    p = np.array([0.0, -0.6])  # 0.6 m west of the goal, on the line of a still-water approach, bow east
    line.aim(p, goal, math.pi / 2, None)
    assert not line.command(p, goal, math.pi / 2, radius_m=1.0).astern  # ahead to the goal
    edge = line.command(p, goal, math.pi / 2, radius_m=1.0, speed_mps=0.2, outside=lambda q: max(q[1] + 0.5, 0.0))
    assert edge.astern  # 0.1 m short of an edge at E -0.5 (the goal beyond it): not out of the area
    # bow upstream (current toward N, bow S), 0.04 m upstream of the goal: backing down at 0.02 m/s over ground would
    # still have the water pass the rudder from ahead; the service sends speed 0 (throttle off) and the current
    # carries the boat back
    hold = LineApproach(max_speed_mps=0.3, gain_per_s=0.5, settle_m=0.05, way_mps=0.15, approach_mps=0.15)
    current, p = np.array([0.03, 0.0]), np.array([-0.04, 0.0])
    hold.aim(p, goal, math.pi, current)
    assert hold.command(p, goal, math.pi, radius_m=1.3, current_ned=current).speed_mps == 0.0


def test_holding_in_a_current_creeps_upstream_across_the_goal_then_drifts_back_across_it() -> None:
    """A cycle about the goal long enough for the rudder to act: the boat creeps CREEP_M upstream (way on, at
    least CREEP_MPS over ground) from half of it downstream of the goal, then drifts back with the throttle off
    (speed 0) as far, not in bursts of a few centimetres (the bow would not answer them)."""
    line = LineApproach(max_speed_mps=0.3, gain_per_s=0.5, settle_m=0.075, way_mps=0.15, approach_mps=0.15)
    goal, current, bow = np.zeros(2), np.array([0.03, 0.0]), math.pi  # current toward N, bow upstream (S)

    def at(north: float) -> Maneuver:
        p = np.array([north, 0.0])
        line.aim(p, goal, bow, current)
        return line.command(p, goal, bow, radius_m=1.3, current_ned=current, t=0.0)

    half = 0.5 * CREEP_M  # the cycle runs from half of it downstream of the goal to half of it upstream
    cycle = [at(north) for north in (half + 0.01, 0.0, -half + 0.01, -half - 0.01, 0.0, half - 0.01, half + 0.01)]
    assert line.holding
    assert all(abs(wrap_pi(m.heading_rad - bow)) < 1e-6 for m in cycle)  # on the line, bow upstream
    creep, drift = cycle[:3] + cycle[-1:], cycle[3:6]
    assert all(m.speed_mps >= CREEP_MPS and not m.astern for m in creep)  # ahead, upstream
    assert all(m.speed_mps == 0.0 for m in drift)  # the current carries it back


@pytest.mark.parametrize("astern", [False, True])
@pytest.mark.parametrize("holds_at_rest", [False, True])
def test_holding_a_boat_that_holds_its_ground_at_speed_0_it_is_backed_down_onto_the_goal(
    astern: bool, holds_at_rest: bool
) -> None:
    """An autopilot without Rover's stop controller holds the boat's ground at speed 0: a rudder boat whose hold
    began 0.2 m upstream of the goal sat there for good, sent 0 (an independent kinematic rudder boat, current
    toward N: 0 of 3 arrived). Such a boat (learned by the helm, estimation/speed_lag.py ``RestHold``) is backed
    down, over ground downstream faster than the current (the water past the rudder from astern), until the creep
    begins; any other is sent 0 and the current carries it."""
    line = LineApproach(max_speed_mps=0.3, gain_per_s=0.5, settle_m=0.075, way_mps=0.15, approach_mps=0.15)
    line.cycle.holds_at_rest = holds_at_rest
    goal, current = np.zeros(2), np.array([0.03, 0.0])  # toward N: upstream is S
    bow = 0.0 if astern else math.pi  # astern the bow lies downstream (N), ahead upstream (S)

    def at(north: float, t: float) -> Maneuver:
        p = np.array([north, 0.0])
        line.aim(p, goal, bow, current)
        return line.command(p, goal, bow, radius_m=1.3, current_ned=current, t=t)

    sent = [at(north, 0.2 * k) for k, north in enumerate(np.linspace(-0.2, -0.07, 20))]  # upstream of the goal
    assert line.holding
    if not holds_at_rest:
        assert all(m.speed_mps == 0.0 for m in sent)  # the current carries it: speed 0 throughout
        return
    for m in sent:
        downstream = float(m.velocity_ned @ current) / 0.03
        assert downstream >= 0.03 + BACK_MARGIN_MPS - 1e-9  # faster than the current: the water from astern
        assert m.astern != astern  # stern first through the water (bow upstream), ahead when the bow is downstream
        assert abs(wrap_pi(m.heading_rad - bow)) < 1e-6  # along the line
    # backed down onto the goal, it creeps again from half of CREEP_M downstream of it (and is still backed down
    # on the way, never sent 0 again: the boat holds its ground at rest)
    assert at(-0.05, 12.2).velocity_ned @ current > 0.0  # downstream
    creep = at(0.5 * CREEP_M + 0.01, 12.4)
    assert creep.velocity_ned @ current < 0.0 and creep.astern == astern  # upstream again, the hold's own way


def test_holding_off_the_line_a_creep_slows_to_its_end_instead_of_coasting_past_it() -> None:
    """Off the line the creep's speed is the offset's (way for the rudder), but it slows to CREEP_MPS at the
    creep's end, CREEP_M / 2 past the goal: coasting on from 0.09 m/s, boats ran 0.11-0.14 m past the goal and,
    0.17 m off the line, beyond 0.2 m from it (the default campaign's rudder start 5 toward S, stop 31)."""
    line = LineApproach(max_speed_mps=0.3, gain_per_s=0.5, settle_m=0.075, way_mps=0.15, approach_mps=0.15)
    goal, current, bow = np.zeros(2), np.array([0.03, 0.0]), math.pi  # current toward N, bow upstream (S)

    def at(north: float, east: float) -> Maneuver:
        p = np.array([north, east])
        line.aim(p, goal, bow, current)
        return line.command(p, goal, bow, radius_m=1.3, current_ned=current, t=0.0)

    half = 0.5 * CREEP_M
    at(half + 0.01, 0.05)  # taken on near the line
    assert line.holding
    creep = [at(north, 0.17).speed_mps for north in np.linspace(half + 0.01, -half + 0.01, 13)]
    assert creep[0] > 2.5 * CREEP_MPS  # way on while the creep has room
    assert all(b <= a + 1e-12 for a, b in itertools.pairwise(creep))  # slowing all the way
    assert CREEP_MPS <= creep[-1] <= CREEP_MPS + 0.5 * 0.01 + 1e-9  # at its end, the creep's own speed
    assert at(-half - 0.01, 0.17).speed_mps == 0.0  # then the current carries it back


@pytest.mark.parametrize("astern", [False, True])
def test_holding_righting_the_bow_goes_no_more_than_creep_m_past_the_goal_then_drifts_back(astern: bool) -> None:
    """With the bow 30 deg off, righting keeps way on upstream, but only to CREEP_M past the goal; then the boat
    drifts back (speed 0) onto the goal and rights the bow on the next creep. It used to run on: astern, where the
    rudder is weak, 0.3 m and more upstream (hold p95 of 0.30-0.32 m in uniform currents); ahead, 0.27 m, beyond
    the reacquire radius."""
    line = LineApproach(max_speed_mps=0.3, gain_per_s=0.5, settle_m=0.075, way_mps=0.15, approach_mps=0.15)
    goal, current = np.zeros(2), np.array([0.03, 0.0])  # toward N: upstream is S
    on_line = 0.0 if astern else math.pi  # astern the bow lies downstream (N), ahead upstream (S)
    off = wrap_pi(on_line + math.radians(30.0))
    sign = -1.0 if astern else 1.0

    def at(north: float, bow: float) -> Maneuver:
        p = np.array([north, 0.0])
        line.aim(p, goal, bow, current)
        return line.command(p, goal, bow, radius_m=1.3, current_ned=current, t=0.0)

    at(0.05, on_line)  # taken on, holding
    assert line.holding and line.astern == astern
    righting = [at(north, off) for north in (0.0, -0.05, -0.1)]  # upstream of the goal, still within CREEP_M
    assert all(sign * m.speed_mps > 0.0 and m.astern == astern for m in righting)  # way on, upstream
    back = [at(north, off) for north in (-CREEP_M - 0.01, -0.05, 0.0, 0.5 * CREEP_M + 0.01, CREEP_M - 0.01)]
    # beyond CREEP_M: drift back, all the way onto the goal and on (righting 30 deg on a 1.3 m circle runs further
    # upstream than CREEP_M: its creep begins CREEP_M downstream, the most righting may run past the goal)
    assert all(m.speed_mps == 0.0 for m in back)
    assert sign * at(CREEP_M + 0.01, off).speed_mps > 0.0  # then a creep upstream again, righting on the way


@pytest.mark.parametrize(
    ("radius_m", "off_deg", "start"),
    [
        (0.56, 35.0, 0.111),  # a 2.72 s turn and 1 s coasting on, at 0.06 m/s over ground: a 0.223 m run
        (0.8, 50.0, CREEP_M),  # a 0.43 m run: from CREEP_M, as far as righting may run past the goal
        (0.56, 15.0, 0.5 * CREEP_M),  # within the righting threshold: no righting
    ],
)
def test_holding_a_creep_that_rights_the_bow_begins_half_its_run_downstream_of_the_goal(
    radius_m: float, off_deg: float, start: float
) -> None:
    """Drifting back onto the goal (from beyond CREEP_M upstream, where righting stops) a boat has no water past its
    rudder: its bow stays as the hold found it. A no-astern rudder boat (0.56 m circle) held 35 deg off was righted
    from CREEP_M / 2 downstream and ran 0.19 m upstream, 0.19 m from the goal. A creep that rights the bow begins half
    its run downstream instead: the turn down to half the righting threshold at HOLD_WAY_MPS over ground (the
    current's speed more through the water), then the way dying over the stopping time; at least CREEP_M / 2, at most
    CREEP_M. A bow within the threshold creeps from CREEP_M / 2 as before."""
    line = LineApproach(max_speed_mps=0.3, gain_per_s=0.5, settle_m=0.075, way_mps=0.15, approach_mps=0.15)
    line.stop_s = 1.0
    goal, current, bow = np.zeros(2), np.array([0.03, 0.0]), math.pi  # current toward N, bow upstream (S)

    def at(north: float, heading: float) -> Maneuver:
        p = np.array([north, 0.0])
        line.aim(p, goal, heading, current)
        return line.command(p, goal, heading, radius_m=radius_m, current_ned=current, t=0.0)

    off = wrap_pi(bow + math.radians(off_deg))
    at(-CREEP_M - 0.03, bow)  # taken on beyond CREEP_M upstream of the goal
    assert line.holding
    drifting = [at(north, off).speed_mps for north in np.linspace(-CREEP_M - 0.02, start - 0.005, 12)]
    assert all(s == 0.0 for s in drifting)  # the current carries it down, no creep yet
    creep = at(start + 0.005, off).speed_mps
    assert creep >= (HOLD_WAY_MPS if off_deg > 20.0 else CREEP_MPS)  # then way on upstream (righting the bow)


@pytest.mark.parametrize("off_deg", [8.0, 20.0])
def test_a_planned_path_is_driven_to_its_end_before_the_hold_takes_over(off_deg: float) -> None:
    """0.3 m downstream of the goal on the current's line (toward W), the bow 8 deg off upstream: near enough to
    hold, but a planned path under way is driven to its end first (its last leg lines the bow up); once it is done,
    the hold takes over from the same pose. 20 deg off is not near enough (the hold takes a boat on only lined up
    as well as the capture search hands one over, ENTRY_RAD: taken on 20-25 deg off, its righting set boats across
    their line and held them at 0.3-0.7 m p95): within CAPTURE_M of the goal the capture search lines it up."""
    line = LineApproach(max_speed_mps=0.3, gain_per_s=0.5, settle_m=0.05, way_mps=0.15, approach_mps=0.15)
    goal, current = np.zeros(2), np.array([0.0, -0.03])  # upstream is east
    p, heading = np.array([0.0, -0.3]), math.radians(90.0 + off_deg)
    line.aim(p, goal, heading, current)
    assert line.path.plan(0.0, p, heading, goal, (math.pi / 2, -math.pi / 2), 1.3, None, current)
    m = line.command(p, goal, heading, radius_m=1.3, current_ned=current, t=0.05)
    assert not line.holding
    if off_deg > math.degrees(ENTRY_RAD):
        assert line.capture.active and not line.path.active
        return
    assert line.path.active and not line.capture.active
    line.path.reset()  # the path driven (or abandoned): the same pose is held
    line.command(p, goal, heading, radius_m=1.3, current_ned=current, t=0.1)
    assert line.holding
    fresh = ApproachPath(cruise_mps=0.15, max_speed_mps=0.3)  # the path's own command, not the hold's
    assert fresh.plan(0.0, p, heading, goal, (math.pi / 2, -math.pi / 2), 1.3, None, current)
    expected = fresh.command(0.05, p, heading, current)
    assert expected is not None and m.heading_rad == pytest.approx(expected.heading_rad)


def test_a_reversal_at_the_area_edge_keeps_its_new_way_for_a_leg_so_the_bow_can_turn() -> None:
    """Reversed before the edge, the boat backs away EDGE_LEG_M before it goes ahead again: not a shuttle of a few
    centimetres each way (each reversal holds the heading while the boat stops, so the bow never turned, and a boat
    in the area's corner saw-toothed there for a minute)."""
    goal, bow = np.zeros(2), math.pi / 2  # bow east, toward the goal beyond an edge at E -0.5

    def outside(q: np.ndarray) -> float:
        return max(float(q[1]) + 0.5, 0.0)

    def at(line: LineApproach, east: float) -> Maneuver:
        p = np.array([0.0, east])
        line.aim(p, goal, bow, None)
        return line.command(p, goal, bow, radius_m=1.0, speed_mps=0.2, outside=outside)

    def approach() -> LineApproach:
        return LineApproach(max_speed_mps=0.3, gain_per_s=0.5, settle_m=0.05, way_mps=0.15, approach_mps=0.15)

    assert not at(approach(), -0.75).astern  # 0.25 m from the edge, ahead does not yet lead out
    line = approach()
    assert at(line, -0.6).astern  # 0.1 m from it, ahead would: reversed
    for east in (-0.65, -0.75, -0.6 - EDGE_LEG_M + 0.02):  # backing away, the leg goes on
        assert at(line, east).astern, east
    assert not at(line, -0.6 - EDGE_LEG_M - 0.02).astern  # the leg driven: ahead again


@pytest.mark.parametrize("holding", [False, True])
def test_a_held_current_line_turns_slowly_toward_the_estimate_and_a_line_not_held_at_once(holding: bool) -> None:
    """The current's line is held only in water not seen to be sheared, where the current is steady: an estimate
    whose direction swings by 20 deg for 2 s (the hull's own sway read as current) turns a held line by about 2 deg;
    a swing that lasts turns it all the way within a few AXIS_TAU_S. A line not yet held follows the estimate at
    once (stop 35)."""
    from koopguide.guidance.law.line_approach import AXIS_TAU_S

    line = LineApproach(max_speed_mps=0.3, gain_per_s=0.5, settle_m=0.05, way_mps=0.15, approach_mps=0.15)
    goal, p = np.zeros(2), np.array([0.02, 0.0])
    north = np.array([0.03, 0.0])  # toward north: the bow upstream faces south
    line.aim(p, goal, math.pi, north, t=0.0)
    assert abs(wrap_pi(line.axis_rad - math.pi)) < 1e-9
    line.holding = holding
    swung = 0.03 * np.array([math.cos(math.radians(20.0)), math.sin(math.radians(20.0))])
    upstream = math.atan2(-swung[1], -swung[0])  # -160 deg
    for k in range(1, 21):  # 2 s of the swung estimate
        line.aim(p, goal, math.pi, swung, t=0.1 * k)
    turned = abs(wrap_pi(line.axis_rad - math.pi))
    if not holding:
        assert abs(wrap_pi(line.axis_rad - upstream)) < 1e-9
        return
    assert turned == pytest.approx(math.radians(20.0) * (1.0 - math.exp(-2.0 / AXIS_TAU_S)), rel=0.05)
    for k in range(21, round(5.0 * AXIS_TAU_S / 0.1)):  # it lasts: the line follows it
        line.aim(p, goal, math.pi, swung, t=0.1 * k)
    assert abs(wrap_pi(line.axis_rad - upstream)) < math.radians(0.2)


@pytest.mark.parametrize("stop_s", [1.0 / STOP_GAIN, 3.0, 6.0])
def test_a_boat_slow_to_stop_is_ramped_onto_the_goal_no_faster_than_it_can_stop(stop_s: float) -> None:
    """From speed u a boat told to stop runs on about u tau (estimation/speed_lag.py): the line's feedback and the
    planned approach's runs ask at most distance / tau, so a heavy hull does not run past the goal (one of twice the
    mass with a weak astern ran 0.2 m past it on the ramps made for the simulator's boats)."""
    line = LineApproach(max_speed_mps=0.3, gain_per_s=0.5, settle_m=0.05, way_mps=0.15, approach_mps=0.25)
    line.stop_s = stop_s
    goal, heading = np.zeros(2), 0.0
    p = np.array([-0.4, 0.0])  # on the line, 0.4 m short of the goal, facing it
    line.aim(p, goal, heading, None)
    m = line.command(p, goal, heading, radius_m=None)  # no circle yet: feedback along the line
    assert not m.astern and m.speed_mps == pytest.approx(0.4 * min(0.5, 1.0 / stop_s))
    assert m.speed_mps * stop_s <= 0.4 + 1e-9  # its run-on from that speed ends by the goal
    line.command(p, goal, heading, radius_m=1.2, t=0.0)  # the planned approach's ramps too
    assert line.path.stop_gain == pytest.approx(min(STOP_GAIN, 1.0 / stop_s))
    far = np.array([-3.0, 1.0])  # a path planned from afar: each run's end is ramped down to by its stop gain
    path = line.path
    assert path.plan(0.0, far, heading, goal, None, 1.2, None, None)
    slowing = []
    for k, (n, e, h, _) in enumerate(path.samples[:-1]):
        m = path.command(0.1 * k, np.array([n, e]), h, None)  # the boat on the path, in still water
        if m is None:
            break
        remaining = STEP_M * (path.run_end(path.i) - path.i)  # along the run to its end [m]
        if remaining < 0.3:
            slowing.append(abs(m.speed_mps) <= max(PATH_MIN_SPEED_MPS, path.stop_gain * remaining) + 1e-9)
    assert slowing and all(slowing)


@pytest.mark.parametrize("toward_deg", [None, 0.0, 90.0, 180.0, 270.0])
@pytest.mark.parametrize("facing_deg", [0.0, 90.0, 180.0, 270.0])
def test_a_boat_that_goes_ahead_only_is_never_sent_astern_by_the_line_approach(
    toward_deg: float | None, facing_deg: float
) -> None:
    """A boat seen to gather no sternway (estimation/speed_lag.py SternwayTrial), past the goal or beside it, facing
    any way, its circle not yet measured (feedback, no plan): no K-turn legs astern and no reversal astern; in a
    current it holds bow upstream, and a goal behind it in still water it turns round to (stop 48)."""
    line = LineApproach(max_speed_mps=0.3, gain_per_s=0.5, settle_m=0.05, way_mps=0.15, approach_mps=0.15)
    line.astern_able = False
    current = None if toward_deg is None else 0.03 * unit(math.radians(toward_deg))

    def edge(q: np.ndarray) -> np.ndarray:  # a square area 0.9 m across about the goal: the boat starts by its edge
        return np.maximum(np.abs(np.asarray(q, dtype=float)).max(axis=-1) - 0.45, 0.0)

    goal = np.zeros(2)
    for p in (np.array([0.4, 0.0]), np.array([0.0, 0.4]), np.array([-0.3, -0.3])):
        heading = math.radians(facing_deg)
        line.reset()
        line.aim(p, goal, heading, current)
        if current is not None:  # bow upstream, whichever way it faces
            assert abs(wrap_pi(line.axis_rad - math.atan2(-current[1], -current[0]))) < 1e-9
        m = line.command(p, goal, heading, radius_m=None, current_ned=current, outside=edge)
        if current is None:
            assert not m.astern and m.speed_mps >= 0.0


def pivot_after(
    planner: ManeuverPlanner, target_rate_degps: float, seconds: float, holding: bool = False
) -> tuple[list[bool], list[float]]:
    """A boat that pivots at 7 deg/s toward the heading it is sent, from north, sent toward a point whose bearing
    starts 80 deg to starboard and turns at ``target_rate_degps`` (a current carries the boat round its goal), making
    for it or (``holding``) keeping station: the planner's ahead/astern choices and the heading errors, tick by tick
    (0.2 s)."""
    rate, dt, heading = math.radians(7.0), 0.2, 0.0
    asterns, errors = [], []
    for k in range(round(seconds / dt)):
        t = k * dt
        wanted = 0.2 * unit(math.radians(80.0 + target_rate_degps * t))
        m = planner.plan(wanted, heading, None, pivoting(), distance_m=0.45, holding=holding, t=t)
        error = wrap_pi(m.heading_rad - heading)
        heading = wrap_pi(heading + math.copysign(min(abs(error), rate * dt), error))
        asterns.append(m.astern)
        errors.append(abs(error))
    return asterns, errors


def test_a_boat_that_turns_in_place_chasing_a_heading_that_turns_as_fast_takes_the_other_end_to_meet_it() -> None:
    """The bearing of the goal turns as fast as the boat pivots (stop 56: a diff-thrust boat carried round its goal by
    the double gyre chased it for a minute): after CHASE_S the other end of the line, turning the other way, meets
    it."""
    planner = ManeuverPlanner(max_speed_mps=0.3, way_mps=0.15, ferry_rad=FERRY_RAD)
    asterns, errors = pivot_after(planner, 7.0, 30.0)
    assert not any(asterns[: round(CHASE_S / 0.2)])  # ahead first: 80 deg off
    assert min(errors[: round(CHASE_S / 0.2)]) > math.radians(75.0)  # and never closing on it
    assert any(asterns)
    met = next(i for i, e in enumerate(errors) if e < math.radians(5.0)) * 0.2
    assert met < 2.0 * CHASE_S  # astern, turning to port toward a heading that turns to starboard


@pytest.mark.parametrize("target_rate_degps", [0.0, 3.0, -3.0])
def test_a_turn_in_place_that_closes_on_its_heading_keeps_its_end(target_rate_degps: float) -> None:
    """A still heading, or one turning slower than the boat: the boat closes on it ahead, as it began."""
    planner = ManeuverPlanner(max_speed_mps=0.3, way_mps=0.15, ferry_rad=FERRY_RAD)
    asterns, errors = pivot_after(planner, target_rate_degps, 40.0)
    assert not any(asterns)
    assert errors[-1] < math.radians(1.0)


def test_a_turn_watched_again_after_a_gap_is_judged_afresh() -> None:
    """A command without the planner (a hold, a tick without a heading) leaves a gap: the turn before it is no chase
    (one call 80 deg off, then 20 s later 60 deg further round and still 80 deg off: no flip on that tick)."""
    planner = ManeuverPlanner(max_speed_mps=0.3, way_mps=0.15, ferry_rad=FERRY_RAD)
    assert not planner.plan(0.2 * unit(math.radians(80.0)), 0.0, None, pivoting(), distance_m=0.45, t=0.0).astern
    later = planner.plan(0.2 * unit(math.radians(140.0)), math.radians(60.0), None, pivoting(), distance_m=0.45, t=20.0)
    assert not later.astern


def test_keeping_station_no_chase_is_watched() -> None:
    """Holding station (here in still water, where no current's line is held) the chase is not watched: the bearing
    that turns as fast as the boat pivots keeps its end (ahead)."""
    planner = ManeuverPlanner(max_speed_mps=0.3, way_mps=0.15, ferry_rad=FERRY_RAD)
    asterns, _ = pivot_after(planner, 7.0, 30.0, holding=True)
    assert not any(asterns)
