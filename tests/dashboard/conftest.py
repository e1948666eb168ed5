"""Fixtures for the dashboard and mission-log tests: a Zshape model trained with the shipped defaults."""

from __future__ import annotations

from pathlib import Path

import pytest

from koopguide import cli


@pytest.fixture(scope="session")
def zshape_default_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The shipped training defaults (about 10 s): every Zshape start converges to the goal."""
    path = tmp_path_factory.mktemp("models") / "zshape.pt"
    assert cli.main(["train", "--lasa", "Zshape", "-o", str(path), "--seed", "0", "--quiet"]) == 0
    return path
