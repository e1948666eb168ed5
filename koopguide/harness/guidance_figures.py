"""The figures of ``koopguide bench guidance`` (one row per command rate), the target's verdict and the table.

Latencies in ms (fix-to-setpoint, the daemon's own samples), rates per simulated second, CPU in % of one
core; see :mod:`koopguide.harness.guidance_bench` for how each is measured.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

TARGET_RATE_HZ = 50.0
TARGET_P99_MS = 2.0


@dataclass
class RateFigures:
    rate_hz: float
    setpoints_per_s: float  # per simulated second
    latency_p50_ms: float | None
    latency_p99_ms: float | None
    latency_max_ms: float | None
    samples: int
    cpu_pct: float  # of one core
    window_wall_s: float
    window_sim_s: float
    messages_per_s: float  # MAVLink messages from the vehicle handled per wall second
    states: list[str]  # daemon states during the window (just ["guiding"] for a clean window)
    queries_answered: int = 0  # field queries asked in the window and answered with the grid
    queries_failed: int = 0  # ... answered with an error, or not at all
    query_ms_max: float | None = None  # the slowest answered query's round trip [ms]


def verdict(figures: list[RateFigures]) -> dict[str, Any]:
    """PASS/FAIL of p99 <= 2 ms at 50 Hz ('not measured' without a 50 Hz row or its samples)."""
    row = next((f for f in figures if f.rate_hz == TARGET_RATE_HZ), None)
    p99 = row.latency_p99_ms if row is not None else None
    result = "not measured" if p99 is None else ("PASS" if p99 <= TARGET_P99_MS else "FAIL")
    return {"rate_hz": TARGET_RATE_HZ, "p99_ms_at_most": TARGET_P99_MS, "p99_ms": p99, "result": result}


def print_table(machine: dict[str, Any], figures: list[RateFigures], target: dict[str, Any]) -> None:
    print(
        f"guidance bench: {machine['cpu_count']} CPUs, Python {machine['python']} ({machine['platform']}); "
        f"model {machine['model']}; {machine['seconds']:g} s window per rate, "
        f"fixes at {machine['position_rate_hz']:g} Hz"
    )
    print(
        f"{'rate_hz':>7}  {'setpoints/s':>11}  {'p50 ms':>7}  {'p99 ms':>7}  {'max ms':>7}  {'samples':>7}  "
        f"{'CPU %':>6}  {'msgs/s':>6}  {'queries':>7}  {'q max ms':>8}  states"
    )

    def ms(value: float | None) -> str:
        return f"{value:7.3f}" if value is not None else f"{'-':>7}"

    for f in figures:
        print(
            f"{f.rate_hz:7g}  {f.setpoints_per_s:11.2f}  {ms(f.latency_p50_ms)}  {ms(f.latency_p99_ms)}  "
            f"{ms(f.latency_max_ms)}  {f.samples:7d}  {f.cpu_pct:6.2f}  {f.messages_per_s:6.1f}  "
            f"{f.queries_answered:3d}/{f.queries_answered + f.queries_failed:<3d}  {ms(f.query_ms_max):>8}  "
            f"{','.join(f.states)}"
        )
    queries = (
        f"field queries n={','.join(map(str, machine['query_sizes']))} at {machine['query_hz']:g} Hz "
        "answered during each window"
        if machine["query_hz"] > 0
        else "no zenoh, no field queries"
    )
    batch = "; simulator SCHED_BATCH (--sim-batch)" if machine["sim_batch"] else ""
    print(f"{queries}; queries column: answered/asked in the window{batch}")
    measured = f"{target['p99_ms']:.3f} ms" if target["p99_ms"] is not None else "no samples"
    print(f"target p99 <= {TARGET_P99_MS:g} ms at {TARGET_RATE_HZ:g} Hz: {target['result']} ({measured})")
