"""Shared fixtures for the learning-core tests: small, fast, real (real LASA data, real training)."""

from __future__ import annotations

import pytest

from koopguide.base import config, data
from koopguide.model.learn import trainer


def small_config(**overrides) -> trainer.TrainConfig:
    """The shipped defaults with a short budget and a smaller lifting, for fast tests."""
    base = {"model": {"nu": 256, "rank": 16}, "optim": {"steps": 400}}
    return config.build(trainer.TrainConfig, config.load_layers("train", None, config.merge(base, overrides)))


@pytest.fixture(scope="session")
def zshape() -> data.Demonstrations:
    return data.load_lasa("Zshape")


@pytest.fixture(scope="session")
def small_trained(zshape) -> trainer.TrainedField:
    return trainer.train(zshape, small_config(), seed=0)
