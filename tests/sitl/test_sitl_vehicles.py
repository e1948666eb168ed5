"""The vehicle family: each kind's dynamics (open loop) and ArduPilot's guided semantics on each (closed loop).

Open loop: steady speed and rise time, turning circle, turning with no way through the water, lateral
thrust, drift with the current. Closed loop (the boat's own autopilot, no sockets): zero velocity means
north, velocity + yaw holds a heading at speed 0 or reverses, speed is held over ground along the
heading in a cross current, velocity setpoints are steered to while driving, pivot turns (toward a
position) only on the skid-steer boat, LOITER drifts inside LOIT_RADIUS.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sitl.config import VehicleKind
from sitl.vehicles import body_force
from sitl.vessel import steady_surge_speed
from tests.support.open_water import current, fly, make_boat, run

KINDS = ("diff_thrust", "rudder", "vectored")
AHEAD = {"diff_thrust": (1.0, 1.0), "rudder": (1.0, 0.0), "vectored": (1.0, 1.0, 0.0, 0.0)}
FULL_TURN = {"diff_thrust": (1.0, 0.0), "rudder": (1.0, 1.0), "vectored": (1.0, 1.0, 1.0, -1.0)}
TURN_ON_THE_SPOT = {"diff_thrust": (1.0, -1.0), "rudder": (0.0, 1.0), "vectored": (0.0, 0.0, 1.0, -1.0)}
# steady turning-circle diameter at the full-turn command [m] (measured; bounds +-15 %)
TURNING_DIAMETER_M = {"diff_thrust": 3.75, "rudder": 2.07, "vectored": 2.03}
VELOCITY, VELOCITY_YAW, POSITION = 3559, 2535, 0b110111111000  # type masks
T, N, E, PSI, VN, VE = range(6)  # trajectory columns
DIFF_PARAMS = make_boat("diff_thrust")[0].params
RUDDER_PARAMS = make_boat("rudder")[0].params


def pivot_creep_mps(boat) -> float:
    """Steady surge speed of a full pivot, (T_fwd - T_rev) / |X_u|: reverse thrust is weaker [m/s]."""
    hull = boat.params.hull
    return (hull.k_forward - hull.k_reverse) * hull.n_max**2 / -hull.x_u


def heading_deg(traj: np.ndarray) -> float:
    return math.degrees(traj[-1, PSI])


def distance_moved(traj: np.ndarray) -> float:
    return float(math.hypot(traj[-1, N] - traj[0, N], traj[-1, E] - traj[0, E]))


# ---- open loop ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", KINDS)
def test_full_ahead_reaches_the_same_top_speed_with_the_hull_time_constant(kind):
    boat, flow = make_boat(kind)
    traj = run(boat, flow, 15.0, AHEAD[kind])
    u = traj[:, VN]  # heading north: V_N is the surge speed
    assert u[-1] == pytest.approx(steady_surge_speed(boat.params.hull, 0.3), abs=1e-3)  # 0.40 m/s
    t63 = traj[np.argmax(u >= 0.63 * u[-1]), T]
    assert 1.3 < t63 < 1.7  # (m - X_udot) / |X_u| = 1.47 s, plus the motor lag
    assert abs(traj[-1, E]) < 1e-9 and abs(traj[-1, PSI]) < 1e-9  # straight, no sway


@pytest.mark.parametrize("kind", KINDS)
def test_turning_circle(kind):
    boat, flow = make_boat(kind)
    run(boat, flow, 10.0, AHEAD[kind])
    run(boat, flow, 30.0, FULL_TURN[kind])  # settle into the turn
    r = boat.state[5]
    speed = math.hypot(boat.truth().vn, boat.truth().ve)
    diameter = 2.0 * speed / r
    assert r > 0  # a positive command turns to starboard
    assert diameter == pytest.approx(TURNING_DIAMETER_M[kind], rel=0.15)
    # the track is a circle of that diameter: one full revolution spans it north and east
    revolution = run(boat, flow, 2.0 * math.pi / r, FULL_TURN[kind])
    span_n = np.ptp(revolution[:, N])
    span_e = np.ptp(revolution[:, E])
    assert span_n == pytest.approx(diameter, rel=0.03) and span_e == pytest.approx(diameter, rel=0.03)


def test_with_no_way_the_rudder_boat_cannot_turn_while_the_others_turn_on_the_spot():
    turned = {}
    for kind in KINDS:
        boat, flow = make_boat(kind)
        traj = run(boat, flow, 10.0, TURN_ON_THE_SPOT[kind])
        turned[kind] = (math.degrees(np.unwrap(traj[:, PSI])[-1]), distance_moved(traj))
    assert turned["rudder"] == (0.0, 0.0)  # full rudder, no way: nothing at all
    assert turned["diff_thrust"][0] > 60.0  # pivots (and creeps ahead: reverse thrust is weaker)
    assert turned["vectored"][0] > 60.0 and turned["vectored"][1] < 1e-6  # a pure couple


def test_only_the_vectored_boat_thrusts_sideways():
    boat, flow = make_boat("vectored")
    traj = run(boat, flow, 15.0, (0.0, 0.0, 1.0, 1.0))  # both tunnel thrusters to starboard
    lateral = boat.params.lateral
    expected = 2 * lateral.k * boat.params.hull.n_max**2 / 5.0  # 2 T_L / |Y_v| = 0.1 m/s
    assert traj[-1, VE] == pytest.approx(expected, rel=0.01) and abs(traj[-1, VN]) < 1e-9
    assert abs(heading_deg(traj)) < 1e-9  # bow and stern push equally: no yaw


@given(
    n=st.tuples(*[st.floats(-50.0, 50.0)] * 2),
    nu=st.tuples(*[st.floats(-0.5, 0.5)] * 3),
    delta=st.floats(-0.7, 0.7),
)
def test_no_sideways_force_without_lateral_thrusters(n, nu, delta):
    assert DIFF_PARAMS.kind is VehicleKind.DIFF_THRUST and RUDDER_PARAMS.kind is VehicleKind.RUDDER
    x = (0.0, 0.0, 0.3, *nu, *n)
    assert body_force(x, DIFF_PARAMS)[1] == 0.0
    # the rudder's force needs way through the water: none at u_r = 0, whatever the rudder angle
    rudder_x = (0.0, 0.0, 0.3, 0.0, nu[1], nu[2], n[0], delta)
    tau = body_force(rudder_x, RUDDER_PARAMS)
    assert tau[1] == 0.0 and tau[2] == 0.0


@pytest.mark.parametrize("kind", KINDS)
def test_without_thrust_every_kind_drifts_at_exactly_the_current(kind):
    boat, flow = make_boat(kind, overrides=current(0.07, 200.0))
    boat.state = (*boat.state[:3], 0.2, -0.05, 0.1, *boat.state[6:])  # moving and turning through the water
    run(boat, flow, 25.0, (0.0,) * len(AHEAD[kind]))
    truth = boat.truth()
    a = math.radians(200.0)
    assert truth.vn == pytest.approx(0.07 * math.cos(a), abs=1e-6)
    assert truth.ve == pytest.approx(0.07 * math.sin(a), abs=1e-6)


# ---- closed loop: ArduPilot's guided semantics on each kind --------------------------------------------
@pytest.mark.parametrize(("kind", "turns_north"), [("diff_thrust", True), ("rudder", False), ("vectored", True)])
def test_zero_velocity_means_heading_north_at_speed_zero(kind, turns_north):
    boat, flow = make_boat(kind, pose=(0.0, 0.0, 90.0))  # at rest, heading east
    traj = fly(boat, flow, 20.0, mask=VELOCITY, velocity=(0.0, 0.0))
    if turns_north:
        assert abs(heading_deg(traj)) < 5.0
    else:  # no way through the water, no steering: still heading east
        assert abs(heading_deg(traj) - 90.0) < 2.0
    # speed 0: it never drives; only the skid-steer pivot creeps, no faster than its thrust asymmetry allows
    creep = pivot_creep_mps(boat) if kind == "diff_thrust" else 0.005
    assert np.hypot(traj[:, VN], traj[:, VE]).max() < 1.05 * creep


@pytest.mark.parametrize("kind", KINDS)
def test_velocity_and_yaw_holds_a_heading_at_speed_zero_and_reverses(kind):
    boat, flow = make_boat(kind, pose=(0.0, 0.0, 90.0))
    east = math.radians(90.0)
    traj = fly(boat, flow, 15.0, mask=VELOCITY_YAW, velocity=(0.0, 0.0), yaw=east)
    assert abs(heading_deg(traj) - 90.0) < 3.0 and distance_moved(traj) < 0.05
    traj = fly(boat, flow, 15.0, mask=VELOCITY_YAW, velocity=(-0.15, 0.0), yaw=east)  # vx < 0: astern
    settled = traj[-500:]
    assert abs(heading_deg(traj) - 90.0) < 5.0
    assert np.mean(settled[:, VE]) == pytest.approx(-0.15, abs=0.015)  # backing west over ground
    assert abs(np.mean(settled[:, VN])) < 0.015


@pytest.mark.parametrize("kind", KINDS)
def test_speed_is_held_over_ground_along_the_heading_and_a_cross_current_sets_the_boat_sideways(kind):
    boat, flow = make_boat(kind, overrides=current(0.05, 90.0))
    traj = fly(boat, flow, 20.0, mask=VELOCITY, velocity=(0.3, 0.0))
    settled = traj[-500:]
    assert np.mean(settled[:, VN]) == pytest.approx(0.3, abs=0.01)
    assert np.mean(settled[:, VE]) == pytest.approx(0.05, abs=0.01)  # not corrected: set east
    assert abs(heading_deg(traj)) < 3.0


@pytest.mark.parametrize("kind", KINDS)
def test_a_velocity_setpoint_behind_is_steered_to_while_driving_no_pivot(kind):
    boat, flow = make_boat(kind)  # heading north, asked to go south at 0.3 m/s (HeadingAndSpeed)
    traj = fly(boat, flow, 40.0, mask=VELOCITY, velocity=(-0.3, 0.0))
    error = 180.0 - np.degrees(np.abs(traj[:, PSI]))
    speed = np.hypot(traj[:, VN], traj[:, VE])
    assert speed[error > 60.0].max() > 0.15  # it drives while the error is still large
    assert abs(heading_deg(traj)) > 175.0 and np.mean(speed[-300:]) == pytest.approx(0.3, abs=0.02)


@pytest.mark.parametrize(("kind", "pivots"), [("diff_thrust", True), ("rudder", False), ("vectored", False)])
def test_only_the_skid_steer_boat_pivots_toward_a_position_target(kind, pivots):
    boat, flow = make_boat(kind)  # heading north; the target lies 100 deg to starboard, 1.5 m away
    bearing = math.radians(100.0)
    goal = (1.5 * math.cos(bearing), 1.5 * math.sin(bearing))
    traj = fly(boat, flow, 40.0, mask=POSITION, position=goal)
    to_goal = np.degrees(np.arctan2(goal[1] - traj[:, E], goal[0] - traj[:, N]))
    error = np.abs((to_goal - np.degrees(traj[:, PSI]) + 180.0) % 360.0 - 180.0)
    speed = np.hypot(traj[:, VN], traj[:, VE])
    turning = error > 70.0  # beyond WP_PIVOT_ANGLE (60 deg), with a margin for the exit at 10 deg
    if pivots:  # turns on the spot (creeping as above) while the error exceeds WP_PIVOT_ANGLE
        assert speed[turning].max() < 1.05 * pivot_creep_mps(boat)
    else:
        assert speed[turning].max() > 0.05  # drives while it turns
    distance = np.hypot(traj[:, N] - goal[0], traj[:, E] - goal[1])
    # it gets there (within WP_RADIUS) or, the rudder boat, passes it no farther than its turning radius
    assert distance.min() < (0.5 * TURNING_DIAMETER_M[kind] if kind == "rudder" else 0.1)
    if kind != "rudder":  # ... and stops, loitering within LOIT_RADIUS
        assert distance[-1] < boat.autopilot.params.get("LOIT_RADIUS") and speed[-1] < 0.02
    # (a point inside the rudder boat's turning circle cannot be reached: it keeps circling near it)


@pytest.mark.parametrize("kind", KINDS)
def test_loiter_drifts_inside_loit_radius_and_drives_back_outside(kind):
    boat, flow = make_boat(kind, overrides=current(0.05, 90.0))
    traj = fly(boat, flow, 110.0, mode="LOITER")
    point = boat.autopilot.hold_point
    distance = np.hypot(traj[:, N] - point[0], traj[:, E] - point[1])
    radius = boat.autopilot.params.get("LOIT_RADIUS")
    assert radius == 2.0  # ArduPilot's default
    inside = traj[distance < 0.9 * radius]
    assert np.mean(inside[:, VE]) == pytest.approx(0.05, abs=0.01)  # drifting with the current
    assert 1.9 < distance.max() < 2.6  # driven back once outside
    assert distance[-1] < 2.6


@pytest.mark.parametrize("kind", KINDS)
def test_speed_zero_brakes_then_the_boat_drifts_with_the_current(kind):
    boat, flow = make_boat(kind, overrides=current(0.15, 0.0))  # faster than the 0.1 m/s stop speed
    fly(boat, flow, 10.0, mask=VELOCITY, velocity=(0.3, 0.0))  # 0.3 m/s north over ground
    traj = fly(boat, flow, 20.0, mask=VELOCITY_YAW, velocity=(0.0, 0.0), yaw=0.0)  # speed 0, keep north
    vn = traj[:, VN]
    assert np.argmax(vn <= 0.1) * 0.01 < 2.0  # braked below the stop speed (coasting never would here)
    # then throttle off for good (ArduPilot's stop controller latches): carried along at the current
    assert np.mean(vn[-300:]) == pytest.approx(0.15, abs=0.01)
    assert boat.autopilot.control.throttle == 0.0 and boat.autopilot.control.stopped
    assert abs(heading_deg(traj)) < 3.0  # still holding the heading


@pytest.mark.parametrize("kind", KINDS)
def test_velocity_and_yaw_over_mavlink_on_every_kind(gcs_and_sim, kind):
    records: list[dict] = []
    gcs, _ = gcs_and_sim({"vehicle": kind, "start_poses": [[2.25, 0.3, 60.0]]}, records)  # heading 060
    gcs.mav.request_data_stream_send(1, 1, 6, 10, 1)  # POSITION at 10 Hz
    gcs.wait_type("LOCAL_POSITION_NED")
    assert gcs.set_mode(15).result == 0 and gcs.arm().result == 0
    east = math.radians(90.0)
    samples = []

    def send(speed):
        def each(m):
            gcs.velocity(speed, 0.0, mask=VELOCITY_YAW, yaw=east)
            if m.get_type() == "LOCAL_POSITION_NED":
                samples.append((gcs.t, m.vx, m.vy))
            elif m.get_type() == "ATTITUDE":
                samples.append((gcs.t, m.yaw))

        return each

    gcs.run_for(12.0, send(0.15))  # heading east at 0.15 m/s (the rudder boat turns while it drives)
    velocities = [s for s in samples if len(s) == 3][-10:]
    assert np.mean([s[2] for s in velocities]) == pytest.approx(0.15, abs=0.03)
    assert abs(np.mean([s[1] for s in velocities])) < 0.03
    samples.clear()
    gcs.run_for(8.0, send(0.0))  # speed 0, keep heading east: stops, does not turn north
    yaws = [math.degrees(s[1]) for s in samples if len(s) == 2]
    assert min(yaws) > 80.0 and max(yaws) < 100.0
    assert math.hypot(*[np.mean([s[k] for s in samples if len(s) == 3][-10:]) for k in (1, 2)]) < 0.03
    assert not [r for r in records if r["kind"] == "wall"]
