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
def test_boats_crossing_keep_their_separation_and_reach_their_slots(line_model: Path):
    r = fe.fly(fe.ENCOUNTERS["crossing_120"], line_model, "diff_thrust", 0.0)
    print(r)
    assert r.min_separation_m >= settings.load().fleet.min_separation_m, r  # never closer (ground truth)
    assert r.filter_seen, r  # the courses met: the filter had to act
    assert all(t is not None for t in r.arrival_s), r  # both arrived...
    assert max(r.slot_errors_m) <= fe.SLOT_RADIUS_M, r  # ... and are at their slots at the end


@pytest.mark.timeout(150)
def test_boats_head_on_in_a_current_keep_their_separation(line_model: Path):
    r = fe.fly(fe.ENCOUNTERS["head_on"], line_model, "diff_thrust", fe.CURRENT_MPS)
    print(r)
    assert r.min_separation_m >= settings.load().fleet.min_separation_m, r  # never closer (ground truth)
    assert r.filter_seen, r
    if not (all(t is not None for t in r.arrival_s) and max(r.slot_errors_m) <= fe.SLOT_RADIUS_M):
        pytest.xfail(
            f"known (docs/fleet.md): in a current a boat ends off its slot in some runs, {r.slot_errors_m} m "
            "(near the slots each boat answers the other's station-keeping velocity)"
        )
