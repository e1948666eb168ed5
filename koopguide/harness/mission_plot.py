"""Picture of a guided mission in local NED: the scaled field's streamlines, the water flow, the boat's path.

Axes: East to the right, North up (a chart), metres. ``flow_ned(n, e)`` gives the water velocity [m/s]
(for the arrows); ``track`` is (T, 3) of t [s], N, E [m].
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np


def plot_mission(
    output: Path,
    velocity_ned: Callable[[np.ndarray], np.ndarray],
    box_ned: np.ndarray,
    track: np.ndarray,
    start_ned: tuple[float, float],
    goal_ned: tuple[float, float],
    arrive_radius_m: float,
    flow_ned: Callable[[float, float], tuple],
    title: str,
) -> None:
    """Write the PNG. ``velocity_ned((N, 2) NED points) -> (N, 2)`` is the guidance field [m/s];
    ``box_ned`` = [[N_min, E_min], [N_max, E_max]] the area to draw."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = 60
    e_lin = np.linspace(box_ned[0, 1], box_ned[1, 1], n)
    n_lin = np.linspace(box_ned[0, 0], box_ned[1, 0], n)
    ge, gn = np.meshgrid(e_lin, n_lin)
    V = velocity_ned(np.column_stack([gn.ravel(), ge.ravel()]))
    vn, ve = V[:, 0].reshape(ge.shape), V[:, 1].reshape(ge.shape)
    fig, ax = plt.subplots(figsize=(8, 8))
    speed = np.hypot(vn, ve)
    ax.streamplot(ge, gn, ve, vn, color=speed, cmap="Blues", density=1.2, linewidth=0.7, arrowsize=0.7)
    qe, qn = np.meshgrid(np.linspace(e_lin[0], e_lin[-1], 7), np.linspace(n_lin[0], n_lin[-1], 7))
    flow = np.array([flow_ned(a, b) for a, b in zip(qn.ravel(), qe.ravel(), strict=True)])
    if np.any(np.hypot(flow[:, 0], flow[:, 1]) > 0):
        ax.quiver(
            qe.ravel(), qn.ravel(), flow[:, 1], flow[:, 0], color="tab:cyan", alpha=0.7, width=0.004, label="water flow"
        )
    if len(track):
        ax.plot(track[:, 2], track[:, 1], color="tab:red", lw=1.6, label="boat (ground truth)")
    ax.plot(start_ned[1], start_ned[0], "o", color="tab:green", ms=9, label="start")
    ax.plot(goal_ned[1], goal_ned[0], "*", color="gold", mec="k", ms=16, label="goal")
    ax.add_patch(plt.Circle((goal_ned[1], goal_ned[0]), arrive_radius_m, fill=False, ls="--", color="k"))
    ax.set_xlabel("East [m]")
    ax.set_ylabel("North [m]")
    ax.set_aspect("equal")
    ax.set_title(title)
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(output, dpi=110)
    plt.close(fig)
