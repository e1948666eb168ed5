"""Synthetic demonstration sets: a 3-D helix descending into its goal (for the dimension-generic field).

Array conventions as in :mod:`koopguide.base.data`: each trajectory ``(T, 3)``, time along axis 0, in
model units of the same scale as LASA (|x| <= ~40), ending exactly at the goal, the origin.
"""

from __future__ import annotations

import numpy as np

from koopguide.base.demonstrations import Demonstrations

SYNTHETIC = ("helix",)


def helix(
    demos: int = 5, samples: int = 1000, turns: float = 1.5, radius: float = 25.0, height: float = 40.0
) -> Demonstrations:
    """``demos`` descending helices: radius and height shrink to 0 as the goal (origin) is reached.

    ``x = r(s) cos(theta_0 + 2 pi turns s)``, ``y = r(s) sin(...)``, ``z = height (1 - s)`` with
    ``r(s) = radius (1 - s)``, ``s`` from 0 to 1 with a smooth (minimum-jerk) timing so each demo starts
    and ends at rest like LASA's; demos differ by a fixed spread of start angle, radius and height.
    """
    out = []
    u = np.linspace(0.0, 1.0, samples)
    s = 10 * u**3 - 15 * u**4 + 6 * u**5  # minimum-jerk timing
    for i in range(demos):
        f = (i - (demos - 1) / 2) / max(demos - 1, 1)  # -0.5 .. 0.5
        theta0 = 0.25 * f
        r = radius * (1.0 + 0.15 * f) * (1.0 - s)
        phase = theta0 + 2.0 * np.pi * turns * s
        z = height * (1.0 - 0.1 * f) * (1.0 - s)
        out.append(np.column_stack([r * np.cos(phase), r * np.sin(phase), z]))
    return Demonstrations(source="synthetic:helix", trajectories=tuple(out))


def load_synthetic(name: str) -> Demonstrations:
    if name == "helix":
        return helix()
    raise ValueError(f"unknown synthetic demonstration set {name!r}; known: {', '.join(SYNTHETIC)}")
