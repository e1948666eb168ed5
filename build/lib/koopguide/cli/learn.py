"""The learning side of the CLI: ``train``, ``eval``, ``plot`` and ``bench``.

Each command builds its configuration once, here, and passes it down; progress goes to stderr so
``eval --json`` keeps stdout clean for machines.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from koopguide.base import data
from koopguide.model.field import FlowField, load_field


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("train", help="train a flow field on LASA or your own demonstrations")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--lasa", metavar="SHAPE", help=f"a LASA shape ({', '.join(data.LASA_SHAPES[:4])}, ...)")
    src.add_argument("--demos", metavar="PATH", type=Path, help="a .csv/.npy file or a folder of them")
    p.add_argument("-o", "--output", required=True, type=Path, help="model file to write (.pt)")
    p.add_argument("--config", type=Path, help="YAML overriding config/train.yaml")
    p.add_argument("--seed", type=int, default=0, help="random seed (training is deterministic per seed)")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(run=cmd_train)

    p = sub.add_parser("eval", help="SEA, DTWD, convergence, fixed-point error and spectral radius")
    p.add_argument("model", type=Path)
    p.add_argument("--demos", metavar="PATH", help="evaluate on these demos (default: the training data)")
    p.add_argument("--json", action="store_true", help="print the metrics as JSON")
    p.add_argument("--starts", type=int, default=500, help="random starts for the convergence test")
    p.add_argument("--seed", type=int, default=0, help="seed of the random starts")
    p.set_defaults(run=cmd_eval)

    p = sub.add_parser("plot", help="streamlines, demos, rollouts and K's eigenvalues as a PNG")
    p.add_argument("model", type=Path)
    p.add_argument("-o", "--output", required=True, type=Path)
    p.add_argument("--demos", metavar="PATH", help="demos to draw (default: the training data)")
    p.set_defaults(run=cmd_plot)

    p = sub.add_parser("bench", help="benchmarks that print figures (never timed tests)")
    p.add_argument("what", choices=["speed", "sitl", "guidance", "missions"],
                   help="speed: training and query speed; sitl: simulator; guidance: service latency and CPU; "
                   "missions: closed-loop campaign of vehicles x flows x starts")
    p.add_argument("rest", nargs=argparse.REMAINDER, help="arguments for the benchmark")
    p.set_defaults(run=cmd_bench)


# ------------------------------------------------------------------------------------- train
def demos_from(lasa: str | None, path: str | Path | None) -> data.Demonstrations:
    return data.load_lasa(lasa) if lasa else data.load_demos(path)


def cmd_train(args: argparse.Namespace) -> int:
    from koopguide.model.learn import trainer
    from koopguide.model.learn.export import save, training_config

    cfg = training_config(args.config)
    demos = demos_from(args.lasa, args.demos)
    if not args.output.parent.exists():
        raise FileNotFoundError(f"output folder {args.output.parent} does not exist")
    log = (lambda *_: None) if args.quiet else _stderr
    n_pairs = sum(len(data.subsample(t, cfg.subsample_every)) - 1 for t in demos.trajectories)
    log(f"training on {demos.source}: {len(demos.trajectories)} demos, dim {demos.dim}, {n_pairs} pairs, "
        f"{cfg.optim.steps} steps, seed {args.seed}")

    def progress(k: int, steps: int, terms: dict[str, float]) -> None:
        log(f"  step {k:5d}/{steps}  " + "  ".join(f"{name} {value:.3e}" for name, value in terms.items()))

    trained = trainer.train(demos, cfg, args.seed, progress=progress)
    save(args.output, trained, demos, cfg)
    info = trained.info
    log(f"trained in {info['train_seconds']:.1f} s; rho(K) {info['rho']:.3f}; wrote {args.output}")
    return 0


# -------------------------------------------------------------------------------------- eval
def training_demos(field: FlowField, override: str | None) -> data.Demonstrations:
    """The demonstrations to compare with: ``override``, else the model's own training data."""
    if override is not None:
        return data.load_source(override)
    summary = field.meta.get("data", {})
    source = summary.get("source")
    if not source:
        raise ValueError("model file does not record its training data; pass --demos PATH")
    demos = data.load_source(source)
    if summary.get("sha256") and demos.digest() != summary["sha256"]:
        raise ValueError(f"demos at {source} differ from those the model was trained on (sha256 mismatch); "
                         f"pass --demos PATH to evaluate on other data")
    return demos


def cmd_eval(args: argparse.Namespace) -> int:
    from koopguide.model.evaluate import evaluate

    field = load_field(args.model)
    demos = training_demos(field, args.demos)
    if demos.dim != field.dim:
        raise ValueError(f"demos have dimension {demos.dim}, model has dimension {field.dim}")
    if args.starts < 1:
        raise ValueError(f"--starts must be >= 1, got {args.starts}")
    metrics = evaluate(field, demos, starts=args.starts, seed=args.seed)
    metrics["model"] = str(args.model)
    metrics["source"] = demos.source
    if args.json:
        print(json.dumps(metrics, indent=2))
        return 0
    print(f"model        {args.model}  ({demos.source}; dim {field.dim}, nu {field.nu}, rank {field.rank}, "
          f"{'goal-centred' if field.goal_centred else 'paper lifting'})")
    if metrics["sea"] is not None:
        print(f"SEA          {metrics['sea']:.1f}   (mean over {len(demos.trajectories)} demos)")
    print(f"DTWD         {metrics['dtwd']:.1f}")
    print(f"converged    {metrics['converged']}/{metrics['starts']} random starts within "
          f"{metrics['convergence_tolerance']:g} of the goal after {metrics['convergence_steps']} learned steps "
          f"(worst {metrics['final_distance_max']:.3g})")
    print(f"goal fixed-point error   {metrics['goal_fixed_point_err']:.3g}")
    print(f"spectral radius of K     {metrics['rho']:.4f}")
    return 0


# -------------------------------------------------------------------------------------- plot
def cmd_plot(args: argparse.Namespace) -> int:
    from koopguide.model.plot import plot_field

    field = load_field(args.model)
    demos = training_demos(field, args.demos)
    if field.dim != 2:
        raise ValueError(f"plot draws 2-D fields; this model has dimension {field.dim}")
    if not args.output.parent.exists():
        raise FileNotFoundError(f"output folder {args.output.parent} does not exist")
    plot_field(field, demos, args.output, title=f"{demos.source}  ({args.model.name})")
    _stderr(f"wrote {args.output}")
    return 0


# ------------------------------------------------------------------------------------- bench
def cmd_bench(args: argparse.Namespace) -> int:
    if args.what == "sitl":
        from sitl import bench as sitl_bench

        return sitl_bench.main(args.rest)
    if args.what == "missions":
        from koopguide.harness import campaign

        return campaign.main(args.rest)
    if args.what == "guidance":
        from koopguide.harness import guidance_bench

        return guidance_bench.main(args.rest)
    from koopguide.harness.learn_bench import main as bench_main

    return bench_main(args.rest)


def _stderr(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)

