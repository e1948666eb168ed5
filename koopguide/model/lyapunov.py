"""A Lyapunov limit on the learned step: convergence to the goal by construction outside the demos' tube.

Array conventions: states ``(N, d)`` in model units; the limit's table is a regular grid of shape
``(n_1, ..., n_d)`` over the box ``[lo, hi]`` (node ``i`` of axis ``k`` at ``lo_k + i (hi_k - lo_k) /
(n_k - 1)``); ratios are dimensionless (distance to the goal after one learned step / before).

With ``V(x) = |x - g|^2`` and a learned step ``f``, the limited step is the radial projection

    f~(x) = g + (f(x) - g) min(1, gamma(x) |x - g| / |f(x) - g|)

(a continuous map: the projection onto the ball of radius ``gamma(x) |x - g|`` around the goal).
Wherever ``gamma(x) <= gamma_0 < 1``:

- the learned-step map contracts, ``|f~(x) - g| <= gamma_0 |x - g|``;
- so does every Euler step of the continuous field ``v = f~(x) - x`` with ``h in (0, 1]``, because
  ``x + h v - g = (1 - h)(x - g) + h (f~(x) - g)`` gives ``|e'| <= (1 - h (1 - gamma_0)) |e|``.

``gamma(x)`` is ``outside`` (< 1) away from the demonstrations and, within a tube around them, rises
to what the learned field needs there (its own ratio on the demonstrations, plus a margin): inside
the tube the fit is untouched, outside every trajectory is pulled towards the goal (the Lyapunov
decrease of CLF-DM, Khansari-Zadeh & Billard 2014, with V fixed to the squared distance).
Where it can still fail: inside the tube wherever the demonstrations move away from the goal
(``gamma >= 1``), so a trajectory could in principle stay there; the certificate checks it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from koopguide.model.grid_table import GridTable


@dataclass(frozen=True)
class RatioLimit:
    """``gamma(x)``: multilinear interpolation of ``table`` over ``[lo, hi]``, ``outside`` beyond it."""

    lo: np.ndarray  # (d,) model units, lower corner of the table
    hi: np.ndarray  # (d,) model units, upper corner
    table: np.ndarray  # (n_1, ..., n_d) dimensionless ratio per grid node
    outside: float  # dimensionless ratio beyond the table (< 1)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_grid", GridTable(self.lo, self.hi, np.asarray(self.table)[..., None]))

    def ratio(self, X: np.ndarray) -> np.ndarray:
        """``gamma`` at each row of ``X`` ``(N, d)`` -> ``(N,)``."""
        grid: GridTable = self._grid  # type: ignore[attr-defined]
        inside = grid.inside(X)
        values = grid.at(X)[:, 0]
        return values if inside is None else np.where(inside, values, self.outside)

    def ratio_one(self, x: np.ndarray) -> float:
        """``gamma`` at a single state ``(d,)``, in plain Python (the one-point query path)."""
        value = self._grid.at_one(x)  # type: ignore[attr-defined]
        return self.outside if value is None else value[0]


def limit_step(X: np.ndarray, Y: np.ndarray, goal: np.ndarray, gamma: np.ndarray) -> np.ndarray:
    """Radial projection of the next states ``Y`` onto the balls ``|y - g| <= gamma |x - g|`` (rows)."""
    e_next = Y - goal
    e = X - goal
    allowed = gamma * np.sqrt(_row_sq(e))
    have = np.sqrt(_row_sq(e_next))
    scale = np.minimum(1.0, allowed / np.maximum(have, 1e-300))
    e_next *= scale[:, None]
    e_next += goal
    return e_next


def _row_sq(e: np.ndarray) -> np.ndarray:
    """Squared norm of each row, by columns (faster than a reduction over a short axis)."""
    out = e[:, 0] * e[:, 0]
    for k in range(1, e.shape[1]):
        out += e[:, k] * e[:, k]
    return out


def limit_step_one(x: Sequence[float], y: list[float], goal: list[float], gamma: float) -> list[float]:
    """:func:`limit_step` for one state, in plain Python floats (``x``, ``y`` and ``goal`` sequences of floats)."""
    e2 = 0.0
    n2 = 0.0
    for k, g in enumerate(goal):
        e = x[k] - g
        e2 += e * e
        n = y[k] - g
        n2 += n * n
    allowed = gamma * math.sqrt(e2)
    have = math.sqrt(n2)
    if have <= allowed:
        return y
    s = allowed / have
    return [g + (y[k] - g) * s for k, g in enumerate(goal)]


def smoothstep(t: np.ndarray) -> np.ndarray:
    """``3t^2 - 2t^3`` on ``[0, 1]``, clipped: a C1 ramp from 0 to 1."""
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def build_limit(
    step,
    samples: np.ndarray,
    goal: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    nodes: tuple[int, ...],
    outside: float,
    tube_width: float,
    margin: float,
) -> RatioLimit:
    """The ratio table for a learned step ``step((N, d)) -> (N, d)`` and demonstration ``samples``.

    At each demonstration sample ``s`` the field needs ``rho(s) = |f(s) - g| / |s - g|``; a node at
    distance ``r`` from its nearest samples gets ``outside + tau(r) max(0, rho (1 + margin) + margin -
    outside)`` (the largest over its 8 nearest samples), ``tau`` a smoothstep falling from 1 on the
    demonstrations to 0 at ``tube_width``.
    """
    from scipy.spatial import cKDTree

    samples = np.asarray(samples, dtype=np.float64)
    dist = np.linalg.norm(samples - goal, axis=1)
    keep = dist > 1e-9
    samples, dist = samples[keep], dist[keep]
    rho = np.linalg.norm(step(samples) - goal, axis=1) / dist
    excess = np.maximum(0.0, rho * (1.0 + margin) + margin - outside)
    axes = [np.linspace(lo[k], hi[k], nodes[k]) for k in range(len(nodes))]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(nodes))
    k = min(8, len(samples))
    near_d, near_i = cKDTree(samples).query(grid, k=k)
    near_d, near_i = near_d.reshape(len(grid), k), near_i.reshape(len(grid), k)
    tau = smoothstep(1.0 - near_d / tube_width)
    table = outside + np.max(tau * excess[near_i], axis=1)
    return RatioLimit(
        lo=np.asarray(lo, float), hi=np.asarray(hi, float), table=table.reshape(nodes), outside=float(outside)
    )


def carve(limit: RatioLimit, points: np.ndarray, radius: float) -> RatioLimit:
    """The same limit with ``gamma = outside`` at every node within ``radius`` of ``points`` (repair)."""
    from scipy.spatial import cKDTree

    axes = [np.linspace(limit.lo[k], limit.hi[k], n) for k, n in enumerate(limit.table.shape)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))
    d, _ = cKDTree(np.asarray(points, float)).query(grid, k=1)
    table = limit.table.ravel().copy()
    table[d <= radius] = np.minimum(table[d <= radius], limit.outside)
    return RatioLimit(lo=limit.lo, hi=limit.hi, table=table.reshape(limit.table.shape), outside=limit.outside)


def contracting(limit: RatioLimit) -> RatioLimit:
    """``gamma = outside`` everywhere: the global contraction every repair ends in at worst."""
    return RatioLimit(lo=limit.lo, hi=limit.hi, table=np.full(limit.table.shape, limit.outside), outside=limit.outside)
