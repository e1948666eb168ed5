"""Two guidance services steer two simulated skid-steer boats through encounters where each boat's slot lies
beyond the other boat (koopguide.harness.fleet_encounters): they keep min_separation_m on the simulator's
ground-truth record and both reach their slots. The whole family (every encounter x vehicle x current) is
``koopguide bench separation``; its figures are in docs/fleet.md."""

from __future__ import annotations

from pathlib import Path

import pytest

from koopguide.base import data
from koopguide.guidance import settings
from koopguide.harness import fleet_encounters as fe
from koopguide.model.learn.export import train_to_file


@pytest.fixture(scope="module")
def line_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The LASA Line shape trained with the shipped defaults: a straight course into each slot."""
    path = tmp_path_factory.mktemp("models") / "line.pt"
    train_to_file(data.load_lasa(fe.SHAPE), path, seed=0)
    return path


@pytest.mark.timeout(150)
@pytest.mark.parametrize(
    ("encounter", "current_mps"),
    [
        pytest.param("crossing_120", 0.0, id="crossing-calm"),
        pytest.param("head_on", fe.CURRENT_MPS, id="head-on-current"),
    ],
)
def test_boats_keep_their_separation_and_reach_their_slots(line_model: Path, encounter: str, current_mps: float):
    r = fe.fly(fe.ENCOUNTERS[encounter], line_model, "diff_thrust", current_mps)
    print(r)
    assert r.min_separation_m >= settings.load().fleet.min_separation_m, r  # never closer (ground truth)
    assert r.filter_seen, r  # the courses met: the filter had to act
    assert all(t is not None for t in r.arrival_s), r  # both arrived...
    assert max(r.slot_errors_m) <= fe.SLOT_RADIUS_M, r  # ... and are at their slots at the end
