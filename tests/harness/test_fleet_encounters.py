"""Two guidance services steer two simulated skid-steer boats through encounters where each boat's slot lies
beyond the other boat (koopguide.harness.fleet_encounters): they keep min_separation_m on the simulator's
ground-truth record and both reach their slots. The whole family (every encounter x vehicle x current) is
``koopguide bench separation``; its figures are in docs/fleet.md."""

from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest

from koopguide.base import data
from koopguide.guidance import settings
from koopguide.harness import fleet_encounters as fe
from koopguide.model.learn.export import train_to_file

pytestmark = pytest.mark.flight  # closed-loop flights: `make test` runs them on two workers (pyproject.toml)


@pytest.fixture(scope="module")
def line_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The LASA Line shape trained with the shipped defaults: a straight course into each slot."""
    path = tmp_path_factory.mktemp("models") / "line.pt"
    train_to_file(data.load_lasa(fe.SHAPE), path, seed=0)
    return path


# Two services and the simulator share one interpreter (one GIL). In the test process, after hundreds of other
# tests, they were starved for 0.35 s of wall clock at a time ("no fresh position for 1.4 s" at x4): 0.4 m of
# travel at 0.3 m/s with stale setpoints, which no filter on the setpoint can answer for. A fresh interpreter and
# x2 keep starvation out of the figures (a service really runs at x1: the same stall is 0.1 m there). A run that
# still fell behind its pace is flown again slower (fleet_encounters.fly), hence the timeouts: x2, x1, x0.5.
SPEEDUP = 2.0


def fly(name: str, model: Path, current_mps: float = 0.0, guidance: dict | None = None) -> fe.EncounterResult:
    """One encounter of diff_thrust boats, flown in a fresh interpreter (``guidance``: config overrides)."""
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        job = pool.submit(
            fe.fly, fe.ENCOUNTERS[name], model, "diff_thrust", current_mps, speedup=SPEEDUP, guidance=guidance
        )
        return job.result()


@pytest.mark.timeout(420)
def test_boats_crossing_keep_their_separation_and_reach_their_slots(line_model: Path):
    r = fly("crossing_120", line_model)
    print(r)
    assert r.min_separation_m >= settings.load().fleet.min_separation_m, r  # never closer (ground truth)
    assert r.filter_seen, r  # the courses met: the filter had to act
    assert all(t is not None for t in r.arrival_s), r  # both arrived...
    assert max(r.slot_errors_m) <= fe.SLOT_RADIUS_M, r  # ... and are at their slots at the end


@pytest.mark.timeout(420)
def test_boats_head_on_in_a_current_keep_their_separation(line_model: Path):
    r = fly("head_on", line_model, fe.CURRENT_MPS)
    print(r)
    assert r.min_separation_m >= settings.load().fleet.min_separation_m, r  # never closer (ground truth)
    assert r.filter_seen, r
    if not (all(t is not None for t in r.arrival_s) and max(r.slot_errors_m) <= fe.SLOT_RADIUS_M):
        pytest.xfail(
            f"known (docs/fleet.md): in a current a boat ends off its slot in some runs, {r.slot_errors_m} m "
            "(near the slots each boat answers the other's station-keeping velocity)"
        )


@pytest.mark.timeout(420)
def test_boats_held_beside_each_other_across_a_current_keep_their_separation(line_model: Path):
    """Head-on in the current with the stall watchdog at 3 s: both boats, held by the filter short of each other,
    go to direct pursuit beside each other, one with its bow across the current. Rover holds speed over ground
    along the bow only, so that boat drifts onto the other whatever speed >= 0 it is sent: 6 of 6 runs came
    closer than 0.4 m (0.15-0.39 m) until the filter sent it along its heading the other way (stop 46)."""
    r = fly("head_on", line_model, fe.CURRENT_MPS, {"failsafe": {"stall_s": 3.0}})
    print(r)
    assert r.min_separation_m >= settings.load().fleet.min_separation_m, r  # never closer (ground truth)
    assert r.filter_seen, r
    assert all(t is not None for t in r.arrival_s), r  # and no deadlock: both arrive...
    assert max(r.slot_errors_m) <= fe.SLOT_RADIUS_M, r  # ... and are at their slots at the end


@pytest.mark.timeout(420)
def test_a_boat_goes_round_a_boat_parked_on_its_course_and_both_reach_their_slots(line_model: Path):
    """Overtaking: the slower boat reaches its slot first and parks on the other's course; a barrier filter alone
    deadlocks behind it (the faster boat crept 0.005 m/s for a minute and never arrived): it goes round."""
    r = fly("overtaking", line_model)
    print(r)
    assert r.min_separation_m >= settings.load().fleet.min_separation_m, r  # never closer (ground truth)
    assert r.filter_seen, r
    assert all(t is not None for t in r.arrival_s), r
    assert max(r.slot_errors_m) <= fe.SLOT_RADIUS_M, r
    assert r.arrival_s[0] < 90.0, r  # round it, not a minute's creep and a direct-pursuit fallback
