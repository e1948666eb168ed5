"""The fix-to-setpoint latency window of the guidance service (its status's ``loop_latency_ms``)."""

from __future__ import annotations

import collections

import numpy as np

LATENCY_WINDOW = 2000  # fix-to-setpoint latencies kept for the percentiles


class LatencyWindow:
    """The latest fix-to-setpoint latencies [ms] and their percentiles."""

    def __init__(self, size: int = LATENCY_WINDOW) -> None:
        self._samples: collections.deque[float] = collections.deque(maxlen=size)

    def add(self, ms: float) -> None:
        self._samples.append(ms)

    def drain(self) -> list[float]:
        """The samples taken since the last drain (oldest first), removed from the window."""
        out = list(self._samples)
        self._samples.clear()
        return out

    def percentiles(self) -> dict[str, float | None]:
        if not self._samples:
            return {"p50": None, "p99": None}
        p50, p99 = np.percentile(np.fromiter(self._samples, float), [50, 99])
        return {"p50": round(float(p50), 4), "p99": round(float(p99), 4)}
