"""Linear EDMD baseline: the same Fourier lifting with fixed random features and a least-squares K.

Array conventions: pairs ``X, Y`` ``(P, d)`` in model units; lifted ``Psi (P, nu + d)`` with the state in
the first ``d`` columns, as in KoopMotion (eq. 3), so the field reads ``f(x) = [K Psi(x)]_{1:d}``.
EDMD (Williams et al. 2015): ``K = argmin_K sum_p |Psi(y_p) - K Psi(x_p)|^2``, here with a small ridge
and in its dual form (``P`` pairs < ``nu + d`` features). It shows what learning the features adds.
"""

from __future__ import annotations

import math

import numpy as np

from koopguide.base import data
from koopguide.model.field import FlowField


def edmd_field(demos: data.Demonstrations, nu: int, subsample_every: int, seed: int, ridge: float = 1e-6) -> FlowField:
    """A plain (uncertified) FlowField with ``K`` fitted by ridge least squares on the chord pairs."""
    x, y, _ = data.pairs(demos, subsample_every, 0.0)
    d = demos.dim
    rng = np.random.default_rng(seed)
    W = rng.uniform(-1.0, 1.0, (nu, d)) * math.sqrt(6.0 / (nu + d))  # the trainer's initial features
    b = rng.uniform(-1.0, 1.0, nu) * math.sqrt(6.0 / (1 + nu))
    c = math.sqrt(2.0 / nu)

    def lift(v: np.ndarray) -> np.ndarray:
        return np.concatenate([v, c * np.cos(2.0 * math.pi * (v @ W.T + b))], axis=1)

    PX, PY = lift(x), lift(y)
    gram = PX @ PX.T  # (P, P)
    lam = ridge * np.trace(gram) / len(gram)
    K_T = PX.T @ np.linalg.solve(gram + lam * np.eye(len(gram)), PY)  # (nu + d, nu + d) = K^T
    # K = A B^T with A = K, B = I: rank nu + d
    return FlowField(
        W,
        b,
        K_T.T,
        np.eye(nu + d),
        demos.goal,
        goal_centred=False,
        substeps=subsample_every,
        meta={"bounds_lo": demos.bounds[0].tolist(), "bounds_hi": demos.bounds[1].tolist()},
    )
