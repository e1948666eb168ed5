"""FlowField: query a trained KoopMotion field with numpy only.

Array conventions: a state is ``(dim,)`` and a batch ``(N, dim)`` in model units (LASA units for LASA
models); every query accepts either and answers in the same form. One learned step spans
``substeps`` raw demonstration samples.

The field is the re-lifted map of KoopMotion: ``f(x) = [K Psi(x)]_{1:d}`` with ``K = A B^T`` and
``Psi(x) = [x, c cos(2 pi (W x + b))]`` (KoopMotion eqs. 3-4); goal-centred models lift with
``Phi(x) = Psi(x) - Psi(g)`` and read ``f(x) = g + [K Phi(x)]_{1:d}``, so ``f(g) = g`` exactly.

A certified model also carries a Lyapunov limit (:mod:`koopguide.model.lyapunov`): ``step`` then returns
the radially limited step ``f~(x)``, which contracts towards the goal away from the demonstrations.
The Fourier block (``cos`` of ``nu`` phases and its projection) runs in float32, the linear part
and the output in float64: ``koopguide bench speed`` reports the difference from float64 throughout.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from koopguide.base import modelfile
from koopguide.model.grid_table import GridTable
from koopguide.model.lyapunov import RatioLimit, limit_step, limit_step_one


class FlowField:
    """A trained flow field. Build it with :func:`load_field` or from arrays."""

    def __init__(
        self,
        W: np.ndarray,
        b: np.ndarray,
        A: np.ndarray,
        B: np.ndarray,
        goal: np.ndarray,
        goal_centred: bool,
        substeps: int,
        meta: dict[str, Any] | None = None,
        limit: RatioLimit | None = None,
        precision: str = "float32",
        tabulate: bool = True,
    ) -> None:
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
        self.limit = limit
        if precision not in ("float32", "float64"):
            raise ValueError(f"precision must be 'float32' or 'float64', got {precision!r}")
        self.precision = precision
        fdt = np.float32 if precision == "float32" else np.float64
        self._fW = self._two_pi_W_T.astype(fdt)
        self._fb = self._two_pi_b.astype(fdt)
        self._fC = self._cBA_f.astype(fdt)
        self._goal_list = self.goal.tolist()
        self._offset = np.zeros(d)
        if self.goal_centred:  # f(x) = g + [K (Psi(x) - Psi(g))]_{1:d}, in the same arithmetic as queries
            self._offset = self.goal - self.learned_step(self.goal[None])[0]
        self._table = _query_table(self, limit) if limit is not None and tabulate else None

    def with_limit(self, limit: RatioLimit | None) -> FlowField:
        """The same learned field under another Lyapunov limit; reuses the tabulated ``f`` when the grid matches."""
        out = FlowField(
            self.W,
            self.b,
            self.A,
            self.B,
            self.goal,
            self.goal_centred,
            self.substeps,
            meta=self.meta,
            limit=limit,
            precision=self.precision,
            tabulate=False,
        )
        old = self._table
        if (
            limit is not None
            and old is not None
            and np.array_equal(old.lo, limit.lo)
            and np.array_equal(old.hi, limit.hi)
        ):
            out._table = _query_table(out, limit, f_values=old.values[..., : self.dim])
        elif limit is not None:
            out._table = _query_table(out, limit)
        return out

    # ------------------------------------------------------------------------------ queries
    def step(self, X: np.ndarray) -> np.ndarray:
        """Next state after one learned step, re-lifted from ``X`` at each call (Lyapunov-limited if certified)."""
        X = np.asarray(X, dtype=np.float64)
        if X.ndim == 1 and X.shape == (self.dim,):
            return self._step_one(X)
        X2 = self._as_batch(X)
        if self.limit is None:
            out = self.learned_step(X2)
        elif self._table is None:
            out = limit_step(X2, self.learned_step(X2), self.goal, self.limit.ratio(X2))
        else:
            inside = self._table.inside(X2)
            fg = self._table.at(X2)
            if inside is not None and not inside.all():
                fg[~inside, : self.dim] = self.learned_step(X2[~inside])
                fg[~inside, self.dim] = self.limit.outside
            out = limit_step(X2, fg[:, : self.dim], self.goal, fg[:, self.dim])
        return out[0] if X.ndim == 1 else out

    def _step_one(self, x: np.ndarray) -> np.ndarray:
        if self._table is not None:
            fg = self._table.at_one(x)
            if fg is not None:
                return np.array(limit_step_one(x.tolist(), fg[: self.dim], self._goal_list, fg[self.dim]))
        y = self.learned_step(x[None])[0]  # the batch arithmetic, so one point and a batch agree bit for bit
        if self.limit is None:
            return y
        gamma = self.limit.ratio_one(x) if self._table is None else self.limit.outside
        return np.array(limit_step_one(x.tolist(), y.tolist(), self._goal_list, gamma))

    def learned_step(self, X: np.ndarray) -> np.ndarray:
        """The trained map ``f(x)`` itself, without the Lyapunov limit: ``(N, d) -> (N, d)``.

        Row-wise arithmetic only (elementwise phases, float64 projection), so a row's answer does not
        depend on the batch it came in.
        """
        X = self._as_batch(np.asarray(X, dtype=np.float64))
        Xf = X.astype(self._fW.dtype)
        phase = Xf[:, 0:1] * self._fW[0]
        for k in range(1, self.dim):
            phase += Xf[:, k : k + 1] * self._fW[k]
        phase += self._fb
        return X @ self._BA_x + np.cos(phase, out=phase) @ self._cBA_f + self._offset

    def velocity(self, X: np.ndarray) -> np.ndarray:
        """Displacement over one learned step, ``step(X) - X`` (divide by ``substeps`` per raw sample)."""
        X = np.asarray(X, dtype=np.float64)
        if X.shape == (self.dim,) and self._table is not None:  # the one-point hot path, in plain floats
            fg = self._table.at_one(X)
            if fg is not None:
                x = X.tolist()
                y = limit_step_one(x, fg, self._goal_list, fg[self.dim])
                return np.array([y[k] - x[k] for k in range(self.dim)])
        return self.step(X) - X

    def velocity_xy(self, x: float, y: float) -> tuple[float, float]:
        """:meth:`velocity` of a 2-D field at the point ``(x, y)``, in plain floats (the same numbers): the
        guidance law follows the field's streamline with it for every setpoint."""
        table = self._table
        fg = table.at_xy(x, y) if table is not None and self.dim == 2 else None
        if fg is None:
            v = self.velocity(np.array((x, y)))
            return float(v[0]), float(v[1])
        step = limit_step_one((x, y), fg, self._goal_list, fg[2])
        return step[0] - x, step[1] - y

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

    def eigenfunctions(self, X: np.ndarray, count: int = 4) -> tuple[np.ndarray, np.ndarray]:
        """Leading Koopman eigenfunctions ``phi_i(x) = y_i^H B^T Psi(x)`` at rows of ``X``: ``(lam (k,), phi (N, k))``.

        ``y_i`` is a left eigenvector of the core ``B^T A`` (``y^H B^T A = lam y^H``), so ``w_i = B y_i``
        is a left eigenvector of ``K = A B^T`` and ``phi_i(K z) = lam_i phi_i(z)`` along the lifted linear
        system. Of each conjugate pair only the one with ``Im lam >= 0`` is returned; largest ``|lam|`` first.
        """
        lam, Y = np.linalg.eig((self.B.T @ self.A).T)  # right eigenvectors of M^T = left of M
        keep = np.flatnonzero(lam.imag >= -1e-12)
        keep = keep[np.argsort(-np.abs(lam[keep]), kind="stable")][:count]
        phi = (self.lift(X) @ self.B) @ Y[:, keep]  # y^T (B^T Psi) with y the eigenvector of M^T
        return lam[keep], phi

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
        return (
            f"FlowField(dim={self.dim}, nu={self.nu}, rank={self.rank}, goal={self.goal.tolist()}, "
            f"substeps={self.substeps}, goal_centred={self.goal_centred})"
        )


def load_field(path: str | Path) -> FlowField:
    """Load a model file written by ``koopguide train`` (numpy only; no torch needed)."""
    weights, meta = modelfile.read(path)
    limit = None
    if "limit_table" in weights:
        spec = meta["limit"]
        limit = RatioLimit(
            lo=np.asarray(spec["lo"], float),
            hi=np.asarray(spec["hi"], float),
            table=weights["limit_table"],
            outside=float(spec["outside"]),
        )
    return FlowField(
        weights["W"],
        weights["b"],
        weights["A"],
        weights["B"],
        goal=np.asarray(meta["goal"]),
        goal_centred=bool(meta["goal_centred"]),
        substeps=int(meta["substeps"]),
        meta=meta,
        limit=limit,
    )


#: Target node count of the query table by dimension (per axis: its d-th root, nested in the limit's grid).
QUERY_TABLE_NODES = {2: 1 << 16, 3: 1 << 17}


def _query_table(field: FlowField, limit: RatioLimit, f_values: np.ndarray | None = None) -> GridTable | None:
    """``[f(x), gamma(x)]`` at the nodes of a grid over the limit's box that refines the limit's own grid.

    Each limit cell is split into ``m`` per axis, so multilinear interpolation of the nodes reproduces
    the limit's ``gamma`` exactly and ``f`` to within the error ``koopguide bench speed`` reports.
    Dimensions above 3 are not tabulated (exact evaluation).
    """
    if field.dim not in QUERY_TABLE_NODES:
        return None
    coarse = np.asarray(limit.table.shape)
    m = max(1, int((QUERY_TABLE_NODES[field.dim] ** (1.0 / field.dim) - 1) // int(np.max(coarse - 1))))
    fine = tuple(int(n) for n in (coarse - 1) * m + 1)
    axes = [np.linspace(limit.lo[k], limit.hi[k], n) for k, n in enumerate(fine)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, field.dim)
    values = np.empty((len(nodes), field.dim + 1))
    reuse = f_values is not None and f_values.shape[: field.dim] == fine
    values[:, : field.dim] = f_values.reshape(-1, field.dim) if reuse else learned_step_on_grid(field, axes)
    for i in range(0, len(nodes), 8192):
        values[i : i + 8192, field.dim] = limit.ratio(nodes[i : i + 8192])
    return GridTable(limit.lo, limit.hi, values.reshape(*fine, field.dim + 1))


def learned_step_on_grid(field: FlowField, axes: list[np.ndarray]) -> np.ndarray:
    """``f(x)`` at every node of the grid ``axes[0] x ... x axes[d-1]`` in float64, ``(prod(n_k), d)`` in C order.

    The phases separate over the axes, ``2 pi (W x + b) = 2 pi b + sum_k 2 pi W_k x_k``, so with
    ``E_k = exp(i 2 pi W_k x_k)`` the Fourier part ``sum_j C_j cos(phase_j)`` is ``Re(F @ E_last^T)`` where
    ``F`` holds ``C_j exp(i 2 pi b_j) prod_{k < d-1} E_k`` for every combination of the other axes: two
    real matrix products instead of ``nu`` cosines per node.
    """
    d = field.dim
    front = np.exp(1j * field._two_pi_b)[None, :]  # (1, nu), then (n_0 ... n_{d-2}, nu)
    for k in range(d - 1):
        front = (front[:, None, :] * np.exp(1j * np.outer(axes[k], field._two_pi_W_T[k]))[None]).reshape(-1, field.nu)
    last = np.exp(1j * np.outer(axes[-1], field._two_pi_W_T[d - 1]))  # (n_last, nu)
    weighted = (front[:, None, :] * field._cBA_f.T[None]).reshape(-1, field.nu)  # (rows * d, nu)
    fourier = weighted.real @ last.real.T - weighted.imag @ last.imag.T  # (rows * d, n_last)
    fourier = fourier.reshape(len(front), d, len(last)).transpose(0, 2, 1).reshape(-1, d)
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, d)
    return nodes @ field._BA_x + fourier + field._offset


def _positive_int(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)
