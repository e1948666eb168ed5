"""Streamlines of a field sampled on a grid: what the dashboard and the replay draw (pure numpy, no I/O).

Input is the reply of the ``koopguide/<id>/field`` queryable (docs/zenoh.md): ``n * n`` grid points in
local NED with the model's x index varying fastest. Such a grid is an affine lattice (a square in model
coordinates, rotated and scaled into NED), so a point's fractional grid index follows from one 2x2
solve and the velocity there from bilinear interpolation of the four neighbours.

Conventions (whole module): positions ``(M, 2)`` local NED [m] as ``[N, E]``; velocities ``(M, 2)``
NED [m/s]; grid indices ``(i, j)`` with ``i`` along the model's x axis.

Streamlines are spaced evenly in the manner of Jobard & Lefer (1997), "Creating evenly-spaced
streamlines of arbitrary density": each line is integrated forward and backward from a seed with a
fixed arc-length step (midpoint rule, RK2) and stops where it enters a cell of a coarse occupancy grid
that another line already passes through, leaves the grid, stalls, or reaches the goal.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

#: Largest grid the dashboard asks for and accepts (points per axis).
MAX_GRID_N = 60


class FieldGridError(ValueError):
    """A field reply that is not an ``n x n`` affine grid of finite numbers; names what is wrong."""


@dataclass(frozen=True)
class FieldGrid:
    """A sampled field. ``origin_ned`` [m] is grid point (0, 0); ``axes_ned`` [m] rows are the steps
    along i and along j; ``velocity`` is ``(n, n, 2)`` [m/s] indexed ``[j, i]``; ``goal_ned`` [m]."""

    n: int
    origin_ned: np.ndarray
    axes_ned: np.ndarray
    velocity: np.ndarray
    goal_ned: np.ndarray | None

    @classmethod
    def from_reply(cls, reply: dict[str, Any]) -> FieldGrid:
        """Build from the field queryable's JSON reply; raise :class:`FieldGridError` when malformed."""
        if not isinstance(reply, dict):
            raise FieldGridError(f"field reply must be a JSON object, got {type(reply).__name__}")
        n = reply.get("n")
        if isinstance(n, bool) or not isinstance(n, int) or not 2 <= n <= MAX_GRID_N:
            raise FieldGridError(f"field reply 'n' must be an integer 2 .. {MAX_GRID_N}, got {n!r}")
        positions = _array(reply, "position_ned", n)
        velocities = _array(reply, "velocity_ned", n)
        i, j = np.meshgrid(np.arange(n), np.arange(n))
        design = np.column_stack([np.ones(n * n), i.reshape(-1), j.reshape(-1)])
        coeffs = np.linalg.lstsq(design, positions, rcond=None)[0]  # rows: origin, step along i, along j
        origin, axes = coeffs[0], coeffs[1:]
        if abs(np.linalg.det(axes)) < 1e-12:
            raise FieldGridError(f"field reply grid is degenerate: steps {axes.tolist()} m")
        error = float(np.abs(design @ coeffs - positions).max())
        step = float(np.linalg.norm(axes, axis=1).min())
        if error > 0.01 * step + 1e-4:  # the reply rounds positions to 0.1 mm
            raise FieldGridError(f"field reply positions are not a regular grid (off by {error:.4g} m)")
        goal = reply.get("goal_ned")
        goal_ned = None
        if goal is not None:
            goal_ned = np.asarray(goal, dtype=float)
            if goal_ned.shape != (2,) or not np.all(np.isfinite(goal_ned)):
                raise FieldGridError(f"field reply 'goal_ned' must be [N, E] finite, got {goal!r}")
        return cls(n, origin, axes, velocities.reshape(n, n, 2), goal_ned)

    @property
    def corners_ned(self) -> np.ndarray:
        """``(4, 2)`` corners of the grid's domain [m], in order around it."""
        a, b = self.axes_ned * (self.n - 1)
        return np.array([self.origin_ned, self.origin_ned + a, self.origin_ned + a + b, self.origin_ned + b])

    @functools.cached_property
    def _to_index(self) -> np.ndarray:
        return np.linalg.inv(self.axes_ned)

    def index_of(self, points: np.ndarray) -> np.ndarray:
        """Fractional grid indices ``(M, 2)`` as ``(i, j)`` of NED points ``(M, 2)``."""
        return (np.atleast_2d(points) - self.origin_ned) @ self._to_index

    def velocity_at(self, points: np.ndarray) -> np.ndarray:
        """Bilinear velocity ``(M, 2)`` [m/s] at NED points; NaN rows outside the grid."""
        ij = self.index_of(points)
        out = np.full((len(ij), 2), np.nan)
        last = self.n - 1
        inside = np.all((ij >= 0.0) & (ij <= last), axis=1)
        if not inside.any():
            return out
        i, j = ij[inside, 0], ij[inside, 1]
        i0 = np.minimum(np.floor(i).astype(int), last - 1)
        j0 = np.minimum(np.floor(j).astype(int), last - 1)
        fi, fj = (i - i0)[:, None], (j - j0)[:, None]
        v = self.velocity
        out[inside] = (
            (1 - fi) * (1 - fj) * v[j0, i0]
            + fi * (1 - fj) * v[j0, i0 + 1]
            + (1 - fi) * fj * v[j0 + 1, i0]
            + fi * fj * v[j0 + 1, i0 + 1]
        )
        return out


def _array(reply: dict[str, Any], key: str, n: int) -> np.ndarray:
    if key not in reply:
        raise FieldGridError(f"field reply has no {key!r} (keys: {', '.join(sorted(map(str, reply)))})")
    try:
        values = np.asarray(reply.get(key), dtype=float)
    except (TypeError, ValueError):
        raise FieldGridError(f"field reply {key!r} must be a list of [N, E] numbers") from None
    if values.shape != (n * n, 2):
        raise FieldGridError(f"field reply {key!r} must have {n * n} rows of 2 numbers, got shape {values.shape}")
    if not np.all(np.isfinite(values)):
        raise FieldGridError(f"field reply {key!r} has non-finite values")
    return values


def streamlines(
    grid: FieldGrid, spacing_m: float | None = None, step_m: float | None = None, max_points: int = 400
) -> list[np.ndarray]:
    """Evenly spaced streamlines ``[(K, 2), ...]`` in NED [m], each ordered along the flow.

    ``spacing_m`` (Jobard & Lefer's d_sep; default 1.5 grid steps) is the distance a seed keeps from
    every line drawn so far; a line stops where it comes within half of it of another line (d_test).
    ``step_m`` is the arc length of one integration step (default: a quarter of the spacing).
    """
    cell = float(np.linalg.norm(grid.axes_ned, axis=1).min())
    spacing = 1.5 * cell if spacing_m is None else float(spacing_m)
    step = 0.25 * spacing if step_m is None else float(step_m)
    if not (math.isfinite(spacing) and spacing > 0 and math.isfinite(step) and step > 0):
        raise ValueError(f"streamlines: spacing and step must be positive, got {spacing_m!r} and {step_m!r}")
    speeds = np.linalg.norm(grid.velocity, axis=-1)
    stall = 1e-3 * float(speeds.max()) if speeds.max() > 0 else math.inf
    taken = _Occupancy(spacing)
    lines: list[np.ndarray] = []
    seeds = (
        grid.origin_ned
        + (np.stack(np.meshgrid(np.arange(grid.n), np.arange(grid.n)), -1).reshape(-1, 2) + 0.5) @ grid.axes_ned
    )
    for seed in seeds:
        if taken.near(seed, spacing, None):
            continue
        line_id = len(lines)
        back = _trace(grid, seed, -step, max_points // 2, stall, taken, line_id)
        ahead = _trace(grid, seed, step, max_points // 2, stall, taken, line_id)
        points = np.vstack([back[::-1], seed[None], ahead])
        if len(points) >= 3:
            lines.append(points)
            for p in points:
                taken.add(p, line_id)
    return lines


class _Occupancy:
    """Points of the lines drawn so far, bucketed in square cells of side ``size`` [m]."""

    def __init__(self, size: float) -> None:
        self.size = size
        self.cells: dict[tuple[int, int], list[tuple[float, float, int]]] = {}

    def _key(self, p: np.ndarray) -> tuple[int, int]:
        return math.floor(p[0] / self.size), math.floor(p[1] / self.size)

    def add(self, p: np.ndarray, line_id: int) -> None:
        self.cells.setdefault(self._key(p), []).append((float(p[0]), float(p[1]), line_id))

    def near(self, p: np.ndarray, radius: float, line_id: int | None) -> bool:
        """A point of another line than ``line_id`` within ``radius`` (<= the cell size) of ``p``."""
        ki, kj = self._key(p)
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                for n, e, owner in self.cells.get((ki + di, kj + dj), ()):
                    if owner != line_id and (n - p[0]) ** 2 + (e - p[1]) ** 2 < radius * radius:
                        return True
        return False


def _direction(grid: FieldGrid, p: np.ndarray, stall: float) -> np.ndarray | None:
    v = grid.velocity_at(p[None])[0]
    speed = float(np.hypot(v[0], v[1]))
    if not math.isfinite(speed) or speed < stall:
        return None
    return v / speed


def _trace(
    grid: FieldGrid, seed: np.ndarray, ds: float, limit: int, stall: float, taken: _Occupancy, line_id: int
) -> np.ndarray:
    """Points from ``seed`` (excluded) with signed arc step ``ds`` [m], midpoint rule, until a stop."""
    points: list[np.ndarray] = []
    p = seed
    for _ in range(limit):
        d1 = _direction(grid, p, stall)
        if d1 is None:
            break
        d2 = _direction(grid, p + 0.5 * ds * d1, stall)
        if d2 is None:
            break
        p = p + ds * d2
        if grid.goal_ned is not None and float(np.hypot(*(p - grid.goal_ned))) < abs(ds):
            points.append(grid.goal_ned.copy())
            break
        if taken.near(p, 0.5 * taken.size, line_id) or not np.all(np.isfinite(grid.velocity_at(p[None]))):
            break
        points.append(p)
    return np.array(points).reshape(-1, 2)
