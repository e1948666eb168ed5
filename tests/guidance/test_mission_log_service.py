"""``koopguide run --log``: the service's own mission log, from a mission flown against the real simulator
(speed-up 10), read back with the mcap reader and ``read_mission``, and rendered with ``koopguide replay``.
Conventions: local NED [m], [m/s]; vehicle seconds."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from PIL import Image

from koopguide import cli
from koopguide.bus.missionlog import SCHEMAS, read_mission
from koopguide.harness import mission


@pytest.fixture(scope="module")
def logged(tmp_path_factory: pytest.TempPathFactory, zshape_model: Path):
    """One mission from Zshape's first start in a 0.02 m/s current, logged; (cfg, result, log path)."""
    path = tmp_path_factory.mktemp("log") / "mission.mcap"
    cfg, sim_cfg, _pose = mission.demo_mission(zshape_model, 0, 0.02, 10.0, vehicle_id="boat8")
    result = asyncio.run(mission.fly_paced(cfg, zshape_model, sim_cfg, 120.0, settle_s=3.0, log_path=path))
    assert result.arrived
    return cfg, result, path


@pytest.mark.timeout(180)
def test_the_log_reopens_with_the_mcap_reader_with_a_json_schema_per_topic(logged) -> None:
    _cfg, _result, path = logged
    with path.open("rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
        schemas = {summary.channels[c].topic: summary.schemas[summary.channels[c].schema_id] for c in summary.channels}
    assert set(schemas) == set(SCHEMAS)
    for topic, schema in schemas.items():
        assert schema.encoding == "jsonschema" and json.loads(schema.data) == SCHEMAS[topic]
    assert counts["/field"] == 1  # once, when the goal was placed
    assert all(counts[topic] > 0 for topic in SCHEMAS), counts


@pytest.mark.timeout(180)
def test_the_log_holds_every_fix_setpoint_state_change_and_status_of_the_mission(logged) -> None:
    cfg, result, path = logged
    record = read_mission(path)
    assert record.metadata["vehicle_id"] == "boat8"
    assert float(record.metadata["arrival_radius_m"]) == cfg.arrival.radius_m
    fixes, estimates, setpoints = record.fixes, record.estimates, record.setpoints
    span = fixes[-1, 0] - fixes[0, 0]
    assert span > 10.0 and len(fixes) >= 0.8 * span * cfg.mavlink.position_rate_hz  # every accepted fix
    assert len(estimates) == len(fixes) and np.all(np.diff(fixes[:, 0]) > 0)
    # the estimate follows the fixes (centimetres), and the current's estimate appears along the way
    assert float(np.max(np.hypot(*(estimates[:, 1:3] - fixes[:, 1:3]).T))) < 0.05
    assert np.isfinite(estimates[-1, 5:7]).all()
    # each setpoint sent: at the command rate, never above the speed limit, the largest one as the service saw
    speeds = np.hypot(setpoints[:, 1], setpoints[:, 2])
    t_guiding = next(t for t, s in result.transitions if s == "guiding")
    t_arrived = next(t for t, s in result.transitions if s == "arrived")
    guiding = setpoints[(setpoints[:, 0] >= t_guiding) & (setpoints[:, 0] < t_arrived)]
    assert len(guiding) >= 0.8 * (t_arrived - t_guiding) * cfg.command.rate_hz  # the command rate while guiding
    assert float(speeds.max()) == pytest.approx(result.max_setpoint_mps, abs=1e-9)
    assert float(speeds.max()) <= cfg.command.max_speed_mps + 1e-9
    # state changes: exactly the service's transitions, with the latest reason
    assert [(t, s) for t, s, _ in record.states] == [(pytest.approx(t), s) for t, s in result.transitions]
    assert "arrived" in [s for _, s, _ in record.states] and all(reason for _, _, reason in record.states)
    # statuses at status.rate_hz (wall) with growing seq; the last one at the goal
    seqs = [s["seq"] for s in record.statuses]
    assert len(seqs) >= 10 and seqs == sorted(set(seqs))
    assert record.statuses[-1]["distance_to_goal_m"] <= cfg.arrival.reacquire_radius_m
    assert record.field_grid is not None and record.field_grid["n"] == 30
    # the boat ended at the goal in the log as in the simulator's ground truth
    assert float(np.hypot(*estimates[-1, 1:3])) <= cfg.arrival.reacquire_radius_m


@pytest.mark.timeout(180)
def test_koopguide_replay_renders_the_services_log(logged, tmp_path: Path, capsys) -> None:
    _cfg, _result, path = logged
    gif = tmp_path / "mission.gif"
    assert cli.main(["replay", str(path), "-o", str(gif), "--speed", "10"]) == 0
    frames = int(capsys.readouterr().out.rsplit("(", 1)[1].split()[0])
    with Image.open(gif) as image:
        assert frames > 1 and image.n_frames == frames


def test_a_log_path_that_is_not_mcap_is_refused_before_anything_opens(zshape_model: Path, tmp_path: Path, capsys):
    code = cli.main(["run", "--model", str(zshape_model), "--log", str(tmp_path / "mission.txt")])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--log must name a .mcap file" in err and "mission.txt" in err
