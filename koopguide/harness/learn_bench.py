"""``koopguide bench speed``: training time, query latency and throughput, peak memory.

Figures are printed, never asserted: speed targets are checked by reading this output.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

QUERY_SCRIPT = r"""
import json, statistics, sys, time
import numpy as np
from koopguide import load_field
t0 = time.perf_counter(); field = load_field(sys.argv[1]); load_s = time.perf_counter() - t0
x = field.goal + 10.0
import os
for _ in range(2000):
    field.velocity(x)
single = []
for _ in range(7):
    n = 20000; t = time.perf_counter()
    for _ in range(n):
        field.velocity(x)
    single.append((time.perf_counter() - t) / n)
batch = {}
rng = np.random.default_rng(0)
from koopguide.model.field import FlowField
lo, hi = field.bounds
span = hi - lo
X = rng.uniform(lo - 0.1 * span, hi + 0.1 * span, (20000, field.dim))
def twin(**kw):
    return FlowField(field.W, field.b, field.A, field.B, field.goal, field.goal_centred, field.substeps,
                     limit=field.limit, **kw)
exact = twin(precision="float64", tabulate=False).velocity(X)
speed = float(np.median(np.linalg.norm(exact, axis=1)))
err_f32 = np.linalg.norm(twin(precision="float32", tabulate=False).velocity(X) - exact, axis=1)
err_all = np.linalg.norm(field.velocity(X) - exact, axis=1)
errors = {"median_speed": speed, "float32_max": float(err_f32.max()), "table_float32_max": float(err_all.max()),
          "table_float32_p99": float(np.quantile(err_all, 0.99))}
for n in (1, 100, 10000, 100000):
    X = rng.uniform(lo, hi, (n, field.dim))
    reps = max(3, 400000 // n); t = time.perf_counter()
    for _ in range(reps):
        field.velocity(X)
    batch[n] = n * reps / (time.perf_counter() - t)
print(json.dumps({"load_s": load_s, "errors": errors, "tabulated": field._table is not None,
                  "single_us_median": statistics.median(single) * 1e6,
                  "single_us_best": min(single) * 1e6, "batch_points_per_s": batch,
                  "torch_imported": "torch" in sys.modules,
                  "peak_rss_mb": [int(l.split()[1]) / 1024 for l in open("/proc/self/status")
                                  if l.startswith("VmHWM")][0]}))
"""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="koopguide bench speed")
    parser.add_argument("--lasa", default="Zshape", help="shape to train (default Zshape)")
    parser.add_argument("--repeats", type=int, default=3, help="training runs (the median is reported)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)

    from koopguide.base import data
    from koopguide.model.learn import trainer
    from koopguide.model.learn.export import save, training_config

    cfg = training_config(None)
    demos = data.load_lasa(args.lasa)
    times, fits, certs, fit_cpu, cert_cpu, trained = [], [], [], [], [], None
    for seed in range(args.repeats):
        started = time.perf_counter()
        trained = trainer.train(demos, cfg, seed)
        times.append(time.perf_counter() - started)
        fits.append(trained.info["fit_seconds"])
        certs.append(trained.info["certify_seconds"])
        fit_cpu.append(trained.info["fit_cpu_seconds"])
        cert_cpu.append(trained.info["certify_cpu_seconds"])
    train_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # includes importing torch
    with tempfile.TemporaryDirectory() as tmp:
        model = Path(tmp) / "bench.pt"
        save(model, trained, demos, cfg)
        env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}  # one BLAS thread, as benched
        out = subprocess.run(
            [sys.executable, "-c", QUERY_SCRIPT, str(model)], capture_output=True, text=True, check=True, env=env
        )
    query = json.loads(out.stdout)
    figures = {
        "shape": args.lasa,
        "train_steps": cfg.optim.steps,
        "train_threads": cfg.threads,
        "train_seconds_median": statistics.median(times),
        "train_seconds_all": times,
        "fit_seconds_median": statistics.median(fits),
        "certify_seconds_median": statistics.median(certs),
        "fit_cpu_seconds_median": statistics.median(fit_cpu),
        "certify_cpu_seconds_median": statistics.median(cert_cpu),
        "load_average": os.getloadavg(),
        "train_peak_rss_mb": train_rss,
        **{f"query_{k}": v for k, v in query.items()},
    }
    if args.json:
        print(json.dumps(figures, indent=2))
        return 0
    print(
        f"training   {args.lasa}, {cfg.optim.steps} steps, {cfg.threads} thread(s): fit median "
        f"{figures['fit_seconds_median']:.2f} s ({', '.join(f'{t:.2f}' for t in fits)}); certify-and-repair median "
        f"{figures['certify_seconds_median']:.2f} s; total median {figures['train_seconds_median']:.2f} s "
        f"over {len(times)} runs; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs"
    )
    print(
        f"           CPU time (other jobs inflate it less than wall time): fit median "
        f"{figures['fit_cpu_seconds_median']:.2f} s, certify-and-repair median "
        f"{figures['certify_cpu_seconds_median']:.2f} s"
    )
    print(f"           peak RSS of the training process {train_rss:.0f} MB")
    print(
        f"query      field.velocity, one point: median {query['single_us_median']:.1f} us "
        f"(best {query['single_us_best']:.1f} us); torch imported: {query['torch_imported']}"
    )
    for n, rate in query["batch_points_per_s"].items():
        print(f"           batch of {int(n):>6}: {rate / 1e6:.2f} M points/s")
    e = query["errors"]
    print(
        f"accuracy   vs float64 exact evaluation of the same limited field over the box (median |v| "
        f"{e['median_speed']:.3g}): float32 alone max {e['float32_max']:.2g}; query table + float32 max "
        f"{e['table_float32_max']:.2g}, p99 {e['table_float32_p99']:.2g} (tabulated: {query['tabulated']})"
    )
    print(
        f"           load_field {query['load_s'] * 1e3:.1f} ms; peak RSS of the query process "
        f"{query['peak_rss_mb']:.0f} MB (numpy only)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
