"""``koopguide sitl`` / ``python -m sitl``: flags, bad input, readiness line, recording, clean stop."""

from __future__ import annotations

import json
import signal
import subprocess
import sys

import pytest

from koopguide.base.config import ConfigError
from sitl import config as sitl_config

WALL_LIMIT_S = 60


def run_sitl(*args: str, timeout: float = WALL_LIMIT_S) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "sitl", *args], capture_output=True, text=True, timeout=timeout, check=False
    )


@pytest.mark.parametrize(
    ("yaml_text", "key"),
    [
        ("vessel:\n  hull:\n    mass: 2.0\n", "vessel.hull.mass"),
        ("count: two\n", "count"),
        ("flow:\n  kinds: [tornado]\n", "flow.kinds[0]"),
        ("start_poses: [[1.0, 2.0]]\n", "start_poses[0]"),
        ("vehicle: hovercraft\n", "vehicle"),
        ("count: 2\nvehicles: [rudder]\n", "vehicles"),
        ("autopilot:\n  params:\n    wp_speed_mps: -5\n", "wp_speed_mps"),
        ("autopilot:\n  params:\n    cruise_speed_mps: .nan\n", "cruise_speed_mps"),
        ("vessel:\n  rudder:\n    position_m: 0.2\n", "vessel.rudder.position_m"),
    ],
)
def test_bad_config_keys_fail_with_one_line_naming_the_key(tmp_path, yaml_text, key):
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml_text)
    result = run_sitl("--config", str(bad))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("koopguide: error: "), result.stderr
    assert key in lines[0]


def test_flag_values_are_checked_too():
    result = run_sitl("--flow", "uniform,whirlpool")
    assert result.returncode == 2 and "flow.kinds[1]" in result.stderr
    result = run_sitl("--mavlink", "serial:/dev/ttyUSB0")
    assert result.returncode == 2 and "serial:/dev/ttyUSB0" in result.stderr
    result = run_sitl("--speedup", "-3")
    assert result.returncode == 2 and "--speedup" in result.stderr
    result = run_sitl("--vehicle", "rudder,hovercraft", "--count", "2")
    assert result.returncode == 2 and "vehicles[1]" in result.stderr and "hovercraft" in result.stderr


def test_one_vehicle_kind_per_boat(tmp_path):
    record = tmp_path / "truth.jsonl"
    args = ("--mavlink", "udpin:127.0.0.1:0", "--speedup", "max", "--duration", "2", "--count", "3")
    result = run_sitl(*args, "--vehicle", "rudder,vectored,diff_thrust", "--record", str(record))
    assert result.returncode == 0, result.stderr
    states = [r for r in map(json.loads, record.read_text().splitlines()) if r["kind"] == "state"]
    kinds = {r["sysid"]: (r["vehicle"], len(r["thrust"]), len(r["command"])) for r in states}
    assert kinds == {1: ("rudder", 1, 2), 2: ("vectored", 4, 4), 3: ("diff_thrust", 2, 2)}
    result = run_sitl(*args[:-2], "--vehicle", "vectored", "--record", str(record))
    assert result.returncode == 0, result.stderr
    states = [r for r in map(json.loads, record.read_text().splitlines()) if r["kind"] == "state"]
    assert {r["vehicle"] for r in states} == {"vectored"}


def test_semantic_checks_name_the_key():
    with pytest.raises(ConfigError, match="start_poses"):
        sitl_config.load(overrides={"count": 2, "start_poses": [[1.0, 1.0, 0.0]]})
    with pytest.raises(ConfigError, match="physics_rate_hz"):
        sitl_config.load(overrides={"physics_rate_hz": 50.0})


def test_runs_records_ground_truth_and_reports(tmp_path):
    record = tmp_path / "truth.jsonl"
    result = run_sitl(
        "--mavlink",
        "tcpin:127.0.0.1:0",
        "--speedup",
        "max",
        "--duration",
        "5",
        "--count",
        "2",
        "--flow",
        "uniform,gusts",
        "--record",
        str(record),
    )
    assert result.returncode == 0, result.stderr
    out = result.stdout.splitlines()
    assert out[0].startswith("sitl: boat 1 mavlink tcpin:127.0.0.1:") and not out[0].endswith(":0")
    assert out[1].startswith("sitl: boat 2 mavlink tcpin:127.0.0.1:")
    assert out[2] == "sitl: ready"
    assert any("stopped at t = 5.00 s simulated" in line for line in out)
    rows = [json.loads(line) for line in record.read_text().splitlines()]
    states = [r for r in rows if r["kind"] == "state"]
    assert {r["sysid"] for r in states} == {1, 2}
    assert max(r["t"] for r in states) == pytest.approx(5.0)
    last = states[-1]
    assert last["mode"] == "MANUAL" and last["armed"] is False
    # no thrust: the boats drift with the water, whose speed the record carries
    assert math_isclose(last["vn"], last["flow"][0]) and math_isclose(last["ve"], last["flow"][1])


def math_isclose(a: float, b: float) -> bool:
    return abs(a - b) < 0.01


def test_sigterm_stops_cleanly():
    proc = subprocess.Popen(
        [sys.executable, "-m", "sitl", "--mavlink", "udpin:127.0.0.1:0", "--quiet"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        lines = []
        while not lines or lines[-1] != "sitl: ready":
            line = proc.stdout.readline()
            assert line, f"exited early: {proc.stderr.read() if proc.stderr else ''}"
            lines.append(line.strip())
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=WALL_LIMIT_S)
        assert proc.returncode == 0, err
        assert "stopped at t =" in out
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_koopguide_sitl_help_lists_the_contract_flags():
    result = subprocess.run(
        [sys.executable, "-m", "koopguide", "sitl", "--help"],
        capture_output=True,
        text=True,
        timeout=WALL_LIMIT_S,
        check=False,
    )
    assert result.returncode == 0
    for flag in ("--config", "--mavlink", "--speedup", "--flow", "--count", "--vehicle"):
        assert flag in result.stdout
