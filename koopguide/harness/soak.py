"""``koopguide bench soak``: hours of simulated guidance at 50 Hz, watching for growth in memory and latency.

The bundled simulator runs in a subprocess at ``--speedup`` (its CPU is not counted), sending position
fixes at 50 Hz to the guidance service, which runs in this process as ``koopguide run`` does and
commands at 50 Hz: it guides the boat home, then keeps station for the rest of the soak. Every
``--sample-s`` simulated seconds it records this process's resident memory (VmRSS), the fix-to-setpoint
latency percentiles of the setpoints sent since the last sample, the setpoints per simulated second,
and the service's state. At the end it fits a line to RSS over the second half of the samples and
reports the growth it would make over the whole soak, next to the figures.

Figures are printed, never asserted: exit 0 when the soak ran to the end, 1 when it could not
(the simulator or the service stopped). Conventions: simulated (vehicle) seconds, MB, ms.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from koopguide.harness.guidance_bench import SIM_START_TIMEOUT_S, BenchError, scenario, trained_model

RATE_HZ = 50.0


@dataclass(frozen=True)
class Sample:
    t_s: float  # simulated time [s]
    wall_s: float  # wall time since the start [s]
    rss_mb: float  # this process's resident memory [MB]
    p50_ms: float | None  # latency of the setpoints since the previous sample [ms]
    p99_ms: float | None
    setpoints_per_s: float  # per simulated second since the previous sample
    state: str


def rss_mb() -> float:
    with open("/proc/self/status", encoding="ascii") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


async def soak(model: Path, hours: float, speedup: float, sample_s: float, progress: bool) -> list[Sample]:
    from koopguide.guidance.daemon import GuidanceDaemon
    from sitl.process import SimulatorProcess

    setup = scenario(model, RATE_HZ, seconds=60.0)
    sim_overrides = {**setup.sim_overrides, "speedup": speedup}
    daemon = await GuidanceDaemon.create(setup.cfg, model, zenoh_config=None)
    runner = asyncio.create_task(daemon.run())
    simulator = SimulatorProcess(sim_overrides, start_timeout_s=SIM_START_TIMEOUT_S)
    samples: list[Sample] = []
    try:
        try:
            await asyncio.to_thread(simulator.__enter__)
        except (RuntimeError, TimeoutError) as exc:
            raise BenchError(f"the simulator did not start: {exc}") from exc
        end_s, started = hours * 3600.0, time.monotonic()
        next_sample, sent_before, t_before = sample_s, daemon.setpoints_sent, 0.0
        while True:
            await asyncio.sleep(0.2)
            if runner.done() or simulator.poll() is not None:
                raise BenchError(
                    f"stopped at simulated {daemon.clock.now():.0f} s: service done "
                    f"{runner.done()}, simulator exit {simulator.poll()}"
                )
            t = daemon.clock.now()
            if t < next_sample:
                continue
            latencies = daemon.drain_latencies()
            p50, p99 = np.percentile(latencies, [50, 99]).tolist() if latencies else (None, None)
            sent = daemon.setpoints_sent
            samples.append(
                Sample(
                    t,
                    time.monotonic() - started,
                    rss_mb(),
                    p50,
                    p99,
                    (sent - sent_before) / max(t - t_before, 1e-9),
                    daemon.state.value,
                )
            )
            sent_before, t_before, next_sample = sent, t, next_sample + sample_s
            if progress:
                s = samples[-1]
                print(
                    f"  t {s.t_s:7.0f} s  wall {s.wall_s:6.0f} s  RSS {s.rss_mb:6.1f} MB  p50 {s.p50_ms or 0:5.2f} "
                    f"p99 {s.p99_ms or 0:5.2f} ms  {s.setpoints_per_s:5.1f} setpoints/s  {s.state}",
                    file=sys.stderr,
                    flush=True,
                )
            if t >= end_s:
                return samples
    finally:
        daemon.stop()
        await asyncio.wait_for(runner, 10.0)
        await asyncio.to_thread(simulator.close)


def growth(samples: list[Sample], hours: float) -> dict[str, float | None]:
    """RSS slope over the second half, as MB over the whole soak; latency p99 first vs last quarter."""
    half = samples[len(samples) // 2 :]
    out: dict[str, float | None] = {
        "rss_growth_mb_over_soak": None,
        "p99_first_quarter_ms": None,
        "p99_last_quarter_ms": None,
    }
    if len(half) >= 2:
        slope = np.polyfit([s.t_s for s in half], [s.rss_mb for s in half], 1)[0]  # MB per simulated s
        out["rss_growth_mb_over_soak"] = float(slope * hours * 3600.0)
    quarter = max(1, len(samples) // 4)
    for key, part in (("p99_first_quarter_ms", samples[:quarter]), ("p99_last_quarter_ms", samples[-quarter:])):
        values = [s.p99_ms for s in part if s.p99_ms is not None]
        out[key] = float(np.median(values)) if values else None
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="koopguide bench soak", description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, help="model file (default out/zshape.pt, else Zshape trained now)")
    parser.add_argument("--hours", type=float, default=2.0, help="simulated hours (default 2)")
    parser.add_argument("--speedup", type=float, default=10.0, help="simulated seconds per wall second (default 10)")
    parser.add_argument("--sample-s", type=float, default=120.0, help="simulated seconds between samples")
    parser.add_argument("--json", action="store_true", help="print the samples and figures as JSON")
    args = parser.parse_args(argv)
    if not (args.hours > 0 and args.speedup > 0 and args.sample_s > 0):
        parser.error("--hours, --speedup and --sample-s must be > 0")
    try:
        with tempfile.TemporaryDirectory(prefix="koopguide-soak-") as workdir:
            model = trained_model(args.model, Path(workdir))
            samples = asyncio.run(soak(model, args.hours, args.speedup, args.sample_s, not args.json))
    except BenchError as exc:
        print(f"koopguide bench soak: error: {exc}", file=sys.stderr)
        return 1
    figures = growth(samples, args.hours)
    if args.json:
        print(json.dumps({"samples": [asdict(s) for s in samples], **figures}, indent=2))
        return 0
    first, last = samples[0], samples[-1]
    print(
        f"soak: {last.t_s / 3600:.2f} simulated hours at {RATE_HZ:g} Hz in {last.wall_s:.0f} s wall "
        f"(x{args.speedup:g}), {len(samples)} samples"
    )
    print(
        f"RSS {first.rss_mb:.1f} -> {last.rss_mb:.1f} MB; fitted growth over the soak "
        f"{figures['rss_growth_mb_over_soak']:+.2f} MB (second half)"
    )

    def ms(value: float | None) -> str:
        return "-" if value is None else f"{value:.2f} ms"

    print(
        f"latency p99 (median of the samples): first quarter {ms(figures['p99_first_quarter_ms'])}, last quarter "
        f"{ms(figures['p99_last_quarter_ms'])}; setpoints/s at the end {last.setpoints_per_s:.1f}; "
        f"final state {last.state}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
