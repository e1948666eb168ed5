"""The distance to the goal along the field: how far a boat still has to go by following it (pure math).

The progress watchdog (estimation/progress.py) asks whether this distance shrinks. The straight-line
distance does not answer it (a Zshape's legs lead away from the goal), and neither does the distance made
good along the wanted direction (a boat that shuttles back and forth across a hairpin of the field makes
"progress" on both legs, because the wanted direction turns with it).

For each node ``x_0`` of an ``n x n`` grid over the model's domain the streamline is integrated as the
certificate's Euler integrator does (``x <- x + (f~(x) - x) / substeps``; model/certificate.py), with its
arc length summed, until it is within ``radius`` of the goal:

    L(x_0) = sum_k |x_{k+1} - x_k| + |x_K - g|     [model units; times the frame's scale: metres]

and in between nodes it is interpolated (multilinear, model/grid_table.py). A start that does not reach the
goal within the horizon (an uncertified model) counts its arc length so far plus its remaining straight
distance. Conventions: states ``(N, 2)`` in model units; lengths in metres once scaled.
"""

from __future__ import annotations

import numpy as np

from koopguide.model.field import FlowField
from koopguide.model.grid_table import GridTable

GRID_N = 48  # nodes per axis
HORIZON_LEARNED_STEPS = 100  # as the certificate: up to 100 x substeps raw Euler steps


def field_distance_table(field: FlowField, lo: np.ndarray, hi: np.ndarray, radius: float, n: int = GRID_N) -> GridTable:
    """``L`` [model units] on an ``n x n`` grid over the box [lo, hi], the streamline stopped within ``radius``
    [model units] of the goal."""
    axes = [np.linspace(lo[k], hi[k], n) for k in range(2)]
    X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 2)
    goal = np.asarray(field.goal, dtype=float)
    length = np.zeros(len(X))
    active = np.arange(len(X))
    h = 1.0 / field.substeps
    for _ in range(HORIZON_LEARNED_STEPS * field.substeps):
        left = np.linalg.norm(X - goal, axis=1)
        moving = left > radius
        if not moving.all():
            length[active[~moving]] += left[~moving]
            X, active = X[moving], active[moving]
        if len(X) == 0:
            break
        step = h * (field.step(X) - X)
        step[~np.isfinite(step)] = 0.0
        length[active] += np.linalg.norm(step, axis=1)
        X = X + step
    if len(X):
        length[active] += np.linalg.norm(X - goal, axis=1)
    return GridTable(np.asarray(lo, dtype=float), np.asarray(hi, dtype=float), length.reshape(n, n, 1))
