"""Fixtures for the guidance tests: one real Zshape model trained with the shipped defaults."""

from __future__ import annotations

from pathlib import Path

import pytest

from koopguide.base import data
from koopguide.model.learn.export import train_to_file


@pytest.fixture(scope="session")
def zshape_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("models") / "zshape.pt"
    train_to_file(data.load_lasa("Zshape"), path, seed=0)
    assert path.stat().st_size > 0
    return path
