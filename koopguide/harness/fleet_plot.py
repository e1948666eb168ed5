"""Pictures of a fleet mission: the boats' true paths over the field's streamlines (PNG) and an animated
replay (GIF, matplotlib's PillowWriter). Tracks are (T, 3): t [s], N [m], E [m]; plots put East on x."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

COLOURS = ("tab:red", "tab:purple", "tab:orange", "tab:brown", "tab:pink", "tab:olive", "tab:cyan")
GIF_FRAMES = 60  # frames of the replay
GIF_FPS = 10
GIF_DPI = 55  # the replay stays small (about a megabyte) and quick to render


def _axes(
    velocity_ned: Callable[[np.ndarray], np.ndarray],
    box_ned: np.ndarray,
    slots: np.ndarray,
    radius_m: float,
    title: str,
) -> tuple[Any, Any]:  # a matplotlib (figure, axes)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = 50
    e_lin, n_lin = np.linspace(box_ned[0, 1], box_ned[1, 1], n), np.linspace(box_ned[0, 0], box_ned[1, 0], n)
    ge, gn = np.meshgrid(e_lin, n_lin)
    v = velocity_ned(np.column_stack([gn.ravel(), ge.ravel()]))
    vn, ve = v[:, 0].reshape(ge.shape), v[:, 1].reshape(ge.shape)
    fig, ax = plt.subplots(figsize=(7, 7))
    ax.streamplot(ge, gn, ve, vn, color=np.hypot(vn, ve), cmap="Blues", density=1.1, linewidth=0.7, arrowsize=0.7)
    for k, slot in enumerate(slots):
        ax.plot(slot[1], slot[0], "*", color="gold", mec="k", ms=14, label="slots" if k == 0 else None)
        ax.add_patch(plt.Circle((slot[1], slot[0]), radius_m, fill=False, ls="--", color="k"))
    ax.set_xlim(e_lin[0], e_lin[-1])
    ax.set_ylim(n_lin[0], n_lin[-1])
    ax.set_xlabel("East [m]")
    ax.set_ylabel("North [m]")
    ax.set_aspect("equal")
    ax.set_title(title)
    return fig, ax


def plot_fleet(
    output: Path,
    velocity_ned: Callable[[np.ndarray], np.ndarray],
    box_ned: np.ndarray,
    tracks: list[np.ndarray],
    slots: np.ndarray,
    radius_m: float,
    title: str,
) -> None:
    """The PNG: each boat's true path from its start (circle) to its slot (star)."""
    import matplotlib.pyplot as plt

    fig, ax = _axes(velocity_ned, box_ned, slots, radius_m, title)
    for k, track in enumerate(tracks):
        if len(track):
            colour = COLOURS[k % len(COLOURS)]
            ax.plot(track[:, 2], track[:, 1], color=colour, lw=1.6, label=f"boat{k + 1} (ground truth)")
            ax.plot(track[0, 2], track[0, 1], "o", color=colour, ms=8)
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(output, dpi=110)
    plt.close(fig)


def animate_fleet(
    output: Path,
    velocity_ned: Callable[[np.ndarray], np.ndarray],
    box_ned: np.ndarray,
    tracks: list[np.ndarray],
    slots: np.ndarray,
    radius_m: float,
    min_separation_m: float,
    title: str,
) -> None:
    """The GIF: the boats (with a circle of radius min_separation_m / 2: circles never overlap while the
    separation holds) and their trails, over simulated time."""
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    fig, ax = _axes(velocity_ned, box_ned, slots, radius_m, title)
    live = [t for t in tracks if len(t)]
    t0, t1 = max(t[0, 0] for t in live), min(t[-1, 0] for t in live)
    times = np.linspace(t0, t1, GIF_FRAMES)
    trails, dots, rings = [], [], []
    for k in range(len(live)):
        colour = COLOURS[k % len(COLOURS)]
        trails.append(ax.plot([], [], color=colour, lw=1.4)[0])
        dots.append(ax.plot([], [], "o", color=colour, ms=7)[0])
        rings.append(ax.add_patch(plt.Circle((0, 0), min_separation_m / 2, fill=False, color=colour, lw=0.8)))
    clock = ax.text(0.02, 0.97, "", transform=ax.transAxes, va="top")

    def frame(i: int) -> list:
        for track, trail, dot, ring in zip(live, trails, dots, rings, strict=True):
            upto = track[track[:, 0] <= times[i]]
            n, e = np.interp(times[i], track[:, 0], track[:, 1]), np.interp(times[i], track[:, 0], track[:, 2])
            trail.set_data(upto[:, 2], upto[:, 1])
            dot.set_data([e], [n])
            ring.center = (e, n)
        clock.set_text(f"t = {times[i] - t0:5.1f} s")
        return [*trails, *dots, *rings, clock]

    FuncAnimation(fig, frame, frames=len(times), blit=False).save(output, writer=PillowWriter(fps=GIF_FPS), dpi=GIF_DPI)
    plt.close(fig)
