"""Fleets: rendezvous slots around a shared goal, and a separation filter of the commanded velocity (pure).

Conventions: positions are local NED [m] as arrays ``(N, E)``; velocities NED [m/s] ``(vN, vE)``; arrays of
several points have shape ``(n, 2)``. No I/O.

Slots. ``n`` boats sharing one goal each get a slot: one point (n = 1), two points on a line through the goal
(n = 2), or the vertices of a regular n-gon centred on it (n >= 3) whose neighbouring vertices are
``separation`` apart (circumradius ``separation / (2 sin(pi / n))``). Slots are assigned to the boats by the
minimum total *Euclidean* distance (the Hungarian method, Kuhn 1955, via
``scipy.optimize.linear_sum_assignment``): in such a matching two straight paths never cross, because
uncrossing two crossing segments shortens their total by the triangle inequality. (The minimum total
*squared* distance, as in CAPT, Turpin et al. 2014, keeps synchronised boats apart but its straight paths
can cross: e.g. starts (-1.17, 0.04), (-3.49, 0.05) to slots (-0.16, -0.16), (-0.20, -0.11).)

Separation filter. A control barrier function per neighbour j, h_j = |p - p_j|^2 - d^2 >= 0, kept by
``dh_j/dt >= -alpha h_j`` (Ames et al. 2017, "Control barrier function based quadratic programs";
Wang, Ames & Egerstedt 2017 for robot pairs), i.e. the half-plane in velocity space

    2 (p - p_j) . (v - v_j) >= -alpha (|p - p_j|^2 - d^2)                         (CBF condition)

The filtered velocity is the closest one to the command inside every half-plane and the disc |v| <= v_max
(a 2-D convex QP, solved exactly by enumerating its active sets: the command, its projections onto each
boundary, and the boundaries' pairwise intersections). Head-on encounters make the projection symmetric and
both boats stop on the line between them; the tie-breaker: a boat whose command breaks the condition for a
neighbour with a lower id (string order) first adds ``sidestep`` x |command| to the right, perpendicular to
the line to that neighbour (COLREGs rule 14: both turn to starboard when each yields), so the pair slides past.
A neighbour that is parked (slower than ``PARKED_MPS``: at its slot, or stopped itself) will not give way, and
a command straight at it projects to almost nothing (the classic deadlock of barrier filters; Wang, Ames &
Egerstedt 2017 perturb it away): a boat whose command breaks a parked neighbour's condition, whatever the ids,
goes around it, adding ``|command|`` perpendicular to the line to it on the side the command already leans to
(the shorter way round; kept while it goes round, starboard when dead ahead).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

EPS = 1e-9  # [m/s] tolerance of the constraints' check
PARKED_MPS = 0.03  # a neighbour slower than this will not give way: go around it [m/s]
SIDE_DEADBAND = 0.1  # a command leaning less than this fraction of its speed to a side keeps the side chosen before


@dataclass(frozen=True)
class Neighbour:
    """Another boat as last heard of."""

    vehicle_id: str
    position_ned: tuple[float, float]  # [m]
    velocity_ned: tuple[float, float]  # [m/s]


@dataclass(frozen=True)
class SeparationResult:
    velocity_ned: np.ndarray  # the filtered command (2,) [m/s]
    active: bool  # the command was changed
    feasible: bool  # every barrier condition and the speed cap hold at velocity_ned
    closest_m: float | None  # distance to the nearest neighbour [m]; None without neighbours
    yielding_to: tuple[str, ...]  # neighbours (lower ids) this boat sidestepped for
    detours: dict[str, int] = field(default_factory=dict)  # parked neighbours gone around: +1 starboard, -1 port


# ------------------------------------------------------------------------------------------------ slots
def rendezvous_slots(goal_ned: np.ndarray, n: int, separation_m: float, axis_deg: float = 90.0) -> np.ndarray:
    """(n, 2) slots around ``goal_ned``, neighbours ``separation_m`` apart; the first slot (n = 2: the line)
    lies along compass heading ``axis_deg`` from the goal."""
    if n < 1:
        raise ValueError(f"rendezvous slots: need at least 1 boat, got {n}")
    if not separation_m > 0.0 or not math.isfinite(separation_m):
        raise ValueError(f"rendezvous slots: separation must be a finite number > 0 m, got {separation_m}")
    goal = np.asarray(goal_ned, dtype=float).reshape(2)
    if n == 1:
        return goal[None, :].copy()
    radius = 0.5 * separation_m if n == 2 else separation_m / (2.0 * math.sin(math.pi / n))  # regular n-gon
    angles = math.radians(axis_deg) + 2.0 * math.pi * np.arange(n) / n
    return goal + radius * np.column_stack([np.cos(angles), np.sin(angles)])


def assign_slots(starts_ned: np.ndarray, slots_ned: np.ndarray) -> np.ndarray:
    """``a[i]``: the slot of boat i, minimising the total Euclidean distance from the starts (n, 2)."""
    starts, slots = np.asarray(starts_ned, dtype=float), np.asarray(slots_ned, dtype=float)
    if starts.ndim != 2 or starts.shape[1] != 2 or slots.shape != starts.shape:
        raise ValueError(f"assign slots: starts {starts.shape} and slots {slots.shape} must both be (n, 2)")
    cost = np.linalg.norm(starts[:, None, :] - slots[None, :, :], axis=2)
    from scipy.optimize import linear_sum_assignment  # Hungarian method (Kuhn 1955)

    rows, cols = linear_sum_assignment(cost)
    out = np.empty(len(starts), dtype=int)
    out[rows] = cols
    return out


def slot_goals(goal_ned: np.ndarray, starts_ned: np.ndarray, separation_m: float, axis_deg: float = 90.0) -> np.ndarray:
    """(n, 2): each boat's own goal, its assigned slot around the shared ``goal_ned``."""
    starts = np.asarray(starts_ned, dtype=float)
    slots = rendezvous_slots(goal_ned, len(starts), separation_m, axis_deg)
    return slots[assign_slots(starts, slots)]


# ----------------------------------------------------------------------------------------- the filter
def barrier_rows(
    position_ned: np.ndarray,
    neighbours: list[Neighbour],
    min_separation_m: float | np.ndarray,
    gain_per_s: float,
    recover_within_m: float | np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The CBF condition of each neighbour as ``A v >= b``: A (k, 2) [m], b (k,) [m^2/s]; the separation
    one for all or (k,) one per neighbour [m].

    Inside the barrier (h < 0) the condition asks the pair to part at alpha |h|; with ``recover_within_m``
    (< the separation) it asks that only within that distance, and between the two only that the gap does
    not close (h is raised to min(|p - p_j|^2 - r^2, 0)): a barrier grown by an allowance (a neighbour not
    heard for a while, a boat turning toward it) holds the boats where they are instead of driving them off."""
    p = np.asarray(position_ned, dtype=float)
    pj = np.array([nb.position_ned for nb in neighbours], dtype=float).reshape(-1, 2)
    vj = np.array([nb.velocity_ned for nb in neighbours], dtype=float).reshape(-1, 2)
    a = 2.0 * (p - pj)
    squared = np.sum((p - pj) ** 2, axis=1)
    h = squared - np.asarray(min_separation_m) ** 2
    if recover_within_m is not None:
        h = np.maximum(h, np.minimum(squared - np.asarray(recover_within_m) ** 2, 0.0))
    return a, np.sum(a * vj, axis=1) - gain_per_s * h


def _along_heading(
    a: np.ndarray, b: np.ndarray, heading_ned: np.ndarray, drift_ned: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each condition ``a v >= b`` for a boat moving at s h + w (speed s along the unit heading h, drift w) as
    ``along * s >= need``: (along (k,) [m], need (k,) [m^2/s])."""
    h = np.asarray(heading_ned, dtype=float).reshape(2)
    return a @ h, b - a @ np.asarray(drift_ned, dtype=float).reshape(2)


def _speed_bounds(along: np.ndarray, need: np.ndarray) -> tuple[float, float]:
    """The speeds s [m/s] that keep the conditions ``along * s >= need`` with a component along the heading:
    [lo, hi], from those facing along it (lower bounds) and against it (upper bounds); -inf / inf where none."""
    ahead, back = along > 1e-12, along < -1e-12
    lo = float(np.max(need[ahead] / along[ahead])) if ahead.any() else -math.inf
    hi = float(np.min(need[back] / along[back])) if back.any() else math.inf
    return lo, hi


def heading_speed_cap(a: np.ndarray, b: np.ndarray, heading_ned: np.ndarray, drift_ned: np.ndarray) -> float:
    """The largest setpoint speed s >= 0 [m/s] at which the boat keeps every condition ``a v >= b`` *before* it
    has turned onto the setpoint's direction; ``math.inf`` when no condition bounds it, 0 when one fails at s = 0.

    ArduPilot Rover in GUIDED reduces a velocity setpoint to a heading and a speed held over ground *along the
    boat's heading*, not along the setpoint (mode_guided.cpp, set_desired_heading_and_speed; FACTS "ArduPilot
    Rover"), and the cross-heading drift (current, sway) is not corrected. A boat that cannot move sideways
    (skid-steer, rudder) turns at a few degrees per second, so for seconds it moves at s h + w (h: the unit
    heading, w: the drift across it) whatever the setpoint's direction. Each condition a_j (s h + w) >= b_j
    with a_j . h < 0 (the bow toward the neighbour) bounds s <= (a_j . w - b_j) / (-a_j . h)."""
    _, hi = _speed_bounds(*_along_heading(a, b, heading_ned, drift_ned))
    return hi if hi == math.inf else max(0.0, hi)


def heading_escape_speed(
    a: np.ndarray, b: np.ndarray, heading_ned: np.ndarray, drift_ned: np.ndarray, vmax: float, speed_mps: float = 0.0
) -> float | None:
    """When the boat's speed ``speed_mps`` along its heading (negative: the other way) with its drift breaks a
    condition ``a v >= b`` as it moves at s h + w, holding its heading (:func:`heading_speed_cap`): the speed s along
    the heading nearest to it that keeps every condition [m/s]; None when ``speed_mps`` keeps them, or no
    |s| <= ``vmax`` does. A held boat across a current drifts with the current's component across its bow (Rover
    holds the speed over ground along the heading only): no speed s >= 0 along the way it was going stops that, but
    the other way along its heading may."""
    along, need = _along_heading(a, b, heading_ned, drift_ned)
    if not np.any(along * speed_mps < need - EPS):
        return None
    if np.any(need[np.abs(along) <= 1e-12] > EPS):  # broken across the heading, whatever the speed along it
        return None
    lo, hi = _speed_bounds(along, need)
    lo, hi = max(lo, -vmax), min(hi, vmax)
    return None if lo > hi else min(max(speed_mps, lo), hi)


def _candidates(cmd: np.ndarray, a: np.ndarray, b: np.ndarray, vmax: float) -> list[np.ndarray]:
    """The optimum's possible places: the command, projections onto each boundary, boundary intersections."""
    out = [cmd]
    speed = float(np.hypot(*cmd))
    if speed > vmax:
        out.append(cmd * (vmax / speed))
    for ai, bi in zip(a, b, strict=True):
        nn = float(ai @ ai)
        if nn < 1e-18:
            continue
        out.append(cmd + max(0.0, (bi - ai @ cmd) / nn) * ai)  # onto the line ai.v = bi
        # the line meets the circle |v| = vmax: foot of the perpendicular +- along the line
        foot = ai * (bi / nn)
        rest = vmax**2 - float(foot @ foot)
        if rest >= 0.0:
            along = np.array([-ai[1], ai[0]]) / math.sqrt(nn)
            out += [foot + math.sqrt(rest) * along, foot - math.sqrt(rest) * along]
    for (a1, b1), (a2, b2) in itertools.combinations(zip(a, b, strict=True), 2):
        m = np.array([a1, a2])
        if abs(np.linalg.det(m)) > 1e-12:
            out.append(np.linalg.solve(m, np.array([b1, b2])))
    out.append(np.zeros(2))
    return out


def _violation(v: np.ndarray, a: np.ndarray, b: np.ndarray, vmax: float) -> float:
    worst = max(0.0, float(np.hypot(*v)) - vmax)
    if len(a):
        worst = max(worst, float(np.max(b - a @ v)))
    return worst


def project(cmd: np.ndarray, a: np.ndarray, b: np.ndarray, vmax: float) -> tuple[np.ndarray, bool]:
    """The closest velocity to ``cmd`` with ``a v >= b`` and ``|v| <= vmax``, and whether one exists; when
    none does, the least-violating candidate (capped at vmax)."""
    cands = _candidates(np.asarray(cmd, dtype=float), a, b, vmax)
    feasible = [c for c in cands if _violation(c, a, b, vmax) <= EPS]
    if feasible:
        return min(feasible, key=lambda c: float(np.sum((c - cmd) ** 2))), True
    capped = [c if np.hypot(*c) <= vmax else c * (vmax / np.hypot(*c)) for c in cands]
    return min(capped, key=lambda c: (_violation(c, a, b, vmax), float(np.sum((c - cmd) ** 2)))), False


def separation_filter(
    own_id: str,
    position_ned: np.ndarray,
    command_ned: np.ndarray,
    neighbours: list[Neighbour],
    min_separation_m: float | np.ndarray = 0.4,
    gain_per_s: float = 1.0,
    max_speed_mps: float = 0.3,
    sidestep: float = 0.5,
    recover_within_m: float | np.ndarray | None = None,
    detour_sides: dict[str, int] | None = None,
) -> SeparationResult:
    """Filter ``command_ned`` [m/s] for own boat at ``position_ned`` [m] among ``neighbours`` (CBF condition;
    ``recover_within_m`` as :func:`barrier_rows`; ``detour_sides``: the sides chosen at the last call to go
    around parked neighbours, as returned in ``SeparationResult.detours``)."""
    cmd = np.asarray(command_ned, dtype=float).reshape(2)
    speed = float(np.hypot(*cmd))
    capped = cmd if speed <= max_speed_mps else cmd * (max_speed_mps / speed)
    if not neighbours:
        return SeparationResult(capped, not np.array_equal(capped, cmd), True, None, ())
    p = np.asarray(position_ned, dtype=float).reshape(2)
    a, b = barrier_rows(p, neighbours, min_separation_m, gain_per_s, recover_within_m)
    closest = float(np.min(np.linalg.norm(a, axis=1)) / 2.0)
    broken = a @ capped < b - EPS
    if not broken.any() and speed <= max_speed_mps:
        return SeparationResult(cmd, False, True, closest, ())
    wanted = cmd.copy()  # the projection caps the speed itself (projecting the capped command is not closest)
    yielding, detours, reach = [], {}, min(speed, max_speed_mps)
    for i, nb in enumerate(neighbours):
        if not broken[i]:
            continue
        to_nb = -a[i] / max(float(np.hypot(*a[i])), 1e-12)
        starboard = np.array([-to_nb[1], to_nb[0]])  # +90 deg from the line to it
        if float(np.hypot(*nb.velocity_ned)) < PARKED_MPS:  # it will not give way: go round it
            lean = float(cmd @ starboard)
            side = (1 if lean > 0.0 else -1) if abs(lean) > SIDE_DEADBAND * speed else None
            side = side or (detour_sides or {}).get(nb.vehicle_id, 1)
            wanted += side * reach * starboard
            detours[nb.vehicle_id] = side
            yielding.append(nb.vehicle_id)
        elif nb.vehicle_id < own_id:  # yield to the lower id: step to the right of the line to it
            wanted += sidestep * reach * starboard
            yielding.append(nb.vehicle_id)
    v, feasible = project(wanted, a, b, max_speed_mps)
    return SeparationResult(v, True, feasible, closest, tuple(yielding), detours)
