"""The markdown report and figures of ``koopguide bench lasa`` (from its result rows and model files).

Array conventions: LASA units; rows as produced by :func:`koopguide.harness.lasa_bench.run_one`.
"""

from __future__ import annotations

import math
import statistics
from collections import defaultdict
from pathlib import Path

import numpy as np

from koopguide.base import data

PAPER = {"sea": (169.0, 74.0), "dtwd": (1595.0, 537.0)}  # KoopMotion, 30 LASA shapes, nu = 1000


def mean_std(values: list[float]) -> tuple[float, float]:
    vals = [v for v in values if v is not None and math.isfinite(v)]
    if not vals:
        return float("nan"), float("nan")
    return statistics.fmean(vals), (statistics.stdev(vals) if len(vals) > 1 else 0.0)


def _per_shape(rows: list[dict], label: str) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = defaultdict(list)
    for r in rows:
        if r["label"] == label:
            out[r["shape"]].append(r)
    return out


def _summary(rows: list[dict], label: str) -> dict:
    """Means over seeds per shape, then mean +- std over shapes; convergence and certificate counts."""
    per = _per_shape(rows, label)
    sea = [float(np.mean([r["sea"] for r in rs])) for rs in per.values()]
    dtwd = [float(np.mean([r["dtwd"] for r in rs])) for rs in per.values()]
    runs = [r for rs in per.values() for r in rs]
    return {
        "label": label, "shapes": len(per), "runs": len(runs),
        "sea": mean_std(sea), "dtwd": mean_std(dtwd),
        "full_learned": sum(r["converged"] == 500 for r in runs),
        "full_euler": sum(r["converged_euler"] == 500 for r in runs),
        "certified": sum(bool(r["certified"]) for r in runs),
        "rho_below_1": sum(r["rho"] < 1.0 for r in runs),
        "goal_ok": sum(r["goal_err"] <= 0.01 for r in runs),
        "fit_median": float(np.median([r["fit_seconds"] for r in runs])) if runs else math.nan,
    }  # fmt: skip


def _cpu_sentence(meta: dict) -> str:
    """The default runs' own CPU time: what they cost without other jobs, whatever the load."""
    cpu = meta.get("main_cpu_seconds")
    if cpu is None:
        return ""
    per = cpu / max(1, len(meta["shapes"]) * len(meta["seeds"]))
    return (
        f"The default runs themselves used {cpu:.0f} CPU-seconds ({per:.1f} s per shape and seed for train, "
        f"certify and evaluate), i.e. about {cpu / meta['workers']:.0f} s of wall time on {meta['workers']} "
        "otherwise idle cores, plus the workers' start-up."
    )


def write_report(out: Path, rows: list[dict], meta: dict, models: Path | None) -> None:
    labels = list(dict.fromkeys(r["label"] for r in rows))
    summaries = {label: _summary(rows, label) for label in labels}
    lines = [
        "# LASA benchmark",
        "",
        f"`koopguide bench lasa`: {len(meta['shapes'])} shapes, default seeds {meta['seeds']}, paper-faithful "
        f"seeds {meta['paper_seeds']}, ablations and EDMD on seeds {meta['ablation_seeds']} over "
        f"{len(meta['ablation_shapes'])} shapes; {meta['workers']} worker processes on {meta['cpus']} cores. "
        f"Wall time: default runs {meta['main_wall_seconds']:.0f} s, everything {meta['wall_seconds']:.0f} s "
        f"(load average at the end {', '.join(f'{v:.1f}' for v in meta['load_average'])}: the machine was "
        f"shared with other jobs). {_cpu_sentence(meta)}",
        "",
        "Convergence: 500 uniform random starts from the demonstrations' box with each side moved out by 10%, "
        "within 1 unit of the goal after 100 learned steps (`learned`) and after 100 x 40 Euler steps of "
        "velocity/40 (`euler`). Certificate: the same for a 100 x 100 grid of starts, recorded in the model file.",
        "",
        "## Summary (mean +- std over shapes of the per-shape mean over seeds)",
        "",
        "| configuration | runs | SEA | DTWD | 500/500 learned | 500/500 euler | certified | rho < 1 | "
        "goal err <= 0.01 | median fit s |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for label, s in summaries.items():
        lines.append(
            f"| {label} | {s['runs']} | {s['sea'][0]:.0f} +- {s['sea'][1]:.0f} | {s['dtwd'][0]:.0f} +- "
            f"{s['dtwd'][1]:.0f} | {s['full_learned']} | {s['full_euler']} | {s['certified']} | "
            f"{s['rho_below_1']} | {s['goal_ok']} | {s['fit_median']:.2f} |"
        )
    lines.append(
        f"| paper (published, nu = 1000) | 30 | {PAPER['sea'][0]:.0f} +- {PAPER['sea'][1]:.0f} | "
        f"{PAPER['dtwd'][0]:.0f} +- {PAPER['dtwd'][1]:.0f} | | | | | | |"
    )
    lines += [
        "",
        "Ablations and EDMD are raw learned fields (no Lyapunov limit, no certificate): they show what "
        "the learning itself gives. `paper` is `config/paper.yaml` run here.",
        "",
        "## Per shape (default configuration)",
        "",
        "| shape | SEA | DTWD | converged learned (min over seeds) | converged euler (min) | worst end distance "
        "| certified | repairs | rho (max) | fit s (mean) | fit+certify s (mean) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for shape, rs in _per_shape(rows, "default").items():
        lines.append(
            f"| {shape} | {np.mean([r['sea'] for r in rs]):.0f} | {np.mean([r['dtwd'] for r in rs]):.0f} | "
            f"{min(r['converged'] for r in rs)}/500 | {min(r['converged_euler'] for r in rs)}/500 | "
            f"{max(r['worst'] for r in rs):.3g} | {sum(bool(r['certified']) for r in rs)}/{len(rs)} | "
            f"{max(r['repairs'] or 0 for r in rs)} | {max(r['rho'] for r in rs):.3f} | "
            f"{np.mean([r['fit_seconds'] for r in rs]):.2f} | {np.mean([r['train_seconds'] for r in rs]):.2f} |"
        )
    if models is not None and (Path(models) / "default").is_dir():
        seed = meta["seeds"][0]
        fields = _load(Path(models) / "default", meta["shapes"], seed)
        if fields:
            grid_figure(fields, out / "lasa-grid.png")
            eigen_figure(fields, out / "lasa-eigenvalues.png")
            lines += [
                "",
                f"## Fields (seed {seed})",
                "",
                "![fields](lasa-grid.png)",
                "",
                "Grey: demonstrations; red: reproductions from their starts; orange: rollouts from a grid of "
                "starts over the certificate box.",
                "",
                f"## Eigenvalues of K (seed {seed})",
                "",
                "![eigenvalues](lasa-eigenvalues.png)",
            ]
    (out / "report.md").write_text("\n".join(lines) + "\n")


def _load(folder: Path, shapes: list[str], seed: int) -> dict:
    from koopguide.model.field import load_field

    out = {}
    for shape in shapes:
        path = folder / f"{shape}_seed{seed}.pt"
        if path.is_file():
            out[shape] = load_field(path)
    return out


def grid_figure(fields: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from koopguide.model.evaluate import convergence_box, reproduce

    n = len(fields)
    cols = 6
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.2 * rows), squeeze=False)
    for ax, (shape, field) in zip(axes.ravel(), fields.items(), strict=False):
        demos = data.load_lasa(shape)
        lo, hi = convergence_box(demos.bounds, 0.1)
        gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], 40), np.linspace(lo[1], hi[1], 40))
        V = field.velocity(np.column_stack([gx.ravel(), gy.ravel()]))
        ax.streamplot(
            gx,
            gy,
            V[:, 0].reshape(gx.shape),
            V[:, 1].reshape(gx.shape),
            color="0.75",
            density=0.8,
            linewidth=0.5,
            arrowsize=0.5,
        )
        starts = np.column_stack(
            [g.ravel() for g in np.meshgrid(np.linspace(lo[0], hi[0], 5), np.linspace(lo[1], hi[1], 5))]
        )
        for path_ in field.rollout(starts, 60 * field.substeps // 4, substeps=field.substeps // 4 or 1):
            ax.plot(path_[:, 0], path_[:, 1], color="tab:orange", lw=0.5)
        for t in demos.trajectories:
            ax.plot(t[:, 0], t[:, 1], color="0.25", lw=0.9)
        for r in reproduce(field, demos):
            ax.plot(r[:, 0], r[:, 1], color="tab:red", lw=0.9)
        ax.plot(*field.goal, "*", color="gold", mec="k", ms=9)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal")
        ax.set_title(shape, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def eigen_figure(fields: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(fields)
    cols = 6
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(2.4 * cols, 2.4 * rows), squeeze=False)
    t = np.linspace(0, 2 * np.pi, 200)
    for ax, (shape, field) in zip(axes.ravel(), fields.items(), strict=False):
        lam = np.linalg.eigvals(field.B.T @ field.A)
        ax.plot(np.cos(t), np.sin(t), color="0.6", lw=0.8)
        ax.plot(lam.real, lam.imag, "x", color="tab:blue", ms=4)
        ax.set_title(f"{shape}: rho {np.max(np.abs(lam)):.3f}", fontsize=8)
        ax.set_xlim(-1.1, 1.1)
        ax.set_ylim(-1.1, 1.1)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
