"""From demonstrations to a model file through the trainer's API (used by the CLI and the harness).

:func:`training_config` builds the typed training configuration once (shipped defaults, a user file,
overrides); :func:`save` writes a trained model with its metadata; :func:`train_to_file` does both.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from koopguide.base import config, data, modelfile
from koopguide.model.learn import trainer


def training_config(user_file: Path | None, overrides: dict[str, Any] | None = None) -> trainer.TrainConfig:
    """``defaults/train.yaml``, then ``user_file``, then ``overrides``, as a checked TrainConfig."""
    return config.build(trainer.TrainConfig, config.load_layers("train", user_file, overrides or {}))


class UncertifiedModelError(ValueError):
    """A trained model failed (or skipped) its convergence certificate and was not written."""


def save(path: Path, trained: trainer.TrainedField, demos: data.Demonstrations, cfg: trainer.TrainConfig) -> None:
    """Write ``trained`` with everything a reader needs: goal, bounds, settings, data digest, figures, its
    Lyapunov limit and its convergence certificate."""
    lo, hi = demos.bounds
    meta = {
        "dim": demos.dim,
        "goal": trained.goal.tolist(),
        "substeps": trained.substeps,
        "goal_centred": trained.goal_centred,
        "nu": int(trained.W.shape[0]),
        "rank": int(trained.A.shape[1]),
        "bounds_lo": lo.tolist(),
        "bounds_hi": hi.tolist(),
        "hyperparameters": config.to_plain(cfg),
        "data": demos.summary(),
        "train": trained.info,
        "created_unix": time.time(),
    }
    weights = {"W": trained.W, "b": trained.b, "A": trained.A, "B": trained.B}
    if trained.limit is not None:
        weights["limit_table"] = trained.limit.table
        meta["limit"] = {
            "lo": trained.limit.lo.tolist(),
            "hi": trained.limit.hi.tolist(),
            "outside": trained.limit.outside,
        }
    if trained.certificate is not None:
        meta["certificate"] = trained.certificate
    modelfile.write(path, weights, meta)


def train_to_file(
    demos: data.Demonstrations,
    path: Path,
    seed: int = 0,
    cfg: trainer.TrainConfig | None = None,
    progress: Callable[[int, int, dict[str, float]], None] | None = None,
) -> trainer.TrainedField:
    """Train on ``demos`` (default settings unless ``cfg``) and write the model to ``path``."""
    cfg = training_config(None) if cfg is None else cfg
    trained = trainer.train(demos, cfg, seed, progress=progress)
    save(path, trained, demos, cfg)
    return trained
