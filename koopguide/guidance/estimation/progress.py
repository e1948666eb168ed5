"""ProgressWatchdog: is the boat still getting closer to the goal along the field? (pure, no I/O)

The distance made good along the wanted track is the odometer

    s(t) = sum over fixes of (p_k - p_{k-1}) . d_{k-1}     [m]

with ``d`` the unit direction the guidance wanted over ground at the previous fix (the straight line to the
goal in direct pursuit), or, following the field, the decrease of the distance to the goal along the field
(law/field_distance.py; ``along_m``), which a boat shuttling to and fro across a hairpin of the field does
not fake (the wanted direction turns with it, so the odometer would grow on both legs). A boat that
stalls, circles or is held off by a current makes none. Progress is measured from the best so far of both
s and the straight-line distance to the goal: stalled when neither has improved by ``stall_progress_m`` for
``stall_s``. Conventions: NED [m], vehicle seconds.
"""

from __future__ import annotations

import math

import numpy as np

Vector = tuple[float, float]  # (N, E)


class ProgressWatchdog:
    def __init__(self, stall_s: float, stall_progress_m: float) -> None:
        self.stall_s = stall_s
        self.stall_progress_m = stall_progress_m
        self.odometer = 0.0  # distance made good along the wanted directions [m]
        self._mark: tuple[float, float, float] | None = None  # (t, odometer, -distance) at the last progress
        self._last: tuple[Vector, Vector] | None = None  # (position [m], unit direction) of the last update

    def reset(self) -> None:
        self.odometer = 0.0
        self._mark = None
        self._last = None

    def update(
        self,
        t: float,
        p_ned: np.ndarray,
        wanted_ned: np.ndarray | None,
        distance_m: float,
        along_m: float | None = None,
    ) -> bool:
        """Fold in position ``p_ned`` at ``t``, the wanted ground velocity there and the distance to the goal
        (``along_m``: and along the field, which then measures the progress instead); True when stalled."""
        p = (float(p_ned[0]), float(p_ned[1]))  # plain floats: this runs for every setpoint
        if along_m is not None:
            self.odometer = -along_m
        elif self._last is not None:
            (n0, e0), (dn, de) = self._last
            self.odometer += (p[0] - n0) * dn + (p[1] - e0) * de
        norm = math.hypot(wanted_ned[0], wanted_ned[1]) if wanted_ned is not None else 0.0
        direction = (float(wanted_ned[0]) / norm, float(wanted_ned[1]) / norm) if norm > 1e-12 else (0.0, 0.0)
        self._last = (p, direction)
        mark, step = self._mark, self.stall_progress_m
        if mark is None or self.odometer >= mark[1] + step or -distance_m >= mark[2] + step:
            best = (
                (self.odometer, -distance_m)
                if mark is None
                else (max(self.odometer, mark[1]), max(-distance_m, mark[2]))
            )
            self._mark = (t, *best)
        return t - self._mark[0] >= self.stall_s
