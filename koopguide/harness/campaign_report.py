"""The mission campaign's report, from :class:`koopguide.harness.campaign.RunResult` records: ``report.md``
(aggregates per vehicle and flow, then every run) and ``paths.png`` (a grid, vehicles x flows, of the true
paths over the field's streamlines).

Conventions: local NED metres (East to the right, North up in the pictures), simulated seconds, m/s.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np


def _fmt(value: float | None, digits: int = 2) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def _stats(values: list[float | None]) -> tuple[float | None, float | None]:
    """(median, max) of the values that exist."""
    v = [x for x in values if x is not None and math.isfinite(x)]
    return (float(np.median(v)), float(max(v))) if v else (None, None)


def aggregate(results: list[Any]) -> list[dict[str, Any]]:
    """One row per (vehicle, flow), in the order met."""
    rows = []
    for key in dict.fromkeys((r.vehicle, r.flow) for r in results):
        group = [r for r in results if (r.vehicle, r.flow) == key]
        arrived = [r for r in group if r.arrived]
        rows.append(
            {
                "vehicle": key[0],
                "flow": key[1],
                "runs": len(group),
                "arrived": len(arrived),
                "errors": sum(r.error is not None for r in group),
                "time": _stats([r.time_to_arrive_s for r in arrived]),
                "ratio": _stats([r.time_ratio for r in arrived]),
                "dev_rms": _stats([r.deviation_rms_m for r in group]),
                "dev_max": _stats([r.deviation_max_m for r in group]),
                "hold_p95": _stats([r.hold_p95_m for r in arrived]),
                "max_setpoint": _stats([r.max_setpoint_mps for r in group])[1],
                "arrived_but_far": sum(r.arrived_but_far for r in group),
            }
        )
    return rows


def write(out: Path, results: list[Any], field_: Any, setup: str) -> None:
    """``report.md`` (``setup``: a paragraph on how the campaign ran) and ``paths.png`` in ``out``."""
    rows = aggregate(results)
    total = len(results)
    arrived = sum(r.arrived for r in results)
    lines = [
        "# Mission campaign",
        "",
        setup,
        "",
        f"**Overall: {arrived}/{total} arrived.**",
        "",
        "Time ratio = time to arrive / ideal time (the field's streamline from the start driven at `max_speed`). "
        "Deviation = distance of the true path before arrival from that streamline. Hold p95 = 95th percentile of "
        'the true distance to the goal over the watch after arrival. "Far" counts runs in which the service said '
        "`arrived` while the true boat was beyond the reacquire radius.",
        "",
        "| vehicle | flow | arrived | time to arrive median / max [s] | time ratio median | deviation RMS median "
        "[m] | deviation max [m] | hold p95 median / max [m] | largest setpoint [m/s] | far | errors |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for row in rows:
        lines.append(
            f"| {row['vehicle']} | {row['flow']} | {row['arrived']}/{row['runs']} "
            f"({100 * row['arrived'] / row['runs']:.0f}%) | {_fmt(row['time'][0], 1)} / {_fmt(row['time'][1], 1)} | "
            f"{_fmt(row['ratio'][0])} | {_fmt(row['dev_rms'][0], 3)} | {_fmt(row['dev_max'][1], 3)} | "
            f"{_fmt(row['hold_p95'][0], 3)} / {_fmt(row['hold_p95'][1], 3)} | {_fmt(row['max_setpoint'], 3)} | "
            f"{row['arrived_but_far']} | {row['errors']} |"
        )
    lines += [
        "",
        "## Every run",
        "",
        "| vehicle | flow | start | start NED [m] | arrived | time [s] | ratio | dev RMS / max [m] | "
        "hold p95 [m] | final [m] | largest setpoint [m/s] |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in results:
        note = f" ({r.error})" if r.error else ""
        lines.append(
            f"| {r.vehicle} | {r.flow} | {r.start_index} | {_fmt(r.start_ned[0])}, {_fmt(r.start_ned[1])} | "
            f"{'yes' if r.arrived else 'no' + note} | {_fmt(r.time_to_arrive_s, 1)} | {_fmt(r.time_ratio)} | "
            f"{_fmt(r.deviation_rms_m, 3)} / {_fmt(r.deviation_max_m, 3)} | {_fmt(r.hold_p95_m, 3)} | "
            f"{_fmt(r.final_distance_m, 3)} | {_fmt(r.max_setpoint_mps, 3)} |"
        )
    lines += ["", "![paths](paths.png)", ""]
    (out / "report.md").write_text("\n".join(lines))
    plot_paths(out / "paths.png", results, field_)


def plot_paths(output: Path, results: list[Any], field_: Any) -> None:
    """Vehicles (rows) x flows (columns): every run's true path over the field's streamlines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from koopguide.guidance import settings
    from koopguide.guidance.law.command import GuidanceLaw

    cfg = settings.load(
        overrides={
            "frame": {"goal_ned": [0.0, 0.0], "scale": 0.04, "heading_deg": 90.0},
            "command": {"max_speed_mps": 0.3},
        }
    )
    law = GuidanceLaw.from_config(field_, cfg)
    vehicles = list(dict.fromkeys(r.vehicle for r in results))
    flows = list(dict.fromkeys(r.flow for r in results))
    corners = law.frame.to_ned(np.array(field_.bounds))
    lo, hi = corners.min(axis=0) - 0.4, corners.max(axis=0) + 0.4
    n_lin, e_lin = np.linspace(lo[0], hi[0], 40), np.linspace(lo[1], hi[1], 40)
    ge, gn = np.meshgrid(e_lin, n_lin)
    V = np.array([law.field_velocity_ned(p) for p in np.column_stack([gn.ravel(), ge.ravel()])])
    vn, ve = V[:, 0].reshape(ge.shape), V[:, 1].reshape(ge.shape)
    fig, axes = plt.subplots(
        len(vehicles),
        len(flows),
        figsize=(2.6 * len(flows), 2.8 * len(vehicles)),
        squeeze=False,
        sharex=True,
        sharey=True,
    )
    for i, vehicle in enumerate(vehicles):
        for j, flow in enumerate(flows):
            ax = axes[i, j]
            ax.streamplot(ge, gn, ve, vn, color="0.75", density=0.8, linewidth=0.5, arrowsize=0.5)
            for r in (r for r in results if r.vehicle == vehicle and r.flow == flow and r.track):
                track = np.array(r.track)
                ax.plot(track[:, 2], track[:, 1], lw=0.9, color="tab:blue" if r.arrived else "tab:red")
                ax.plot(track[0, 2], track[0, 1], "o", ms=2.5, color="tab:green")
            ax.add_patch(plt.Circle((0.0, 0.0), 0.15, fill=False, color="k", lw=0.6))
            ax.set_aspect("equal")
            if i == 0:
                ax.set_title(flow, fontsize=9)
            if j == 0:
                ax.set_ylabel(f"{vehicle}\nNorth [m]", fontsize=8)
            if i == len(vehicles) - 1:
                ax.set_xlabel("East [m]", fontsize=8)
            ax.tick_params(labelsize=6)
    fig.suptitle("true paths (blue: arrived, red: not) over the field's streamlines", fontsize=10)
    fig.tight_layout()
    fig.savefig(output, dpi=90)
    plt.close(fig)
