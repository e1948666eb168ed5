"""A recorded mission animated over its field (``koopguide replay FILE.mcap -o mission.gif``).

Reads a :mod:`koopguide.bus.missionlog` file and draws, frame by frame in vehicle time: the field's
streamlines (from the logged ``/field`` grid), the goal and arrival radius, the boat's estimated
track so far (its fixes when no estimates were logged), the boat itself along its course, the
setpoint and estimated current as arrows, and the service's state. Written with matplotlib's
PillowWriter. Conventions: local NED metres, North up and East right; vehicle seconds.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from koopguide.bus.missionlog import MissionLogError, MissionRecord

#: An arrow is this many seconds of travel long.
ARROW_S = 10.0
#: At most this many frames, whatever the mission's length (the step grows instead).
MAX_FRAMES = 300


def frame_times(record: MissionRecord, fps: int, speed: float, max_frames: int = MAX_FRAMES) -> np.ndarray:
    """Vehicle times [s] of the frames: ``speed / fps`` apart, at most ``max_frames``."""
    times = np.concatenate([record.fixes[:, 0], record.estimates[:, 0]])
    if times.size == 0:
        raise MissionLogError("nothing to replay: the log has no /fix or /estimate messages")
    t0, t1 = float(times.min()), float(times.max())
    step = max(speed / fps, (t1 - t0) / max(max_frames - 1, 1))
    return t0 + step * np.arange(int((t1 - t0) / step) + 1) if t1 > t0 else np.array([t0])


def render_replay(record: MissionRecord, out: Path, fps: int = 10, speed: float = 5.0) -> int:
    """Write the animation to ``out``; returns the number of frames."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    from koopguide.bus.streamlines import FieldGrid, streamlines

    times = frame_times(record, fps, speed)
    track = record.estimates[:, :3] if len(record.estimates) else record.fixes[:, :3]  # t, N, E
    fig, ax = plt.subplots(figsize=(6.4, 6.0), dpi=80)
    points = [track[:, 1:3]]
    goal = None
    if record.field_grid is not None:
        grid = FieldGrid.from_reply(record.field_grid)
        for line in streamlines(grid):
            ax.plot(line[:, 1], line[:, 0], color="0.75", lw=0.8, zorder=1)
        points.append(grid.corners_ned)
        goal = grid.goal_ned
    if goal is None:
        goals = [s["goal_ned"] for s in record.statuses if s.get("goal_ned") is not None]
        goal = np.asarray(goals[-1]) if goals else None
    if goal is not None:
        ax.plot(goal[1], goal[0], "kx", ms=10, mew=2, zorder=3)
        radius = _float_or_none(record.metadata.get("arrival_radius_m"))
        if radius:
            ax.add_patch(plt.Circle((goal[1], goal[0]), radius, fill=False, ls="--", color="k", zorder=3))
        points.append(goal[None])
    box = np.vstack(points)
    pad = 0.1 * max(float(np.ptp(box[:, 0])), float(np.ptp(box[:, 1])), 0.5)
    ax.set_xlim(box[:, 1].min() - pad, box[:, 1].max() + pad)
    ax.set_ylim(box[:, 0].min() - pad, box[:, 0].max() + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("East [m]")
    ax.set_ylabel("North [m]")
    (trail,) = ax.plot([], [], color="tab:red", lw=1.5, zorder=4)
    (boat,) = ax.plot([], [], marker=(3, 0, 0), ms=12, color="tab:red", mec="k", ls="none", zorder=5)
    setpoint = ax.quiver(
        [0], [0], [0], [0], color="tab:red", angles="xy", scale_units="xy", scale=1 / ARROW_S, width=0.006, zorder=6
    )
    current = ax.quiver(
        [0], [0], [0], [0], color="tab:blue", angles="xy", scale_units="xy", scale=1 / ARROW_S, width=0.006, zorder=6
    )
    title = ax.set_title("")
    vehicle = record.metadata.get("vehicle_id", "vehicle")

    def draw(k: int) -> None:
        t = times[k]
        upto = track[track[:, 0] <= t]
        if len(upto) == 0:
            upto = track[:1]
        trail.set_data(upto[:, 2], upto[:, 1])
        n, e = upto[-1, 1], upto[-1, 2]
        course = _course(record, t)
        boat.set_data([e], [n])
        boat.set_marker((3, 0, -math.degrees(course)))  # a triangle pointing along the course (0: north)
        sp = _latest(record.setpoints, t)
        setpoint.set_offsets([[e, n]])
        setpoint.set_UVC([0.0 if sp is None else sp[2]], [0.0 if sp is None else sp[1]])
        est = _latest(record.estimates, t)
        c = (0.0, 0.0) if est is None or not np.isfinite(est[5:7]).all() else (est[5], est[6])
        current.set_offsets([[e, n]])
        current.set_UVC([c[1]], [c[0]])
        state = [s for s in record.states if s[0] <= t]
        title.set_text(f"{vehicle}  t = {t:6.1f} s  {state[-1][1] if state else ''}")

    animation = FuncAnimation(fig, draw, frames=len(times), blit=False)
    try:
        animation.save(out, writer=PillowWriter(fps=fps))
    finally:
        plt.close(fig)
    return len(times)


def _latest(rows: np.ndarray, t: float) -> np.ndarray | None:
    """The last row logged at or before vehicle time ``t`` (rows start with t)."""
    k = int(np.searchsorted(rows[:, 0], t, side="right")) - 1 if len(rows) else -1
    return rows[k] if k >= 0 else None


def _course(record: MissionRecord, t: float) -> float:
    """Course over ground [rad from north] at ``t``: the velocity's direction, else the setpoint's."""
    for rows, columns in ((record.estimates, (3, 4)), (record.fixes, (3, 4)), (record.setpoints, (1, 2))):
        row = _latest(rows, t)
        if row is not None and math.hypot(row[columns[0]], row[columns[1]]) > 0.01:
            return math.atan2(row[columns[1]], row[columns[0]])
    return 0.0


def _float_or_none(text: str | None) -> float | None:
    try:
        value = float(text) if text is not None else None
    except ValueError:
        return None
    return value if value is not None and math.isfinite(value) and value > 0 else None
