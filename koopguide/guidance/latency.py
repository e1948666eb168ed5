"""The fix-to-setpoint latency of the guidance service: its window (the status's ``loop_latency_ms``), and
what the service does at start-up to keep it short (docs/guidance.md "Latency and CPU")."""

from __future__ import annotations

import collections
import gc

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


def settle_heap() -> None:
    """Call once the service has started (model, libraries and configuration loaded): collect, then move
    every object alive now out of the garbage collector's sight (``gc.freeze``). A full collection walks
    every tracked object - about 80,000 with the model and the libraries loaded, 75-85 ms on the 2-core
    reference machine - and it runs wherever the allocation that triggers it happens, possibly between a
    fix and its setpoint. These objects live as long as the service, so no collection needs to see them;
    the young objects of each fix are still collected as before."""
    gc.collect()
    gc.freeze()
