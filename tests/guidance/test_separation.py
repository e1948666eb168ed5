"""Fleets' pure math (property-based): rendezvous slots and their assignment, the separation filter."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from koopguide.guidance.law.separation import (
    Neighbour,
    assign_slots,
    barrier_rows,
    heading_speed_cap,
    rendezvous_slots,
    separation_filter,
)

coord = st.floats(-5.0, 5.0, allow_nan=False)
point = st.tuples(coord, coord)
speed_cap = st.floats(0.05, 1.0)


def proper_crossing(p1, p2, q1, q2, tol=1e-6) -> bool:
    def orient(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])

    o1, o2, o3, o4 = orient(p1, p2, q1), orient(p1, p2, q2), orient(q1, q2, p1), orient(q1, q2, p2)
    return o1 * o2 < -tol and o3 * o4 < -tol


@settings(deadline=None)
@given(goal=point, n=st.integers(1, 9), sep=st.floats(0.1, 3.0), axis=st.floats(-360.0, 360.0))
def test_slots_are_centred_and_neighbours_exactly_separation_apart(goal, n, sep, axis):
    slots = rendezvous_slots(np.array(goal), n, sep, axis)
    assert slots.shape == (n, 2)
    np.testing.assert_allclose(slots.mean(axis=0), goal, atol=1e-9)
    if n >= 2:
        d = np.linalg.norm(slots[:, None] - slots[None], axis=2)[~np.eye(n, dtype=bool)]
        assert d.min() == pytest.approx(sep, rel=1e-9)  # no two slots closer than the separation
        steps = np.linalg.norm(np.diff(np.vstack([slots, slots[:1]]), axis=0), axis=1)[: n if n > 2 else 1]
        np.testing.assert_allclose(steps, sep, rtol=1e-9)  # neighbours on the ring exactly that far


@settings(max_examples=150, deadline=None)
@given(starts=st.lists(point, min_size=1, max_size=6, unique=True), goal=point, sep=st.floats(0.2, 2.0))
def test_assignment_is_optimal_and_paths_never_cross(starts, goal, sep):
    starts = np.array(starts)
    slots = rendezvous_slots(np.array(goal), len(starts), sep)
    chosen = assign_slots(starts, slots)
    assert sorted(chosen.tolist()) == list(range(len(starts)))  # a permutation

    def total(perm):
        return float(np.linalg.norm(starts - slots[list(perm)], axis=1).sum())

    best = min(total(p) for p in itertools.permutations(range(len(starts))))  # brute force
    assert total(chosen) <= best + 1e-9
    for i, j in itertools.combinations(range(len(starts)), 2):
        assert not proper_crossing(starts[i], slots[chosen[i]], starts[j], slots[chosen[j]])


def test_bad_slot_inputs_raise_naming_the_value():
    with pytest.raises(ValueError, match="at least 1 boat, got 0"):
        rendezvous_slots(np.zeros(2), 0, 0.5)
    with pytest.raises(ValueError, match=r"separation must be .* got -0\.5"):
        rendezvous_slots(np.zeros(2), 2, -0.5)
    with pytest.raises(ValueError, match=r"\(3, 2\) and slots \(2, 2\)"):
        assign_slots(np.zeros((3, 2)), np.zeros((2, 2)))


neighbour = st.builds(
    Neighbour,
    vehicle_id=st.sampled_from(["a", "b", "c", "m", "z"]),
    position_ned=point,
    velocity_ned=st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5)),
)


@settings(max_examples=300, deadline=None)
@given(
    own=point,
    cmd=st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0)),
    nbs=st.lists(neighbour, max_size=4),
    vmax=speed_cap,
    d=st.floats(0.1, 1.0),
    alpha=st.floats(0.1, 5.0),
    own_id=st.sampled_from(["a", "m", "z"]),
)
def test_filter_keeps_every_condition_the_speed_cap_and_passes_a_free_command(own, cmd, nbs, vmax, d, alpha, own_id):
    assume(all(math.dist(own, nb.position_ned) > 1e-3 for nb in nbs))
    out = separation_filter(own_id, np.array(own), np.array(cmd), nbs, d, alpha, vmax)
    v = out.velocity_ned
    assert np.hypot(*v) <= vmax + 1e-9  # never above the speed cap
    a, b = barrier_rows(np.array(own), nbs, d, alpha)
    if out.feasible:
        assert np.all(a @ v >= b - 1e-7)  # every barrier condition holds
    if np.hypot(*cmd) <= vmax and (len(nbs) == 0 or np.all(a @ np.array(cmd) >= b)):
        assert not out.active
        np.testing.assert_array_equal(v, cmd)  # untouched when no condition is active
    if out.feasible and not out.yielding_to:  # the projection is the closest admissible velocity
        rng = np.random.default_rng(0)
        for trial in rng.uniform(-vmax, vmax, size=(200, 2)):
            if np.hypot(*trial) <= vmax and np.all(a @ trial >= b):
                assert np.sum((v - cmd) ** 2) <= np.sum((trial - cmd) ** 2) + 1e-9


def test_a_single_neighbour_always_leaves_a_feasible_velocity_and_outside_d_stays_outside():
    # With one neighbour outside d, v = v_j + slack satisfies the condition; capped at vmax the
    # condition's boundary still passes within reach whenever |v_j| <= vmax.
    rng = np.random.default_rng(1)
    for _ in range(500):
        p, pj = rng.uniform(-2, 2, 2), rng.uniform(-2, 2, 2)
        if np.linalg.norm(p - pj) <= 0.4:
            continue
        vj = rng.uniform(-0.2, 0.2, 2)
        out = separation_filter(
            "b", p, rng.uniform(-0.3, 0.3, 2), [Neighbour("a", tuple(pj), tuple(vj))], 0.4, 1.0, 0.3
        )
        assert out.feasible


def simulate_head_on(steps: int = 4000, dt: float = 0.02, d: float = 0.4):
    """Two boats (kinematic) swapping places head-on, each filtering its go-to-goal command."""
    p = {"a": np.array([0.0, -2.0]), "b": np.array([0.0, 2.0])}
    goal = {"a": np.array([0.0, 2.0]), "b": np.array([0.0, -2.0])}
    v = {k: np.zeros(2) for k in p}
    closest = math.inf
    for _ in range(steps):
        new = {}
        for me, other in (("a", "b"), ("b", "a")):
            err = goal[me] - p[me]
            cmd = 0.5 * err
            nb = [Neighbour(other, tuple(p[other]), tuple(v[other]))]
            new[me] = separation_filter(me, p[me], cmd, nb, d, 1.0, 0.3).velocity_ned
        v = new
        for k in p:
            p[k] = p[k] + dt * v[k]
        closest = min(closest, float(np.linalg.norm(p["a"] - p["b"])))
    return p, goal, closest


def test_head_on_boats_pass_each_other_keeping_separation_and_both_arrive():
    p, goal, closest = simulate_head_on()
    assert closest >= 0.4 - 0.01  # the barrier holds (Euler steps of 0.02 s: a centimetre of slack)
    for k in p:
        assert np.linalg.norm(p[k] - goal[k]) < 0.05  # no deadlock: both reach the other's start


@pytest.mark.parametrize("own_id", ["a", "z"])  # lower or higher id than the parked boat "m": it does not matter
@pytest.mark.parametrize("goal_east", [0.0, 0.05, -0.05, 0.2])  # dead astern of it, or a little to one side
def test_a_boat_goes_round_a_parked_boat_in_its_way_and_arrives(own_id, goal_east):
    """The goal lies just beyond a boat parked at its slot: projected alone, the go-to-goal command is almost
    all toward it and the boat stalls (the barrier's deadlock); going round it, the boat arrives."""
    d, dt, parked = 0.4, 0.02, np.array([0.0, 0.0])
    p, goal = np.array([-2.0, 0.0]), np.array([0.45, goal_east])
    nb = [Neighbour("m", tuple(parked), (0.0, 0.0))]
    closest, sides = math.inf, None
    for _ in range(3000):
        out = separation_filter(own_id, p, 0.5 * (goal - p), nb, d, 1.0, 0.3, detour_sides=sides)
        sides = out.detours
        p = p + dt * out.velocity_ned
        closest = min(closest, float(np.linalg.norm(p - parked)))
    assert closest >= d - 0.01  # never into the barrier (Euler steps: a centimetre of slack)
    assert np.linalg.norm(p - goal) < 0.05, p  # round it and there


unit_angle = st.floats(-math.pi, math.pi)


@settings(max_examples=300, deadline=None)
@given(
    own=point,
    nbs=st.lists(neighbour, min_size=1, max_size=4),
    heading=unit_angle,
    drift=st.tuples(st.floats(-0.05, 0.05), st.floats(-0.05, 0.05)),
    d=st.floats(0.1, 1.0),
    alpha=st.floats(0.1, 5.0),
)
def test_heading_speed_cap_is_the_largest_speed_keeping_every_condition_along_the_heading(
    own, nbs, heading, drift, d, alpha
):
    a, b = barrier_rows(np.array(own), nbs, d, alpha)
    bow, w = np.array([math.cos(heading), math.sin(heading)]), np.array(drift)
    cap = heading_speed_cap(a, b, bow, w)
    toward = a @ bow < -1e-12  # the rows that a speed along the heading can break
    if not toward.any():
        assert cap == math.inf
        return
    assert 0.0 <= cap < math.inf
    if cap > 0.0:  # at the cap every such row holds for the velocity along the heading plus the drift...
        assert np.all((a @ (cap * bow + w) - b)[toward] >= -1e-9 * (1.0 + np.abs(b[toward])))
    faster = (a @ ((cap + 1e-6 + 1e-6 * cap) * bow + w) - b)[toward]
    assert np.any(faster < 0.0)  # ... and any faster breaks one (the cap is the largest)


@settings(max_examples=200, deadline=None)
@given(own=point, nbs=st.lists(neighbour, min_size=1, max_size=4), d=st.floats(0.2, 1.0), r=st.floats(0.05, 1.0))
def test_within_the_allowance_the_barrier_only_holds_the_gap_and_parts_the_boats_within_the_recovery_distance(
    own, nbs, d, r
):
    r = min(r, d)
    p = np.array(own)
    a, b = barrier_rows(p, nbs, d, 0.4)
    a_r, b_r = barrier_rows(p, nbs, d, 0.4, recover_within_m=r)
    np.testing.assert_array_equal(a, a_r)
    held = np.sum(a * np.array([nb.velocity_ned for nb in nbs]), axis=1)  # b of "the gap does not close"
    gap = np.array([math.dist(own, nb.position_ned) for nb in nbs])
    outside, between = gap >= d, (gap >= r) & (gap < d)
    np.testing.assert_allclose(b_r[outside], b[outside])  # outside the barrier: unchanged
    np.testing.assert_allclose(b_r[between], held[between], atol=1e-12)  # inside it: hold the gap, no more
    assert np.all(b_r[gap < r] > held[gap < r] - 1e-12)  # within r: part
    assert np.all(b_r <= b + 1e-12)  # never more demanding than without
