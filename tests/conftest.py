"""Fixtures shared by every test folder: real LASA data and real trained models (no stand-ins)."""

from __future__ import annotations

from pathlib import Path

import pytest

from koopguide.base import data
from koopguide.model.learn import trainer
from koopguide.model.learn.export import train_to_file
from tests.support.models import small_config


@pytest.fixture(scope="session")
def zshape() -> data.Demonstrations:
    return data.load_lasa("Zshape")


@pytest.fixture(scope="session")
def small_trained(zshape: data.Demonstrations) -> trainer.TrainedField:
    """A quick Zshape fit (a shorter budget, a smaller lifting): for tests of the learning code itself."""
    return trainer.train(zshape, small_config(), seed=0)


@pytest.fixture(scope="session")
def zshape_model(tmp_path_factory: pytest.TempPathFactory, zshape: data.Demonstrations) -> Path:
    """Zshape trained with the shipped defaults, seed 0, as a model file: what `koopguide demo` flies."""
    path = tmp_path_factory.mktemp("models") / "zshape.pt"
    train_to_file(zshape, path, seed=0)
    assert path.stat().st_size > 0
    return path
