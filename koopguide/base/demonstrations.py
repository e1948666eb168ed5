"""A set of demonstrated trajectories (:class:`Demonstrations`) and the error for unusable ones.

Array conventions: a trajectory is a float64 array of shape ``(T, d)``, time along axis 0, positions in
the demonstration's own units (LASA units for LASA: |x| <= 50, goal at the origin). Loading lives in
:mod:`koopguide.base.data`, generated sets in :mod:`koopguide.base.synthetic`.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np


class DemoDataError(ValueError):
    """Demonstration data that cannot be used; the message names the source and the problem."""


@dataclass(frozen=True)
class Demonstrations:
    """A set of demonstrated trajectories, each ``(T_i, d)``, all of one dimension ``d``."""

    source: str
    trajectories: tuple[np.ndarray, ...]

    @property
    def dim(self) -> int:
        return self.trajectories[0].shape[1]

    @property
    def goal(self) -> np.ndarray:
        """``(d,)``: the mean of the demonstrations' final points (exactly the origin for LASA)."""
        return np.mean([t[-1] for t in self.trajectories], axis=0)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lo, hi)``, each ``(d,)``: the box spanned by every sample of every trajectory."""
        stacked = np.concatenate(self.trajectories)
        return stacked.min(axis=0), stacked.max(axis=0)

    def digest(self) -> str:
        """SHA-256 over the exact samples, to tie a model file to the data it was trained on."""
        h = hashlib.sha256()
        for t in self.trajectories:
            h.update(np.ascontiguousarray(t, dtype="<f8").tobytes())
            h.update(str(t.shape).encode())
        return h.hexdigest()

    def summary(self) -> dict:
        lo, hi = self.bounds
        return {
            "source": self.source,
            "n_demos": len(self.trajectories),
            "lengths": [int(t.shape[0]) for t in self.trajectories],
            "dim": self.dim,
            "goal": self.goal.tolist(),
            "goal_spread": float(max(np.linalg.norm(t[-1] - self.goal) for t in self.trajectories)),
            "bounds_lo": lo.tolist(),
            "bounds_hi": hi.tolist(),
            "sha256": self.digest(),
        }
