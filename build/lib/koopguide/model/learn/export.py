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


def save(path: Path, trained: trainer.TrainedField, demos: data.Demonstrations, cfg: trainer.TrainConfig) -> None:
    """Write ``trained`` with everything a reader needs: goal, bounds, settings, data digest, figures."""
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
    modelfile.write(path, {"W": trained.W, "b": trained.b, "A": trained.A, "B": trained.B}, meta)


def train_to_file(demos: data.Demonstrations, path: Path, seed: int = 0, cfg: trainer.TrainConfig | None = None,
                  progress: Callable[[int, int, dict[str, float]], None] | None = None) -> trainer.TrainedField:
    """Train on ``demos`` (default settings unless ``cfg``) and write the model to ``path``."""
    cfg = training_config(None) if cfg is None else cfg
    trained = trainer.train(demos, cfg, seed, progress=progress)
    save(path, trained, demos, cfg)
    return trained
