"""``koopguide bench lasa``: all LASA shapes and seeds, the paper-faithful configuration, ablations and a
linear EDMD baseline, in worker processes, written up as a markdown report with figures.

Array conventions: LASA units throughout; per-run results are plain dicts (one row of the report).
Figures are measured, never asserted.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

from koopguide.base import data
from koopguide.harness.lasa_report import write_report
from koopguide.model.edmd import edmd_field

ABLATIONS: dict[str, dict] = {
    **{f"nu={nu}": {"model": {"nu": nu}} for nu in (128, 256, 512, 1024, 2048)},
    "no divergence term": {"loss": {"divergence": 0.0}},
    "no goal term": {"model": {"goal_centred": False}, "loss": {"goal": 0.0}},
}  # raw fields (convergence: null): what the learning itself gives, before the Lyapunov limit


def run_one(job: dict) -> dict:
    """Train (or fit EDMD) and evaluate one (configuration, shape, seed); runs in a worker process."""
    from koopguide.base import config
    from koopguide.model.evaluate import evaluate
    from koopguide.model.learn import trainer
    from koopguide.model.learn.export import save

    demos = data.load_lasa(job["shape"])
    started, cpu_started = time.perf_counter(), time.process_time()
    if job["kind"] == "edmd":
        field = edmd_field(demos, nu=1024, subsample_every=40, seed=job["seed"])
        fit_s, cert, info = time.perf_counter() - started, None, {}
    else:
        layers = config.load_layers("train", job.get("config_file"), {})
        for extra in job.get("layers", []):
            layers = config.merge(layers, extra)
        cfg = config.build(trainer.TrainConfig, layers)
        trained = trainer.train(demos, cfg, job["seed"])
        field, cert, info = trained.field(), trained.certificate, trained.info
        fit_s = info["fit_seconds"]
        if job.get("models"):
            out = Path(job["models"]) / job["label_dir"] / f"{job['shape']}_seed{job['seed']}.pt"
            out.parent.mkdir(parents=True, exist_ok=True)
            save(out, trained, demos, cfg)
    total_s = time.perf_counter() - started
    m = evaluate(field, demos, starts=500, seed=1000 + job["seed"])
    row = {k: job[k] for k in ("label", "shape", "seed")}
    row.update(
        sea=m["sea"],
        dtwd=m["dtwd"],
        converged=m["converged"],
        converged_euler=m["converged_euler"],
        worst=max(m["final_distance_max"], m["final_distance_max_euler"]),
        rho=m["rho"],
        goal_err=m["goal_fixed_point_err"],
        fit_seconds=fit_s,
        train_seconds=total_s,
        eval_seconds=time.perf_counter() - started - total_s,
        cpu_seconds=time.process_time() - cpu_started,  # train + certify + evaluate, this process's CPU time
        certified=None if cert is None else bool(cert["passed"]),
        repairs=None if cert is None else len(cert["repairs"]) - 1,
        rho_trained=info.get("rho_trained"),
    )
    return row


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="koopguide bench lasa")
    p.add_argument("--shapes", default="all", help="'all' or a comma-separated list of LASA shapes")
    p.add_argument("--seeds", default="0,1,2", help="seeds of the default configuration")
    p.add_argument("--config", type=Path, help="YAML overriding config/train.yaml for the main runs")
    p.add_argument("--models", type=Path, help="keep every trained model file here (default: OUTPUT/models)")
    p.add_argument("-o", "--output", type=Path, required=True, help="folder for report.md, results.json, PNGs")
    p.add_argument("--workers", type=int, default=2, help="worker processes (default 2: both cores)")
    p.add_argument("--paper-seeds", default="0", help="seeds of the paper-faithful configuration ('' skips it)")
    p.add_argument("--ablation-seeds", default="0", help="seeds of the ablations and EDMD ('' skips them)")
    p.add_argument("--ablation-shapes", default="all", help="shapes of the ablations and EDMD")
    args = p.parse_args(argv)

    shapes = _shapes(args.shapes)
    seeds, paper_seeds, abl_seeds = _ints(args.seeds), _ints(args.paper_seeds), _ints(args.ablation_seeds)
    abl_shapes = _shapes(args.ablation_shapes)
    if args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    args.output.mkdir(parents=True, exist_ok=True)
    cfg_file = str(args.config) if args.config else None
    args.models = args.models or args.output / "models"
    models = str(args.models)
    jobs = [
        dict(kind="koop", label="default", label_dir="default", shape=s, seed=k, config_file=cfg_file, models=models)
        for k in seeds
        for s in shapes
    ]
    main_count = len(jobs)
    paper_file = str(Path(__file__).resolve().parent.parent / "defaults" / "paper.yaml")
    jobs += [
        dict(kind="koop", label="paper", label_dir="paper", shape=s, seed=k, config_file=paper_file, models=None)
        for k in paper_seeds
        for s in shapes
    ]
    for name, layer in ABLATIONS.items():
        jobs += [
            dict(
                kind="koop",
                label=name,
                label_dir=name,
                shape=s,
                seed=k,
                config_file=None,
                layers=[{"convergence": None}, layer],
                models=None,
            )
            for k in abl_seeds
            for s in abl_shapes
        ]
    jobs += [dict(kind="edmd", label="EDMD", shape=s, seed=k) for k in abl_seeds for s in abl_shapes]

    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")  # one BLAS thread per worker: spinning BLAS threads only contend here
    rows: list[dict] = []
    started = time.perf_counter()
    main_wall = None
    with ProcessPoolExecutor(max_workers=args.workers, mp_context=get_context("spawn")) as pool:
        for i, row in enumerate(pool.map(run_one, jobs)):
            rows.append(row)
            if i + 1 == main_count:
                main_wall = time.perf_counter() - started
            print(
                f"[{i + 1}/{len(jobs)}] {row['label']:<18} {row['shape']:<16} seed {row['seed']}  SEA "
                f"{_f(row['sea'])}  DTWD {_f(row['dtwd'])}  conv {row['converged']}/{row['converged_euler']}  "
                f"cert {row['certified']}  {row['train_seconds']:.1f}+{row['eval_seconds']:.1f} s",
                flush=True,
            )
    wall = time.perf_counter() - started
    meta = {
        "shapes": shapes,
        "seeds": seeds,
        "paper_seeds": paper_seeds,
        "ablation_seeds": abl_seeds,
        "ablation_shapes": abl_shapes,
        "workers": args.workers,
        "main_wall_seconds": main_wall,
        "main_cpu_seconds": sum(r["cpu_seconds"] for r in rows[:main_count]),
        "wall_seconds": wall,
        "load_average": os.getloadavg(),
        "cpus": os.cpu_count(),
    }
    (args.output / "results.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))

    write_report(args.output, rows, meta, models=args.models)
    print(
        f"wrote {args.output / 'report.md'}; main runs {main_wall:.0f} s wall ({meta['main_cpu_seconds']:.0f} CPU-s "
        f"in the runs themselves), everything {wall:.0f} s; load average {os.getloadavg()[0]:.1f}"
    )
    return 0


def _f(v: float | None) -> str:
    return "-" if v is None else f"{v:.0f}"


def _shapes(text: str) -> list[str]:
    if text == "all":
        return list(data.LASA_SHAPES)
    names = [s.strip() for s in text.split(",") if s.strip()]
    for name in names:
        data.load_lasa(name)  # a DemoDataError naming the unknown shape
    return names


def _ints(text: str) -> list[int]:
    try:
        return [int(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise ValueError(f"expected comma-separated integers, got {text!r}") from None


if __name__ == "__main__":
    sys.exit(main())
