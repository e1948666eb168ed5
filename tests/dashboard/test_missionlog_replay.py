"""The mission log (MCAP) and ``koopguide replay``: a mission flown by the real guidance law on a real
trained field, with a kinematic boat in a current, logged with MissionLog, read back with the mcap
reader, and rendered as an animated GIF."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from PIL import Image, ImageChops

from koopguide import cli
from koopguide.base import data
from koopguide.bus.missionlog import SCHEMAS, MissionLog, MissionLogError, read_mission
from koopguide.dashboard.replay import frame_times
from koopguide.guidance import settings
from koopguide.guidance.law.command import GuidanceLaw
from koopguide.model.field import load_field
from tests.support.status_samples import sample_status

DT = 0.1  # command period [s]
CURRENT = np.array([0.0, 0.02])  # toward the east [m/s]


@pytest.fixture(scope="module")
def mission(tmp_path_factory: pytest.TempPathFactory, zshape_model: Path) -> dict:
    """Fly from Zshape's first demonstration start for up to 60 s (or until 5 s after arrival) and log
    everything; returns what was logged."""
    folder = tmp_path_factory.mktemp("mission")
    model = zshape_model
    cfg = settings.load(None, {"vehicle_id": "boat9"})
    law = GuidanceLaw.from_config(load_field(model), cfg)
    rng = np.random.default_rng(0)
    p = law.frame.to_ned(data.load_lasa("Zshape").trajectories[0][0])
    v = np.zeros(2)
    logged = {"fix": [], "setpoint": [], "state": []}
    path = folder / "mission.mcap"
    state, arrived, t_arrived = None, False, None
    with MissionLog.create(path, "boat9", model, arrival_radius_m=cfg.arrival.radius_m) as log:
        log.log_field(law.sample_grid(20))
        for k in range(600):
            t = k * DT
            fix = p + rng.normal(0, 0.003, 2)
            log.log_fix(t, fix, v)
            log.log_estimate(t, p, v, CURRENT)
            logged["fix"].append([t, *fix, *v])
            setpoint = law.decide(p, arrived, math.atan2(v[1], v[0]) if np.hypot(*v) > 0 else None, CURRENT)
            arrived = arrived or setpoint.state.value == "arrived"
            log.log_setpoint(t, setpoint.velocity_ned, None)
            logged["setpoint"].append([t, *setpoint.velocity_ned])
            if setpoint.state.value != state:
                state = setpoint.state.value
                log.log_state(t, state, setpoint.reason)
                logged["state"].append((t, state))
            if k % 2 == 0:
                log.log_status(
                    sample_status(
                        "boat9", seq=k // 2 + 1, state=state, position_ned=p.tolist(), goal_ned=law.goal_ned.tolist()
                    )
                )
            v = setpoint.velocity_ned + CURRENT  # the boat makes good its setpoint through the water
            p = p + DT * v
            if arrived and t_arrived is None:
                t_arrived = t
            if t_arrived is not None and t - t_arrived >= 5.0:
                break
        count = log.messages
    return {
        "path": path,
        "logged": logged,
        "final": law.distance_to_goal(p),
        "messages": count,
        "radius": cfg.arrival.radius_m,
    }


def test_the_logged_mission_arrives_and_reopens_with_the_mcap_reader(mission: dict) -> None:
    assert mission["final"] <= mission["radius"]  # the law brought the boat in against the current
    with mission["path"].open("rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        channels = {c.topic: c for c in summary.channels.values()}
        assert set(channels) == set(SCHEMAS)
        for channel in channels.values():
            schema = summary.schemas[channel.schema_id]
            assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
            assert "required" in json.loads(schema.data)
        counts = {channels_topic: 0 for channels_topic in SCHEMAS}
        for _schema, channel, message in reader.iter_messages():
            counts[channel.topic] += 1
            json.loads(message.data)
    logged = mission["logged"]
    assert counts["/fix"] == counts["/estimate"] == counts["/setpoint"] == len(logged["fix"])
    assert counts["/state"] == len(logged["state"]) and counts["/field"] == 1
    assert sum(counts.values()) == mission["messages"]


def test_read_mission_gives_back_what_was_logged(mission: dict) -> None:
    record = read_mission(mission["path"])
    logged = mission["logged"]
    assert record.metadata["vehicle_id"] == "boat9" and float(record.metadata["arrival_radius_m"]) == 0.15
    assert np.allclose(record.fixes, logged["fix"])
    assert np.allclose(record.setpoints, logged["setpoint"])
    assert np.allclose(record.estimates[:, 5:7], CURRENT)
    assert [(t, s) for t, s, _ in record.states] == logged["state"]
    assert [s for _, s in logged["state"]][-2:] == ["guiding", "arrived"]
    assert record.field_grid["n"] == 20 and len(record.field_grid["velocity_ned"]) == 400
    assert all(s["vehicle_id"] == "boat9" for s in record.statuses) and len(record.statuses) >= 10


def test_replay_renders_an_animated_gif_of_the_mission(mission: dict, tmp_path: Path, capsys) -> None:
    gif = tmp_path / "mission.gif"
    assert cli.main(["replay", str(mission["path"]), "-o", str(gif), "--fps", "10", "--speed", "20"]) == 0
    expected = len(frame_times(read_mission(mission["path"]), 10, 20.0))
    assert f"({expected} frames)" in capsys.readouterr().out
    with Image.open(gif) as image:
        assert image.format == "GIF" and image.n_frames == expected and expected >= 5
        image.seek(0)
        first = image.convert("RGB")
        image.seek(image.n_frames - 1)
        last = image.convert("RGB")
    assert ImageChops.difference(first, last).getbbox() is not None  # the boat moved between them


def test_bad_logs_and_bad_flags_are_one_line_errors(mission: dict, tmp_path: Path, capsys) -> None:
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all" * 10)
    truncated = tmp_path / "truncated.mcap"
    truncated.write_bytes(mission["path"].read_bytes()[:200])
    for path in (junk, truncated):
        with pytest.raises(MissionLogError, match="not a readable MCAP mission log"):
            read_mission(path)
    cases = [
        (["replay", str(junk), "-o", str(tmp_path / "a.gif")], "not a readable MCAP mission log"),
        (["replay", str(tmp_path / "none.mcap"), "-o", str(tmp_path / "a.gif")], "mission log not found"),
        (["replay", str(mission["path"]), "-o", str(tmp_path / "a.png")], "-o must name a .gif file"),
        (["replay", str(mission["path"]), "-o", str(tmp_path / "a.gif"), "--fps", "0"], "--fps must be 1 .. 50"),
    ]
    for argv, message in cases:
        assert cli.main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("koopguide: error:") and message in err and "\n" not in err
    with MissionLog.create(tmp_path / "nan.mcap", "boat9", "m.pt") as log:
        with pytest.raises(ValueError, match="mission log /fix: Out of range float"):
            log.log_fix(1.0, [math.nan, 0.0], [0.0, 0.0])
        with pytest.raises(ValueError, match="state must be one of"):
            log.log_state(1.0, "flying")
    empty = read_mission(tmp_path / "nan.mcap")
    assert len(empty.fixes) == 0
    with pytest.raises(MissionLogError, match="nothing to replay"):
        frame_times(empty, 10, 5.0)
