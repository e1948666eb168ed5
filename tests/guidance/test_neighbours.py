"""The separation filter of the service (koopguide.guidance.neighbours) on boats that move as a Rover boat
does: along their heading, at the setpoint's speed, turning at a few degrees per second (pure math, no
simulator; the simulator's encounters are tests/harness/test_fleet_encounters.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from koopguide.guidance import events as ev
from koopguide.guidance import settings
from koopguide.guidance.law.separation import Neighbour
from koopguide.guidance.neighbours import BRAKE_MPS2, ESTIMATE_M, REACTION_S, TURN_CREEP_M, Neighbours

FLEET = settings.load().fleet
D_MIN = FLEET.min_separation_m

# A skid-steer boat as measured in the bundled simulator (docs/fleet.md): turn rate <= 7 deg/s, speed along
# the heading following the setpoint's with a 0.5 s lag, braking <= 0.3 m/s^2, and while pivoting (heading
# error > 60 deg) it creeps ahead at 8.5 mm/s (0.11 m per 90 deg).
TURN_RATE = math.radians(7.0)  # [rad/s]
SPEED_LAG_S = 0.5
ACCEL = 0.3  # [m/s^2]
CREEP_MPS = 0.0085
DT = 0.05  # [s]
ARRIVAL_M = 0.1  # a boat this close to its goal holds there [m]


def fly_pair(starts, headings_deg, goals, current=(0.0, 0.0), duration_s: float = 150.0):
    """Two boats, each going to its goal (speed 0.5/s x distance, <= 0.3 m/s, slowed by cos(heading error))
    until within ARRIVAL_M, each filtering its setpoint with Neighbours from the other's status (published every
    step, DT old): (closest distance [m], final distances to the goals [m], whether each arrived)."""
    p = [np.array(s, dtype=float) for s in starts]
    psi = [math.radians(h) for h in headings_deg]
    u = [0.0, 0.0]  # speed along the heading through the water [m/s]
    vel = [np.zeros(2), np.zeros(2)]
    ids = ("boat1", "boat2")
    filters = [Neighbours(i, FLEET, 0.3) for i in ids]
    c = np.array(current, dtype=float)
    closest, t = math.inf, 0.0
    arrived = [False, False]
    while t < duration_s:
        for k in (0, 1):
            j = 1 - k
            filters[k].hear(ev.NeighbourStatus(t, t - DT, ids[j], tuple(p[j] - DT * vel[j]), tuple(vel[j]), DT))
        out = []
        for k in (0, 1):
            to_goal = np.asarray(goals[k]) - p[k]
            dist = float(np.hypot(*to_goal))
            arrived[k] = arrived[k] or dist <= ARRIVAL_M
            if arrived[k]:  # arrived: holds there (speed 0 at its heading)
                out.append(np.zeros(2))
                continue
            bow = np.array([math.cos(psi[k]), math.sin(psi[k])])
            speed = min(0.3, 0.5 * dist) * max(float(to_goal @ bow) / max(dist, 1e-9), 0.0)
            cmd = to_goal / max(dist, 1e-9) * max(speed, 0.002)
            out.append(np.array(filters[k].keep_separation(p[k], tuple(cmd), t, t, psi[k], vel[k]).velocity_ned))
        for k in (0, 1):
            want = out[k]
            if not np.any(want):
                u[k], vel[k] = 0.0, c.copy()
                p[k] = p[k] + vel[k] * DT
                continue
            error = (math.atan2(want[1], want[0]) - psi[k] + math.pi) % (2 * math.pi) - math.pi
            psi[k] += float(np.clip(2.0 * error, -TURN_RATE, TURN_RATE)) * DT
            du = (float(np.hypot(*want)) - u[k]) / SPEED_LAG_S
            u[k] += float(np.clip(du, -ACCEL, ACCEL)) * DT
            creep = CREEP_MPS if abs(error) > math.radians(60.0) else 0.0
            vel[k] = (u[k] + creep) * np.array([math.cos(psi[k]), math.sin(psi[k])]) + c
            p[k] = p[k] + vel[k] * DT
        closest = min(closest, float(np.hypot(*(p[0] - p[1]))))
        t += DT
    errors = [float(np.hypot(*(p[k] - np.asarray(goals[k])))) for k in (0, 1)]
    return closest, errors, arrived


@pytest.mark.parametrize(
    ("starts", "headings", "goals"),
    [
        pytest.param([(0.0, -2.0), (0.0, 2.0)], [90.0, 270.0], [(0.0, 0.25), (0.0, -0.25)], id="head-on"),
        pytest.param([(1.4, -1.4), (1.4, 1.4)], [135.0, 225.0], [(0.0, 0.25), (0.0, -0.25)], id="crossing-90"),
        pytest.param([(0.0, -2.0), (0.0, -1.2)], [90.0, 90.0], [(0.0, 0.25), (0.0, -0.25)], id="overtaking"),
    ],
)
def test_turning_boats_keep_the_separation_and_reach_their_goals(starts, headings, goals):
    closest, errors, arrived = fly_pair(starts, headings, goals)
    assert closest >= D_MIN, closest  # the true centres, never closer than min_separation_m
    assert all(arrived) and max(errors) <= 0.15, errors  # no deadlock: both at their goals


def test_allowance_is_the_estimate_error_at_rest_and_grows_with_closing_speed_facing_and_data_age():
    p = np.zeros(2)
    side = [Neighbour("b", (0.0, 0.5), (0.0, 0.0))]
    north = 0.0  # heading north; the neighbour lies east
    assert Neighbours.margins(p, np.zeros(2), side, [0.0], north)[0] == pytest.approx(ESTIMATE_M)
    facing = Neighbours.margins(p, np.zeros(2), side, [0.0], math.pi / 2)[0]
    assert facing == pytest.approx(ESTIMATE_M + TURN_CREEP_M)  # bow on: the creep of a turn away
    sweeping = Neighbours.margins(p, np.zeros(2), side, [0.0], north, 2.0)[0]
    assert sweeping == pytest.approx(facing)  # abeam, but turning to 115 deg, through the bearing (90 deg)
    turning_off = Neighbours.margins(p, np.zeros(2), side, [0.0], north, -2.0)[0]
    assert turning_off == pytest.approx(ESTIMATE_M)  # turning the other way, to 245 deg
    v = np.array([0.0, 0.3])  # closing at 0.3 m/s
    moving = Neighbours.margins(p, v, side, [0.0], math.pi / 2)[0]
    assert moving == pytest.approx(facing + 0.3 * REACTION_S + 0.3**2 / (2 * BRAKE_MPS2))  # reaction + braking
    older = Neighbours.margins(p, v, side, [0.5], math.pi / 2)[0]
    assert older == pytest.approx(moving + 0.5 * BRAKE_MPS2 * 0.5**2)  # moved on, but unsure by as much
    away = Neighbours.margins(p, -v, side, [0.0], -math.pi / 2)[0]
    assert away == pytest.approx(ESTIMATE_M)  # going away, stern on: nothing more
    coming = [Neighbour("b", (0.0, 0.5), (0.0, -0.01))]  # the neighbour creeps toward this boat
    assert Neighbours.margins(p, np.zeros(2), coming, [0.0], north)[0] == pytest.approx(
        ESTIMATE_M + 0.01 * REACTION_S + TURN_CREEP_M
    )


def test_a_boat_bow_on_to_a_neighbour_at_the_barrier_slows_to_turn_instead_of_driving_on():
    """The failure seen with the simulator: the filter's setpoint pointed away, but Rover drives along the
    heading (toward the neighbour) while it turns, so the speed must be capped, not only the direction."""
    f = Neighbours("boat2", FLEET, 0.3)
    f.hear(ev.NeighbourStatus(0.0, 0.0, "boat1", (0.0, 0.55), (0.0, 0.0), 0.0))
    out = f.keep_separation(np.zeros(2), (0.0, 0.3), 0.0, 0.0, math.pi / 2, np.array([0.0, 0.05]))
    assert out.active
    assert math.hypot(*out.velocity_ned) <= 0.01  # asked 0.3 m/s; along the heading, toward boat1: next to nothing


def test_a_boat_going_astern_is_judged_by_its_stern_and_keeps_its_yaw_only_while_it_can_go_on_astern():
    """Near its slot a skid-steer boat may back onto the point (velocity + yaw, the yaw opposite the velocity):
    the filter must reason about the way it moves, along its stern."""
    f = Neighbours("boat2", FLEET, 0.3)
    f.hear(ev.NeighbourStatus(0.0, 0.0, "boat1", (0.0, -0.55), (0.0, 0.0), 0.0))  # 0.55 m to the west
    bow_east = math.pi / 2
    free = f.keep_separation(np.zeros(2), (0.05, 0.0), 0.0, 0.0, math.pi, np.zeros(2), yaw_rad=math.pi)
    assert not free.active and free.yaw_rad == math.pi  # bow south, backing north, clear of boat1: as asked
    # backing west (yaw east), stern to boat1: the speed is capped as for a bow pointed at it
    toward = f.keep_separation(np.zeros(2), (0.0, -0.1), 0.0, 0.0, bow_east, np.array([0.0, -0.05]), bow_east)
    assert toward.active and math.hypot(*toward.velocity_ned) <= 0.01
    # the same velocity and heading going ahead (no yaw): the bow points away, so the filter only shapes it
    ahead = f.keep_separation(np.zeros(2), (0.0, -0.1), 0.0, 0.0, bow_east, np.array([0.0, -0.05]))
    assert ahead.yaw_rad is None


def rover_hold_beside(helm_velocity, helm_yaw, heading_deg: float, duration_s: float = 60.0) -> float:
    """Boat2 held at (-0.35, -0.3) by a boat parked at the origin (bow north, along the current), in a 0.03 m/s current
    toward the north, asking ``helm_velocity`` [m/s] at ``helm_yaw`` [rad] (None: velocity only) each step. It moves
    as Rover does: heading toward the setpoint's (or the yaw) at <= TURN_RATE, speed over ground along the heading
    following the setpoint's signed speed, and the current's component across the heading carries it (Rover holds
    speed over ground along the heading only). Returns the closest distance to the parked boat [m]."""
    f = Neighbours("boat2", FLEET, 0.3)
    c = np.array([0.03, 0.0])
    p, psi, s = np.array([-0.35, -0.3]), math.radians(heading_deg), 0.0
    vel = np.zeros(2)
    closest, t = math.inf, 0.0
    while t < duration_s:
        f.hear(ev.NeighbourStatus(t, t - DT, "boat1", (0.0, 0.0), (0.0, 0.0), DT))
        out = f.keep_separation(p, helm_velocity, t, t, psi, vel, helm_yaw)
        v = np.array(out.velocity_ned)
        if out.yaw_rad is not None:
            want, speed = out.yaw_rad, float(v @ np.array([math.cos(out.yaw_rad), math.sin(out.yaw_rad)]))
        else:
            want, speed = math.atan2(v[1], v[0]), float(np.hypot(*v))
        error = (want - psi + math.pi) % (2 * math.pi) - math.pi
        psi += float(np.clip(2.0 * error, -TURN_RATE, TURN_RATE)) * DT
        s += (speed - s) * DT / SPEED_LAG_S
        bow = np.array([math.cos(psi), math.sin(psi)])
        vel = s * bow + (c - float(c @ bow) * bow)  # along the heading as asked; across it, the current's
        p = p + vel * DT
        closest = min(closest, float(np.hypot(*p)))
        t += DT
    return closest


@pytest.mark.parametrize("heading_deg", [-60.0, -90.0, -120.0, 60.0, 120.0])
@pytest.mark.parametrize("astern", [True, False])
def test_a_held_boat_drifting_across_its_bow_onto_a_neighbour_moves_along_its_heading_to_keep_the_gap(
    heading_deg: float, astern: bool
):
    """Two boats held side by side in a current, one bow along it, the other across it: Rover cancels the current
    only along each bow, so the second drifts at up to 0.03 m/s onto the first whatever speed >= 0 it is sent the
    way it was going (seen in the simulator: 0.46 m to 0.15 m in 14 s, the setpoint 0.001 m/s). Sent along its
    heading the other way, or on as needed, it keeps its distance, ahead or astern, with its bow held."""
    bow = math.radians(heading_deg)
    to_slot = np.array([0.05, 0.3])  # its slot lies beyond the parked boat: the helm asks toward it
    yaw = math.atan2(-to_slot[1], -to_slot[0]) if astern else None  # astern: the bow the other way
    closest = rover_hold_beside(tuple(0.001 * to_slot / np.hypot(*to_slot)), yaw, heading_deg)
    assert closest >= D_MIN, (closest, heading_deg, astern)
    # one step of the filter, as in the simulator's run: drifting in, the way it must go is along its heading
    f = Neighbours("boat2", FLEET, 0.3)
    f.hear(ev.NeighbourStatus(0.0, 0.0, "boat1", (0.0, 0.0), (0.0, 0.0), 0.0))
    p, c = np.array([-0.2, -0.38]), np.array([0.03, 0.0])
    h = np.array([math.cos(bow), math.sin(bow)])
    drift = c - float(c @ h) * h
    out = f.keep_separation(p, (0.0, 0.001), 0.0, 0.0, bow, drift, None)
    closing = -float(p @ (np.array(out.velocity_ned) + drift)) / float(np.hypot(*p))  # toward boat1 [m/s]
    gap = float(np.hypot(*p))
    allowed = FLEET.barrier_gain_per_s * (gap**2 - D_MIN**2) / (2.0 * gap)  # the barrier at D_MIN (d is wider)
    if float(-p @ drift) / gap > allowed:  # the drift carries it toward boat1 faster than the barrier allows
        assert out.active and closing <= allowed + 1e-9, (out, closing)
        along = np.array(out.velocity_ned) - float(np.array(out.velocity_ned) @ h) * h
        assert np.hypot(*along) < 1e-9  # along its heading: no turn needed


def test_a_boat_whose_way_along_its_heading_already_beats_its_drift_is_left_as_sent():
    """The answer to drift is the speed along the heading nearest to what was sent that keeps the gap: a boat going
    away from its neighbour at 0.2 m/s while the current sets it toward it at 0.02 m/s is left as sent (not slowed to
    the least speed that would do)."""
    f = Neighbours("boat2", FLEET, 0.3)
    f.hear(ev.NeighbourStatus(0.0, 0.0, "boat1", (0.0, 0.0), (0.0, 0.0), 0.0))
    p, west = np.array([-0.3, -0.3]), -math.pi / 2  # 0.42 m south-west of boat1, bow west
    drift = np.array([0.03, 0.0])  # the current toward the north, all across the bow
    assert float(drift @ -p) > 0.0  # it sets the boat toward boat1
    sent = (0.0, -0.2)
    out = f.keep_separation(p, sent, 0.0, 0.0, west, np.array(sent) + drift)
    assert not out.active and out.velocity_ned == sent
    held = f.keep_separation(p, (0.0, -0.001), 0.0, 0.0, west, drift)  # held: too slow to beat it
    assert held.active and held.velocity_ned[1] < -0.001 and abs(held.velocity_ned[0]) < 1e-12  # on west, faster
