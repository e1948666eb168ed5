"""ProgressWatchdog: is the boat still getting closer to the goal along the field? (pure, no I/O)

The distance made good along the wanted track is the odometer

    s(t) = sum over fixes of (p_k - p_{k-1}) . d_{k-1}     [m]

with ``d`` the unit direction the guidance wanted over ground at the previous fix (the field's streamline,
or the straight line to the goal in direct pursuit). Following the field, s grows at the boat's speed; a
boat that stalls, circles or is held off by a current makes none. Stalled: less than ``stall_progress_m``
of s over the last ``stall_s``. Conventions: positions ``(2,)`` NED [m], vehicle seconds.
"""

from __future__ import annotations

import collections

import numpy as np


class ProgressWatchdog:
    def __init__(self, stall_s: float, stall_progress_m: float) -> None:
        self.stall_s = stall_s
        self.stall_progress_m = stall_progress_m
        self.odometer = 0.0  # distance made good along the wanted directions [m]
        self._since: float | None = None  # vehicle time the watch (re)started [s]
        self._last: tuple[np.ndarray, np.ndarray] | None = None  # (position, unit direction) of the last update
        self._history: collections.deque[tuple[float, float]] = collections.deque()  # (t, odometer)

    def reset(self) -> None:
        self.odometer = 0.0
        self._since = None
        self._last = None
        self._history.clear()

    def update(self, t: float, p_ned: np.ndarray, wanted_ned: np.ndarray | None) -> bool:
        """Fold in position ``p_ned`` at ``t`` and the wanted ground velocity there; True when stalled."""
        p = np.asarray(p_ned, dtype=float)
        if self._since is None:
            self._since = t
        if self._last is not None:
            self.odometer += float((p - self._last[0]) @ self._last[1])
        norm = float(np.hypot(*wanted_ned)) if wanted_ned is not None else 0.0
        direction = np.asarray(wanted_ned, dtype=float) / norm if norm > 1e-12 else np.zeros(2)
        self._last = (p, direction)
        history = self._history
        history.append((t, self.odometer))
        while len(history) > 1 and history[1][0] <= t - self.stall_s:  # keep one sample at or before the window
            history.popleft()
        if t - self._since < self.stall_s or history[0][0] > t - self.stall_s:
            return False
        return self.odometer - history[0][1] < self.stall_progress_m
