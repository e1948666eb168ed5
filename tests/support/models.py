"""Training settings for fast tests of the learning code (real data, real training, a smaller budget)."""

from __future__ import annotations

from koopguide.base import config
from koopguide.model.learn import trainer


def small_config(**overrides) -> trainer.TrainConfig:
    """The shipped defaults with a short budget and a smaller lifting, for fast tests."""
    base = {"model": {"nu": 256, "rank": 16}, "optim": {"steps": 400}}
    return config.build(trainer.TrainConfig, config.load_layers("train", None, config.merge(base, overrides)))
