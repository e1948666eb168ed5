"""Fixtures for the guidance tests: one real Zshape model trained with the shipped defaults."""

from __future__ import annotations

from pathlib import Path

import pytest

from koopguide import cli


@pytest.fixture(scope="session")
def zshape_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("models") / "zshape.pt"
    assert cli.main(["train", "--lasa", "Zshape", "-o", str(path), "--seed", "0", "--quiet"]) == 0
    return path
