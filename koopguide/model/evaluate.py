"""Evaluation: SEA, DTWD, convergence from random starts, goal fixed-point error, spectral radius.

Array conventions: trajectories ``(T, d)`` in model units, time along axis 0. Reproductions start at
each demonstration's first sample and take as many samples as the demonstration has, each an Euler
step of ``velocity / substeps`` (one learned step spans ``substeps`` raw samples).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from koopguide.base.data import Demonstrations
from koopguide.model.field import FlowField


def swept_error_area(demo: np.ndarray, rep: np.ndarray) -> float:
    """SEA (Khansari-Zadeh & Billard 2014): sum of the areas of quadrilaterals
    ``(demo_t, demo_{t+1}, rep_{t+1}, rep_t)`` by the shoelace formula, absolute value per quad.

    That vertex order walks the quadrilateral's boundary; ``(demo_t, demo_{t+1}, rep_t, rep_{t+1})``
    would make bow-ties whose signed halves cancel. 2-D only.
    """
    demo, rep = _paired(demo, rep)
    if demo.shape[1] != 2:
        raise ValueError(f"SEA is defined for 2-D trajectories, got dimension {demo.shape[1]}")
    p0, p1, p2, p3 = demo[:-1], demo[1:], rep[1:], rep[:-1]
    quad = np.stack([p0, p1, p2, p3], axis=1)  # (T-1, 4, 2)
    x, y = quad[..., 0], quad[..., 1]
    twice_area = np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1)
    return float(np.sum(np.abs(twice_area)) / 2.0)


def dtw_distance(a: np.ndarray, b: np.ndarray) -> float:
    """DTWD: ``D(i,j) = |a_i - b_j| + min(D(i-1,j), D(i,j-1), D(i-1,j-1))``, ``D(0,0) = |a_0 - b_0|``,
    the result ``D(n,m)`` summed along the path, not normalised (dtw-python's ``symmetric1``)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1] or len(a) == 0 or len(b) == 0:
        raise ValueError(f"DTW needs two non-empty (T, d) arrays of one dimension, got {a.shape} and {b.shape}")
    return float(dtw_distances(a[None], b[None])[0])


def dtw_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`dtw_distance` of ``P`` pairs at once: ``a (P, n, d)``, ``b (P, m, d)`` -> ``(P,)``.

    Computed by anti-diagonals (cells with ``i + j = k``), each one vectorised numpy operation over
    the pairs and the diagonal; costs are formed per diagonal, never as a full ``n x m`` matrix.
    """
    a = np.moveaxis(np.asarray(a, dtype=np.float64), 2, 0)  # (d, P, n): contiguous slices per coordinate
    b = np.moveaxis(np.asarray(b, dtype=np.float64), 2, 0)
    a, b = np.ascontiguousarray(a), np.ascontiguousarray(b)
    _, pairs, n = a.shape
    m = b.shape[2]
    inf = np.inf
    # D on diagonals k-2 and k-1, indexed by row i + 1 (column 0 is an always-infinite sentinel for i = -1)
    prev2 = np.full((pairs, n + 1), inf)
    prev1 = np.full((pairs, n + 1), inf)
    prev1[:, 1] = np.sqrt(np.sum((a[:, :, 0] - b[:, :, 0]) ** 2, axis=0))
    for k in range(1, n + m - 1):
        lo, hi = max(0, k - m + 1), min(n - 1, k)  # rows on this diagonal; column j = k - i
        sq = None
        for ac, bc in zip(a, b, strict=True):
            diff = ac[:, lo : hi + 1] - bc[:, k - hi : k - lo + 1][:, ::-1]
            sq = diff * diff if sq is None else sq + diff * diff
        best = np.minimum(prev1[:, lo : hi + 1], prev1[:, lo + 1 : hi + 2])  # D(i-1, j), D(i, j-1)
        np.minimum(best, prev2[:, lo : hi + 1], out=best)  # D(i-1, j-1)
        cur = np.full((pairs, n + 1), inf)
        cur[:, lo + 1 : hi + 2] = np.sqrt(sq) + best
        prev2, prev1 = prev1, cur
    return prev1[:, n].copy()


def reproduce(field: FlowField, demos: Demonstrations) -> list[np.ndarray]:
    """The field's reproduction of each demonstration: same start, same number of samples."""
    lengths = {t.shape[0] for t in demos.trajectories}
    if len(lengths) == 1:  # one batched rollout
        starts = np.stack([t[0] for t in demos.trajectories])
        return list(field.rollout(starts, lengths.pop() - 1, substeps=field.substeps))
    return [field.rollout(t[0], t.shape[0] - 1, substeps=field.substeps)[0] for t in demos.trajectories]


def convergence_box(demos_bounds: tuple[np.ndarray, np.ndarray], enlarge: float) -> tuple[np.ndarray, np.ndarray]:
    """The demonstrations' bounding box with each side moved out by ``enlarge`` of its length."""
    lo, hi = (np.asarray(v, dtype=np.float64) for v in demos_bounds)
    return lo - enlarge * (hi - lo), hi + enlarge * (hi - lo)


@dataclass(frozen=True)
class ConvergenceResult:
    converged: int  # starts that end within `tolerance` of the goal
    starts: int
    final_distance_max: float  # worst final distance to the goal (model units; a bound if exited early)
    final_distance_median: float


def convergence(
    field: FlowField,
    box: tuple[np.ndarray, np.ndarray],
    starts: int,
    steps: int,
    tolerance: float,
    seed: int,
    integrator: str = "learned",
) -> ConvergenceResult:
    """Uniform random starts in ``box``: ``steps`` learned steps (``integrator="learned"``) or
    ``steps * substeps`` Euler steps of ``velocity / substeps`` (``"euler"``), re-lifted each step."""
    from koopguide.model.certificate import run_to_goal

    lo, hi = box
    rng = np.random.default_rng(seed)
    X = lo + (hi - lo) * rng.random((starts, field.dim))
    dist, _ = run_to_goal(field, X, integrator, steps, tolerance)
    return ConvergenceResult(int(np.sum(dist <= tolerance)), starts, float(np.max(dist)), float(np.median(dist)))


def goal_fixed_point_error(field: FlowField) -> float:
    """``|f(g) - g|``: how far one learned step moves the goal itself."""
    return float(np.linalg.norm(field.step(field.goal) - field.goal))


def nearest_fixed_point_error(field: FlowField, iterations: int = 2000) -> float:
    """Distance from the goal to where iterating ``f`` from the goal settles (the attractor near it)."""
    x = field.goal.copy()
    for _ in range(iterations):
        x = field.step(x)
    return float(np.linalg.norm(x - field.goal))


def evaluate(
    field: FlowField,
    demos: Demonstrations,
    *,
    starts: int = 500,
    steps: int = 100,
    tolerance: float = 1.0,
    enlarge: float = 0.10,
    seed: int = 0,
) -> dict:
    """All metrics as plain data (the JSON of ``koopguide eval --json``)."""
    reps = reproduce(field, demos)
    sea = [swept_error_area(d, r) for d, r in zip(demos.trajectories, reps, strict=True)] if field.dim == 2 else []
    if len({t.shape for t in demos.trajectories}) == 1:  # one batched sweep (LASA: equal lengths)
        dtwd = dtw_distances(np.stack(demos.trajectories), np.stack(reps)).tolist()
    else:
        dtwd = [dtw_distance(d, r) for d, r in zip(demos.trajectories, reps, strict=True)]
    box = convergence_box(demos.bounds, enlarge)
    conv = convergence(field, box, starts, steps, tolerance, seed)
    conv_e = convergence(field, box, starts, steps, tolerance, seed, integrator="euler")
    final_err = [float(np.linalg.norm(r[-1] - demos.goal)) for r in reps]
    return {
        "sea": float(np.mean(sea)) if sea else None,
        "dtwd": float(np.mean(dtwd)),
        "sea_per_demo": sea,
        "dtwd_per_demo": dtwd,
        "converged": conv.converged,
        "starts": conv.starts,
        "convergence_steps": steps,
        "convergence_tolerance": tolerance,
        "convergence_box": [box[0].tolist(), box[1].tolist()],
        "final_distance_max": conv.final_distance_max,
        "converged_euler": conv_e.converged,
        "final_distance_max_euler": conv_e.final_distance_max,
        "reproduction_end_error_max": max(final_err),
        "rho": field.spectral_radius(),
        "goal_fixed_point_err": goal_fixed_point_error(field),
        "attractor_near_goal_err": nearest_fixed_point_error(field),
    }


def _paired(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 2 or len(a) < 2:
        raise ValueError(f"expected two (T, d) trajectories of equal shape with T >= 2, got {a.shape} and {b.shape}")
    return a, b
