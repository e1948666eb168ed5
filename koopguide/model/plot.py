"""Pictures of a 2-D flow field: streamlines, demonstrations, rollouts, and K's spectrum.

Array conventions: model units, x right, y up; trajectories ``(T, 2)``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from koopguide.base.data import Demonstrations
from koopguide.model.evaluate import convergence_box, reproduce
from koopguide.model.field import FlowField


def plot_field(field: FlowField, demos: Demonstrations, output: Path, title: str = "", grid_starts: int = 6) -> None:
    """Write a PNG: left, the field over the demonstrations' box enlarged 10% per side; right, eigenvalues of K."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lo, hi = convergence_box(demos.bounds, 0.1)
    fig, (ax, ax_eig) = plt.subplots(1, 2, figsize=(13, 6), gridspec_kw={"width_ratios": [1.35, 1]})

    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], 60), np.linspace(lo[1], hi[1], 60))
    V = field.velocity(np.column_stack([gx.ravel(), gy.ravel()]))
    speed = np.linalg.norm(V, axis=1).reshape(gx.shape)
    ax.streamplot(
        gx,
        gy,
        V[:, 0].reshape(gx.shape),
        V[:, 1].reshape(gx.shape),
        color=speed,
        cmap="Blues",
        density=1.3,
        linewidth=0.7,
        arrowsize=0.7,
    )

    for i, traj in enumerate(demos.trajectories):
        ax.plot(traj[:, 0], traj[:, 1], color="0.2", lw=1.2, label="demonstrations" if i == 0 else None)
    for i, rep in enumerate(reproduce(field, demos)):
        ax.plot(rep[:, 0], rep[:, 1], color="tab:red", lw=1.2, label="rollouts from demo starts" if i == 0 else None)

    sx, sy = np.meshgrid(np.linspace(lo[0], hi[0], grid_starts), np.linspace(lo[1], hi[1], grid_starts))
    starts = np.column_stack([sx.ravel(), sy.ravel()])
    paths = field.rollout(starts, 100 * field.substeps // 4, substeps=field.substeps // 4 or 1)
    for i, path in enumerate(paths):
        ax.plot(
            path[:, 0],
            path[:, 1],
            color="tab:orange",
            lw=0.7,
            alpha=0.8,
            label="rollouts from a grid of starts" if i == 0 else None,
        )
    ax.plot(starts[:, 0], starts[:, 1], "o", color="tab:orange", ms=2.5)
    ax.plot(*field.goal, marker="*", color="gold", mec="k", ms=16, ls="none", label="goal")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_title(title or "flow field")
    ax.legend(loc="best", fontsize=8)

    lam = field.eigenvalues()
    lam = lam[np.abs(lam) > 0]
    t = np.linspace(0, 2 * np.pi, 400)
    ax_eig.plot(np.cos(t), np.sin(t), color="0.5", lw=1, label="unit circle")
    ax_eig.plot(lam.real, lam.imag, "x", color="tab:blue", label=f"eigenvalues of K (rank {field.rank})")
    ax_eig.set_aspect("equal")
    ax_eig.set_xlim(-1.15, 1.15)
    ax_eig.set_ylim(-1.15, 1.15)
    ax_eig.axhline(0, color="0.85", lw=0.8)
    ax_eig.axvline(0, color="0.85", lw=0.8)
    ax_eig.set_title(f"spectrum of K: rho = {field.spectral_radius():.3f}")
    ax_eig.legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    fig.savefig(output, dpi=110)
    plt.close(fig)


def plot_eigenfunctions(field: FlowField, demos: Demonstrations, output: Path, count: int = 4, title: str = "") -> None:
    """Magnitude (top row) and phase (bottom row) of the ``count`` leading Koopman eigenfunctions (2-D)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lo, hi = convergence_box(demos.bounds, 0.1)
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], 150), np.linspace(lo[1], hi[1], 150))
    lam, phi = field.eigenfunctions(np.column_stack([gx.ravel(), gy.ravel()]), count)
    k = len(lam)
    fig, axes = plt.subplots(2, k, figsize=(3.6 * k, 7), squeeze=False)
    for i in range(k):
        mag = np.abs(phi[:, i]).reshape(gx.shape)
        phase = np.angle(phi[:, i]).reshape(gx.shape)
        for row, (values, cmap, label) in enumerate(((mag, "viridis", "|phi|"), (phase, "twilight", "arg phi"))):
            ax = axes[row, i]
            im = ax.pcolormesh(gx, gy, values, cmap=cmap, shading="auto")
            for traj in demos.trajectories:
                ax.plot(traj[:, 0], traj[:, 1], color="w" if row == 0 else "k", lw=0.7)
            ax.plot(*field.goal, "*", color="gold", mec="k", ms=10)
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
            fig.colorbar(im, ax=ax, fraction=0.046, pad=0.02, label=label)
        axes[0, i].set_title(f"lambda = {lam[i].real:.3f}{lam[i].imag:+.3f}i  (|lambda| {abs(lam[i]):.3f})", fontsize=9)
    fig.suptitle(title or "leading Koopman eigenfunctions: magnitude (top) and phase (bottom)")
    fig.tight_layout()
    fig.savefig(output, dpi=100)
    plt.close(fig)


def plot_field_3d(field: FlowField, demos: Demonstrations, output: Path, title: str = "", grid_starts: int = 3) -> None:
    """A 3-D field: demonstrations, reproductions from their starts and rollouts from a grid of starts."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lo, hi = convergence_box(demos.bounds, 0.1)
    fig = plt.figure(figsize=(9, 8))
    ax = fig.add_subplot(projection="3d")
    for i, traj in enumerate(demos.trajectories):
        ax.plot(*traj.T, color="0.2", lw=1.2, label="demonstrations" if i == 0 else None)
    for i, rep in enumerate(reproduce(field, demos)):
        ax.plot(*rep.T, color="tab:red", lw=1.2, label="rollouts from demo starts" if i == 0 else None)
    axes = [np.linspace(lo[k], hi[k], grid_starts) for k in range(3)]
    starts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    for i, path in enumerate(field.rollout(starts, 100 * field.substeps // 4, substeps=field.substeps // 4 or 1)):
        label = "rollouts from a grid of starts" if i == 0 else None
        ax.plot(*path.T, color="tab:orange", lw=0.6, alpha=0.8, label=label)
    ax.scatter(*field.goal, marker="*", color="gold", edgecolor="k", s=200, label="goal")
    ax.set_title(title or "3-D flow field")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(output, dpi=100)
    plt.close(fig)
