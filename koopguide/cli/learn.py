"""The learning side of the CLI: ``train``, ``eval``, ``plot`` and ``bench``.

Each command builds its configuration once, here, and passes it down; progress goes to stderr so
``eval --json`` keeps stdout clean for machines.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from koopguide.base import data
from koopguide.model.field import FlowField, load_field


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("train", help="train a flow field on LASA or your own demonstrations")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--lasa", metavar="SHAPE", help=f"a LASA shape ({', '.join(data.LASA_SHAPES[:4])}, ...)")
    src.add_argument("--demos", metavar="PATH", type=Path, help="a .csv/.npy file or a folder of them")
    src.add_argument("--synthetic", metavar="NAME", choices=["helix"], help="a generated set: helix (3-D)")
    p.add_argument("-o", "--output", required=True, type=Path, help="model file to write (.pt)")
    p.add_argument("--config", type=Path, help="YAML overriding config/train.yaml")
    p.add_argument("--seed", type=int, default=0, help="random seed (training is deterministic per seed)")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.add_argument(
        "--allow-uncertified",
        action="store_true",
        help="write the model even if it fails its convergence certificate (a loud warning)",
    )
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
    p.add_argument(
        "--eigenfunctions",
        action="store_true",
        help="map magnitude and phase of the leading Koopman eigenfunctions instead (2-D)",
    )
    p.add_argument("--count", type=int, default=4, help="eigenfunctions to map (default 4)")
    p.set_defaults(run=cmd_plot)

    p = sub.add_parser("bench", help="benchmarks that print figures (never timed tests)")
    p.add_argument(
        "what",
        choices=["speed", "lasa", "sitl", "guidance", "missions", "soak", "separation", "capture"],
        help="speed: training and query speed; lasa: all LASA shapes, seeds, ablations and a report; "
        "sitl: simulator; guidance: service latency and CPU; missions: closed-loop campaign of vehicles x flows "
        "x starts; soak: hours of guidance at 50 Hz, memory and latency growth; separation: two-boat encounters "
        "(head-on, crossing, overtaking) x vehicles x currents, the fleet's separation and arrival; capture: the "
        "cost of one capture search near the goal",
    )
    p.add_argument("rest", nargs=argparse.REMAINDER, help="arguments for the benchmark")
    p.set_defaults(run=cmd_bench)


# ------------------------------------------------------------------------------------- train
def demos_from(lasa: str | None, path: str | Path | None) -> data.Demonstrations:
    return data.load_lasa(lasa) if lasa else data.load_demos(path)


def cmd_train(args: argparse.Namespace) -> int:
    from koopguide.model.learn import trainer
    from koopguide.model.learn.export import UncertifiedModelError, save, training_config

    cfg = training_config(args.config)
    demos = data.load_source(f"synthetic:{args.synthetic}") if args.synthetic else demos_from(args.lasa, args.demos)
    if not args.output.parent.exists():
        raise FileNotFoundError(f"output folder {args.output.parent} does not exist")
    log = (lambda *_: None) if args.quiet else _stderr
    n_pairs = sum(len(data.subsample(t, cfg.subsample_every)) - 1 for t in demos.trajectories)
    log(
        f"training on {demos.source}: {len(demos.trajectories)} demos, dim {demos.dim}, {n_pairs} pairs, "
        f"{cfg.optim.steps} steps, seed {args.seed}"
    )

    def progress(k: int, steps: int, terms: dict[str, float]) -> None:
        log(f"  step {k:5d}/{steps}  " + "  ".join(f"{name} {value:.3e}" for name, value in terms.items()))

    trained = trainer.train(demos, cfg, args.seed, progress=progress)
    info = trained.info
    cert = trained.certificate
    if cert is None or not cert["passed"]:
        why = (
            "no certificate was made (convergence: null)"
            if cert is None
            else f"the certificate FAILED: {cert['learned']['converged']}/{cert['learned']['starts']} learned-step and "
            f"{cert['euler']['converged']}/{cert['euler']['starts']} Euler grid starts reached the goal"
        )
        if not args.allow_uncertified:
            raise UncertifiedModelError(
                f"refusing to write {args.output}: {why}; pass --allow-uncertified to write it anyway"
            )
        _stderr(
            f"WARNING: {why}. Writing {args.output} UNCERTIFIED (--allow-uncertified): trajectories may not "
            "reach the goal, and koopguide run refuses it unless its config allows uncertified models."
        )
    save(args.output, trained, demos, cfg)
    if cert is not None:
        from koopguide.model.certificate import summary_lines

        for line in summary_lines(cert):
            log(line)
    log(
        f"fit in {info['fit_seconds']:.2f} s, certified in {info['certify_seconds']:.2f} s; rho(K) {info['rho']:.3f}; "
        f"wrote {args.output}"
    )
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
        raise ValueError(
            f"demos at {source} differ from those the model was trained on (sha256 mismatch); "
            f"pass --demos PATH to evaluate on other data"
        )
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
    bad = [k for k, v in metrics.items() if isinstance(v, float) and not math.isfinite(v)]
    if bad:
        raise ValueError(
            f"{args.model}: the field gives non-finite metrics {bad} ({', '.join(f'{k}={metrics[k]}' for k in bad)})"
        )
    metrics["certificate"] = field.meta.get("certificate")
    metrics["model"] = str(args.model)
    metrics["source"] = demos.source
    if args.json:
        print(json.dumps(metrics, indent=2))
        return 0
    print(
        f"model        {args.model}  ({demos.source}; dim {field.dim}, nu {field.nu}, rank {field.rank}, "
        f"{'goal-centred' if field.goal_centred else 'paper lifting'})"
    )
    if metrics["sea"] is not None:
        print(f"SEA          {metrics['sea']:.1f}   (mean over {len(demos.trajectories)} demos)")
    print(f"DTWD         {metrics['dtwd']:.1f}")
    print(
        f"converged    {metrics['converged']}/{metrics['starts']} random starts within "
        f"{metrics['convergence_tolerance']:g} of the goal after {metrics['convergence_steps']} learned steps "
        f"(worst {metrics['final_distance_max']:.3g})"
    )
    print(
        f"converged    {metrics['converged_euler']}/{metrics['starts']} with Euler steps of velocity/"
        f"{field.substeps} ({metrics['convergence_steps'] * field.substeps} raw steps; worst "
        f"{metrics['final_distance_max_euler']:.3g})"
    )
    print(f"goal fixed-point error   {metrics['goal_fixed_point_err']:.3g}")
    print(f"spectral radius of K     {metrics['rho']:.4f}")
    from koopguide.model.certificate import certificate_ok, summary_lines

    ok, reason = certificate_ok(field)
    cert = field.meta.get("certificate")
    for line in summary_lines(cert) if isinstance(cert, dict) else []:
        print(line)
    print(f"certified    {'yes' if ok else 'NO'}: {reason}")
    return 0


# -------------------------------------------------------------------------------------- plot
def cmd_plot(args: argparse.Namespace) -> int:
    from koopguide.model.plot import plot_eigenfunctions, plot_field, plot_field_3d

    field = load_field(args.model)
    demos = training_demos(field, args.demos)
    if field.dim not in (2, 3) or (args.eigenfunctions and field.dim != 2):
        raise ValueError(
            f"plot draws 2-D fields (and 3-D trajectories without --eigenfunctions); this model has "
            f"dimension {field.dim}"
        )
    if not 1 <= args.count <= 16:
        raise ValueError(f"--count must be in [1, 16], got {args.count}")
    if not args.output.parent.exists():
        raise FileNotFoundError(f"output folder {args.output.parent} does not exist")
    title = f"{demos.source}  ({args.model.name})"
    if args.eigenfunctions:
        plot_eigenfunctions(field, demos, args.output, count=args.count, title=title)
    elif field.dim == 3:
        plot_field_3d(field, demos, args.output, title=title)
    else:
        plot_field(field, demos, args.output, title=title)
    _stderr(f"wrote {args.output}")
    return 0


# ------------------------------------------------------------------------------------- bench
def cmd_bench(args: argparse.Namespace) -> int:
    if args.what == "sitl":
        from sitl import bench as sitl_bench

        return sitl_bench.main(args.rest)
    if args.what == "soak":
        from koopguide.harness import soak

        return soak.main(args.rest)
    if args.what == "missions":
        from koopguide.harness import campaign

        return campaign.main(args.rest)
    if args.what == "separation":
        from koopguide.harness import fleet_encounters

        return fleet_encounters.main(args.rest)
    if args.what == "guidance":
        from koopguide.harness import guidance_bench

        return guidance_bench.main(args.rest)
    if args.what == "capture":
        from koopguide.harness import capture_bench

        return capture_bench.main(args.rest)
    if args.what == "lasa":
        from koopguide.harness.lasa_bench import main as lasa_main

        return lasa_main(args.rest)
    from koopguide.harness.learn_bench import main as bench_main

    return bench_main(args.rest)


def _stderr(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)
