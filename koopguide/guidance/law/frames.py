"""Model coordinates <-> local NED metres (docs/frames.md, a public contract).

Conventions: model points ``p = (x, y)`` in model units (LASA: x right, y up); local NED points
``(N, E)`` in metres; velocities likewise per unit time. Three numbers fix the map: ``goal_ned`` (where
the model's goal lands), ``scale`` (metres per model unit) and ``heading_deg`` (compass heading of model
+x; model +y points 90 degrees counter-clockwise from +x, i.e. at heading - 90 degrees).

    ned = goal_ned + scale * R (p - goal_model),  R = [[cos h, sin h], [sin h, -cos h]]

R's columns are the NED directions of model +x (cos h, sin h) and +y (sin h, -cos h). R is a reflection
(det -1: NED is left-handed seen from above, model x/y right-handed), symmetric and its own inverse.
With h = 90 degrees, model +x is East and +y is North.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from koopguide.guidance.settings import FrameSettings


@dataclass(frozen=True)
class ModelFrame:
    """The placement of a 2-D model in local NED."""

    goal_model: tuple[float, float]  # the field's goal [model units]
    goal_ned: tuple[float, float]  # [m]
    scale: float  # metres per model unit
    heading_deg: float  # compass heading of model +x [deg]

    @classmethod
    def place(cls, goal_model: np.ndarray, settings: FrameSettings) -> ModelFrame:
        """The frame of ``settings`` (goal_ned, scale, heading_deg) for a model whose goal is ``goal_model``."""
        return cls(tuple(float(v) for v in goal_model), settings.goal_ned, settings.scale, settings.heading_deg)

    @functools.cached_property
    def R(self) -> np.ndarray:
        """The rotation-reflection (computed once per frame: it is used for every setpoint)."""
        h = math.radians(self.heading_deg)
        R = np.array([[math.cos(h), math.sin(h)], [math.sin(h), -math.cos(h)]])
        R.flags.writeable = False
        return R

    @functools.cached_property
    def _arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(goal_model, goal_ned, R.T) as read-only arrays, built once (every setpoint uses them)."""
        out = (np.array(self.goal_model, dtype=float), np.array(self.goal_ned, dtype=float), self.R.T)
        for a in out:
            a.flags.writeable = False
        return out

    def to_ned(self, p: np.ndarray) -> np.ndarray:
        """Model points ``(..., 2)`` -> NED ``(..., 2)`` [m]."""
        goal_model, goal_ned, R_T = self._arrays
        return goal_ned + self.scale * (np.asarray(p) - goal_model) @ R_T

    def to_model(self, ned: np.ndarray) -> np.ndarray:
        """NED ``(..., 2)`` [m] -> model points ``(..., 2)`` (R is its own inverse)."""
        goal_model, goal_ned, R_T = self._arrays
        return goal_model + (np.asarray(ned) - goal_ned) @ R_T / self.scale

    def direction_to_ned(self, v: np.ndarray) -> np.ndarray:
        """Model-frame vectors ``(..., 2)`` -> NED vectors, rotated/reflected only (no scale)."""
        return np.asarray(v) @ self._arrays[2]
