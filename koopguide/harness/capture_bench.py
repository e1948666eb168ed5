"""``koopguide bench capture``: what one capture search costs (law/capture.py), the figures printed.

The search runs inside the control loop of a boat that needs way, once per manoeuvre (every ``STEP_S``) near the
goal; while it runs no setpoint goes out, and at the campaign's speed-up x10 each millisecond is 10 ms of vehicle
time. This times :meth:`CaptureSearch.best` from random poses near the goal (a seeded draw: the pose, the heading
and way, the line, a current up to 0.06 m/s, the turning radius, and half of them against an area's edge), for a
boat that goes astern (2401 sequences) and one that goes ahead only (256), and prints the median and the 95th
percentile per search.

Conventions: local NED metres, m/s, milliseconds of wall time on this machine.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from koopguide.guidance.law.capture import CAPTURE_M, CaptureSearch


def _edge(P: np.ndarray) -> np.ndarray:
    """An area whose east edge lies 0.4 m east of the goal (the campaign's tank wall by the goal) [m outside]."""
    return np.maximum(np.atleast_2d(P)[:, 1] - 0.4, 0.0)


def time_searches(n: int, astern: bool, seed: int) -> np.ndarray:
    """Wall milliseconds of ``n`` searches from seeded random poses."""
    rng = np.random.default_rng(seed)
    search = CaptureSearch(max_speed_mps=0.3)
    search.astern = astern
    times = np.empty(n)
    for i in range(n):
        r, bearing = CAPTURE_M * math.sqrt(rng.random()), rng.uniform(-math.pi, math.pi)
        p = r * np.array([math.cos(bearing), math.sin(bearing)])
        c_speed, c_toward = rng.uniform(0.0, 0.06), rng.uniform(-math.pi, math.pi)
        c = c_speed * np.array([math.cos(c_toward), math.sin(c_toward)])
        heading, water, axis = rng.uniform(-math.pi, math.pi), rng.uniform(-0.1, 0.2), rng.uniform(-math.pi, math.pi)
        radius, outside = rng.uniform(0.8, 2.0), (_edge if i % 2 else None)
        start = time.perf_counter()
        search.best(p, np.zeros(2), heading, water, axis, c, radius, outside)
        times[i] = 1000.0 * (time.perf_counter() - start)
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="koopguide bench capture", description=__doc__.split("\n")[0])
    parser.add_argument("--searches", type=int, default=300, help="searches timed per boat kind")
    parser.add_argument("--seed", type=int, default=0, help="seed of the poses")
    args = parser.parse_args(argv)
    if args.searches < 1:
        raise ValueError(f"--searches must be >= 1, got {args.searches}")
    for astern, kind in ((True, "goes astern (2401 sequences)"), (False, "goes ahead only (256 sequences)")):
        ms = time_searches(args.searches, astern, args.seed)
        p50, p95 = np.percentile(ms, [50, 95])
        print(f"capture search, a boat that {kind}: median {p50:.2f} ms, p95 {p95:.2f} ms ({args.searches} searches)")
    return 0
