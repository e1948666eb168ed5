"""FlowField: query a trained KoopMotion field with numpy only.

Array conventions: a state is ``(dim,)`` and a batch ``(N, dim)`` in model units (LASA units for LASA
models); every query accepts either and answers in the same form. One learned step spans
``substeps`` raw demonstration samples.

The field is the re-lifted map of KoopMotion: ``f(x) = [K Psi(x)]_{1:d}`` with ``K = A B^T`` and
``Psi(x) = [x, c cos(2 pi (W x + b))]`` (KoopMotion eqs. 3-4); goal-centred models lift with
``Phi(x) = Psi(x) - Psi(g)`` and read ``f(x) = g + [K Phi(x)]_{1:d}``, so ``f(g) = g`` exactly.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from koopguide.base import modelfile


class FlowField:
    """A trained flow field. Build it with :func:`load_field` or from arrays."""

    def __init__(self, W: np.ndarray, b: np.ndarray, A: np.ndarray, B: np.ndarray, goal: np.ndarray,
                 goal_centred: bool, substeps: int, meta: dict[str, Any] | None = None) -> None:
        self.W = np.asarray(W, dtype=np.float64)  # (nu, d)
        self.b = np.asarray(b, dtype=np.float64)  # (nu,)
        self.A = np.asarray(A, dtype=np.float64)  # (nu + d, r)
        self.B = np.asarray(B, dtype=np.float64)  # (nu + d, r)
        self.nu, self.dim = self.W.shape
        self.rank = self.A.shape[1]
        self.goal = np.asarray(goal, dtype=np.float64).reshape(self.dim)
        self.goal_centred = bool(goal_centred)
        self.substeps = int(substeps)
        self.meta = dict(meta or {})
        self.c = math.sqrt(2.0 / self.nu)
        # Hot-path factors: f(x) = x B_x A_x^T + cos(2 pi (x W^T + b)) (c B_f) A_x^T + offset
        d = self.dim
        self._two_pi_W_T = np.ascontiguousarray(2.0 * math.pi * self.W.T)  # (d, nu)
        self._two_pi_b = 2.0 * math.pi * self.b  # (nu,)
        self._A_x_T = np.ascontiguousarray(self.A[:d].T)  # (r, d)
        self._B_x = np.ascontiguousarray(self.B[:d])  # (d, r)
        self._cB_f = np.ascontiguousarray(self.c * self.B[d:])  # (nu, r)
        self._BA_x = self._B_x @ self._A_x_T  # (d, d)
        self._cBA_f = self._cB_f @ self._A_x_T  # (nu, d): one matmul per query
        if self.goal_centred:
            z_goal = self.goal @ self._BA_x + np.cos(self.goal @ self._two_pi_W_T + self._two_pi_b) @ self._cBA_f
            self._offset = self.goal - z_goal  # f(x) = g + [K (Psi(x) - Psi(g))]_{1:d}
        else:
            self._offset = np.zeros(d)

    # ------------------------------------------------------------------------------ queries
    def step(self, X: np.ndarray) -> np.ndarray:
        """Next state after one learned step, re-lifted from ``X`` at each call."""
        X = np.asarray(X, dtype=np.float64)
        single = X.ndim == 1
        X2 = self._as_batch(X)
        out = X2 @ self._BA_x + np.cos(X2 @ self._two_pi_W_T + self._two_pi_b) @ self._cBA_f + self._offset
        return out[0] if single else out

    def velocity(self, X: np.ndarray) -> np.ndarray:
        """Displacement over one learned step, ``step(X) - X`` (divide by ``substeps`` per raw sample)."""
        X = np.asarray(X, dtype=np.float64)
        return self.step(X) - X

    def lift(self, X: np.ndarray) -> np.ndarray:
        """``Psi(X)`` (or ``Phi(X)`` if goal-centred), ``(N, nu + d)``."""
        X2 = self._as_batch(np.asarray(X, dtype=np.float64))
        z = np.concatenate([X2, self.c * np.cos(X2 @ self._two_pi_W_T + self._two_pi_b)], axis=1)
        if self.goal_centred:
            g = self.goal[None]
            z = z - np.concatenate([g, self.c * np.cos(g @ self._two_pi_W_T + self._two_pi_b)], axis=1)
        return z

    def rollout(self, x0: np.ndarray, n: int, substeps: int | None = None, method: str = "euler") -> np.ndarray:
        """Trajectories ``(N, n + 1, dim)`` from ``x0`` (``(dim,)`` or ``(N, dim)``).

        ``method="euler"``: each of the ``n`` steps moves ``velocity(x) / substeps`` (``substeps=None``
        means whole learned steps, ``x <- step(x)``). ``method="koopman"``: the lifted state is
        propagated by ``K`` alone, ``z_{k+1} = K z_k``, and only the first lift is from a measurement.
        """
        if not isinstance(n, int | np.integer) or n < 0:
            raise ValueError(f"rollout length n must be a non-negative integer, got {n!r}")
        X = self._as_batch(np.asarray(x0, dtype=np.float64)).copy()
        out = np.empty((X.shape[0], n + 1, self.dim))
        out[:, 0] = X
        if method == "euler":
            h = 1.0 if substeps is None else 1.0 / _positive_int(substeps, "substeps")
            for k in range(n):
                X = X + h * (self.step(X) - X)
                out[:, k + 1] = X
        elif method == "koopman":
            if substeps not in (None, 1):
                raise ValueError(
                    f"method='koopman' propagates whole learned steps; substeps must be None, got {substeps}"
                )
            z_r = self.lift(X) @ self.B  # (N, r): K^k z = A (B^T A)^(k-1) B^T z
            core = self.B.T @ self.A  # (r, r)
            base = self.goal if self.goal_centred else 0.0
            for k in range(n):
                out[:, k + 1] = z_r @ self._A_x_T + base
                z_r = z_r @ core.T
        else:
            raise ValueError(f"unknown rollout method {method!r}; use 'euler' or 'koopman'")
        return out

    def eigenvalues(self) -> np.ndarray:
        """All ``nu + d`` eigenvalues of ``K = A B^T``, largest modulus first.

        The non-zero ones are those of the ``r x r`` core ``B^T A``; the remaining ``nu + d - r`` are 0.
        """
        core = np.linalg.eigvals(self.B.T @ self.A).astype(np.complex128)
        lam = np.concatenate([core, np.zeros(self.nu + self.dim - self.rank, dtype=np.complex128)])
        return lam[np.argsort(-np.abs(lam), kind="stable")]

    def spectral_radius(self) -> float:
        return float(np.max(np.abs(np.linalg.eigvals(self.B.T @ self.A))))

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lo, hi)`` of the training demonstrations, from the model file's metadata."""
        if "bounds_lo" not in self.meta:
            raise ValueError("this field carries no data bounds")
        return np.asarray(self.meta["bounds_lo"], dtype=float), np.asarray(self.meta["bounds_hi"], dtype=float)

    def _as_batch(self, X: np.ndarray) -> np.ndarray:
        batch = X[None] if X.ndim == 1 else X
        if batch.ndim != 2 or batch.shape[1] != self.dim:
            raise ValueError(f"expected a state of shape ({self.dim},) or (N, {self.dim}), got {X.shape}")
        return batch

    def __repr__(self) -> str:
        return (f"FlowField(dim={self.dim}, nu={self.nu}, rank={self.rank}, goal={self.goal.tolist()}, "
                f"substeps={self.substeps}, goal_centred={self.goal_centred})")


def load_field(path: str | Path) -> FlowField:
    """Load a model file written by ``koopguide train`` (numpy only; no torch needed)."""
    weights, meta = modelfile.read(path)
    return FlowField(weights["W"], weights["b"], weights["A"], weights["B"], goal=np.asarray(meta["goal"]),
                     goal_centred=bool(meta["goal_centred"]), substeps=int(meta["substeps"]), meta=meta)


def _positive_int(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)
