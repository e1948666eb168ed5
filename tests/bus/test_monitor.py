"""``koopguide monitor``, its table and the example subscriber, against real StatusBus publishers.

Publishers run in this process (a StatusBus on its own event-loop thread); the monitor and the
example run as subprocesses with a ``--zenoh-config`` file: the shipped default moved to a free port.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import zenoh

from koopguide.bus.monitor import PUBLISHER_HANDOVER_S, Monitor, MonitorState, VehicleView, render_table
from koopguide.bus.status import encode_status
from koopguide.bus.zenoh_config import (
    ACL_CLIENT_CONFIG_FILE,
    ACL_ROUTER_CONFIG_FILE,
    DEFAULT_ZENOH_CONFIG_FILE,
    WELL_KNOWN_PORT,
    default_zenoh_config,
)
from tests.support.status_samples import free_port, publishing, sample_status, wait_for

REPO = Path(__file__).resolve().parents[2]
MONITOR = [sys.executable, "-m", "koopguide", "monitor"]


# ---------------------------------------------------------------------------------- helpers
def config_file(tmp_path: Path, port: int) -> Path:
    """The shipped default configuration file, rendezvous moved to ``port``."""
    text = DEFAULT_ZENOH_CONFIG_FILE.read_text()
    assert f":{WELL_KNOWN_PORT}" in text
    path = tmp_path / "zenoh.json5"
    path.write_text(text.replace(f":{WELL_KNOWN_PORT}", f":{port}"))
    return path


def run(cmd: list[str], timeout: float = 20.0) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=timeout)


def full_view(vehicle_id: str, now: float, **changes) -> VehicleView:
    return VehicleView(
        vehicle_id, status=sample_status(vehicle_id, **changes), received_at=now - 0.25, statuses=3, alive=True
    )


# ------------------------------------------------------------------------------ pure table
def test_render_table_shows_every_column():
    now = 1_700_000_100.0
    vehicles = {
        "boat1": full_view("boat1", now),
        "boat-2": VehicleView(
            "boat-2",
            status=sample_status(
                "boat-2",
                state="waiting",
                mode=None,
                armed=None,
                position_ned=None,
                distance_to_goal_m=None,
                position_age_s=None,
                cmd_velocity_ned=[0.0, 0.0],
                loop_latency_ms={"p50": None, "p99": None},
            ),
            received_at=now - 4.0,
            alive=False,
        ),
        "ghost": VehicleView("ghost", alive=True),
    }
    table = render_table(vehicles, now)
    lines = table.splitlines()
    assert "vehicles 3 (alive 2)" in lines[0]
    header, rows = lines[1], lines[2:]
    for column in (
        "VEHICLE",
        "LIVE",
        "STATE",
        "MODE",
        "ARMED",
        "N[m]",
        "E[m]",
        "TO GOAL[m]",
        "CMD[m/s]",
        "POS AGE[s]",
        "MSG AGE[s]",
        "LOOP p50/p99[ms]",
        "BAD",
        "SUSPECT",
    ):
        assert column in header
    assert [r.split()[0] for r in rows] == ["boat-2", "boat1", "ghost"]  # sorted by id
    boat1 = rows[1].split()
    assert boat1 == [
        "boat1",
        "alive",
        "guiding",
        "GUIDED",
        "yes",
        "12.5",
        "-3.2",
        "12.9",
        "0.90",
        "0.04",
        "0.2",
        "0.8/2.5",
        "0",
        "0",
    ]
    assert rows[0].split()[:5] == ["boat-2", "gone", "waiting", "-", "-"]
    assert rows[0].split()[-4:] == ["4.0", "-/-", "0", "0"]
    assert rows[2].split()[:3] == ["ghost", "alive", "-"]


def test_render_table_without_vehicles_says_it_waits():
    assert "no vehicles yet" in render_table({}, time.time())


def test_malformed_payloads_are_counted_never_raised():
    state = MonitorState()
    now = time.time()
    state.on_status("koopguide/boat1/status", b"{broken", now)
    state.on_status("koopguide/boat1/status", encode_status(sample_status("boat1", seq=1)), now)
    state.on_status("koopguide/boat1/status", encode_status(sample_status("other")), now)  # wrong key
    state.on_status("koopguide/boat1/status", b'{"t": NaN}', now)
    assert state.malformed == 3 and state.vehicles["boat1"].malformed == 3
    assert state.vehicles["boat1"].status["seq"] == 1  # the good one is kept
    table = render_table(state.vehicles, now, malformed=state.malformed, last_error=state.last_error)
    assert "malformed statuses 3" in table and "last malformed: boat1:" in table
    assert table.splitlines()[-1].split()[-2:] == ["3", "0"]  # BAD, SUSPECT


def test_a_second_publisher_or_a_sequence_going_back_is_flagged_not_shown():
    state = MonitorState()
    now = 1_700_000_000.0
    real, forger = "a1b2c3d4e5f6", "ffee00112233"
    state.on_status("koopguide/boat1/status", encode_status(sample_status("boat1", seq=5)), now, real)
    # a forger claims the boat has arrived: another publisher while the real one is live
    state.on_status(
        "koopguide/boat1/status", encode_status(sample_status("boat1", seq=6, state="arrived")), now + 0.1, forger
    )
    view = state.vehicles["boat1"]
    assert view.status["state"] == "guiding" and view.status["seq"] == 5
    assert view.suspect == 1 and "second publisher ffee0011" in view.last_suspect
    # a replayed (old) status from the real publisher's id: the sequence does not increase
    state.on_status(
        "koopguide/boat1/status", encode_status(sample_status("boat1", seq=3, state="arrived")), now + 0.2, real
    )
    assert view.suspect == 2 and "sequence went from 5 to 3" in view.last_suspect
    assert view.status["state"] == "guiding"
    table = render_table(state.vehicles, now + 0.3)
    assert "SUSPECT boat1: 2 status(es) ignored" in table
    # the real publisher goes on; after it has been silent past the hand-over time a new one may take over
    state.on_status("koopguide/boat1/status", encode_status(sample_status("boat1", seq=6)), now + 0.3, real)
    assert view.status["seq"] == 6 and view.statuses == 2
    later = now + 0.3 + PUBLISHER_HANDOVER_S + 0.1
    state.on_status("koopguide/boat1/status", encode_status(sample_status("boat1", seq=1)), later, forger)
    assert view.source == forger and view.status["seq"] == 1 and view.suspect == 2


def test_a_forged_status_from_another_zenoh_peer_is_flagged_by_the_monitor():
    port = free_port()
    with publishing("boat1", port, state="guiding"):
        monitor = Monitor.open(default_zenoh_config(port))
        forger = zenoh.open(default_zenoh_config(port))
        try:
            wait_for(
                lambda: (
                    monitor.poll() >= 0
                    and monitor.state.vehicles.get("boat1")
                    and monitor.state.vehicles["boat1"].status is not None
                )
            )
            for seq in range(10**6, 10**6 + 20):  # a forged "arrived", with a sequence ahead of the real one
                forger.put("koopguide/boat1/status", encode_status(sample_status("boat1", seq=seq, state="arrived")))
                time.sleep(0.02)
                monitor.poll()
            view = wait_for(
                lambda: (
                    monitor.poll() >= 0
                    and monitor.state.vehicles["boat1"].suspect >= 10
                    and monitor.state.vehicles["boat1"]
                )
            )
            assert view.status["state"] == "guiding"  # the real publisher's state is what is shown
            assert "second publisher" in view.last_suspect
        finally:
            forger.close()
            monitor.close()


def test_ready_once_every_alive_vehicle_reported():
    state = MonitorState()
    assert not state.all_alive_reported()
    state.on_liveliness("koopguide/a/alive", True)
    state.on_liveliness("koopguide/b/alive", True)
    state.on_status("koopguide/a/status", encode_status(sample_status("a")), time.time())
    assert not state.all_alive_reported()
    state.on_liveliness("koopguide/b/alive", False)  # gone: not waited for
    assert state.all_alive_reported()


# ------------------------------------------------------------------------ in-process session
@pytest.mark.timeout(30)
def test_monitor_sees_status_liveliness_and_garbage(tmp_path: Path):
    port = free_port()
    with Monitor.open(default_zenoh_config(port)) as monitor:
        with publishing("boat1", port):
            wait_for(lambda: monitor.poll() >= 0 and monitor.state.all_alive_reported())
            view = monitor.state.vehicles["boat1"]
            assert view.alive and view.status["state"] == "guiding"
            rogue = zenoh.open(default_zenoh_config(port))
            try:
                wait_for(
                    lambda: (
                        rogue.put("koopguide/rogue/status", b"not a status")
                        or (monitor.poll() >= 0 and monitor.state.malformed > 0)
                    )
                )
            finally:
                rogue.close()
        wait_for(lambda: monitor.poll() >= 0 and monitor.state.vehicles["boat1"].alive is False)
        table = monitor.table()
    assert "boat1" in table and "gone" in table and "malformed statuses" in table


# ------------------------------------------------------------------------------ subprocesses
@pytest.mark.timeout(30)
def test_monitor_once_prints_every_alive_vehicle(tmp_path: Path):
    port = free_port()
    cfg = config_file(tmp_path, port)
    with publishing("boat1", port, state="guiding"), publishing("boat-2", port, state="arrived"):
        started = time.monotonic()
        result = run([*MONITOR, "--zenoh-config", str(cfg), "--once"])
        elapsed = time.monotonic() - started
    assert result.returncode == 0, result.stderr
    rows = {line.split()[0]: line.split() for line in result.stdout.splitlines()[2:]}
    assert rows["boat1"][:3] == ["boat1", "alive", "guiding"]
    assert rows["boat-2"][:3] == ["boat-2", "alive", "arrived"]
    assert "\x1b[" not in result.stdout  # not a terminal: no ANSI
    assert elapsed < 4.5, f"--once took {elapsed:.1f} s with both vehicles publishing"


@pytest.mark.timeout(30)
def test_monitor_once_without_vehicles_exits_1(tmp_path: Path):
    result = run([*MONITOR, "--zenoh-config", str(config_file(tmp_path, free_port())), "--once"])
    assert result.returncode == 1
    assert "no vehicle status received" in result.stderr
    assert result.stdout == ""


@pytest.mark.timeout(30)
def test_monitor_duration_prints_plain_blocks_and_exits_0(tmp_path: Path):
    port = free_port()
    with publishing("boat1", port):
        started = time.monotonic()
        result = run([*MONITOR, "--zenoh-config", str(config_file(tmp_path, port)), "--duration", "1.2"])
        elapsed = time.monotonic() - started
    assert result.returncode == 0, result.stderr
    blocks = [b for b in result.stdout.split("\n\n") if b.strip()]
    assert len(blocks) >= 2  # about two per second
    assert "boat1" in blocks[-1] and "guiding" in blocks[-1]
    assert "\x1b[" not in result.stdout
    assert elapsed < 6.0


def stopped_by_signal(cmd: list[str], signum: int, ready: str, ready_on_stdout: bool) -> tuple[int, str]:
    """Start ``cmd``, wait for its first line on stdout (or stderr) to start with ``ready``, send it ``signum``;
    its exit code and stderr (killed if it has not exited 10 s later)."""
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        first_line = (proc.stdout if ready_on_stdout else proc.stderr).readline()
        assert first_line.startswith(ready), first_line + proc.stderr.read()
        time.sleep(0.3)
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, err


@pytest.mark.timeout(30)
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_monitor_ctrl_c_exits_0(tmp_path: Path, signum: int):
    port = free_port()
    with publishing("boat1", port):  # the first table has started
        code, err = stopped_by_signal(
            [*MONITOR, "--zenoh-config", str(config_file(tmp_path, port))], signum, "koopguide monitor", True
        )
    assert code == 0, err
    assert "Traceback" not in err


@pytest.mark.timeout(30)
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_zenoh_router_stops_on_ctrl_c_or_sigterm_and_exits_0(tmp_path: Path, signum: int):
    """The router waits on the same stop flag as the monitor (it used to raise KeyboardInterrupt from its SIGTERM
    handler, wherever the main thread was)."""
    path = tmp_path / "router.json5"
    path.write_text(
        json.dumps(
            {
                "mode": "router",
                "listen": {"endpoints": [f"tcp/127.0.0.1:{free_port()}"]},
                "scouting": {"multicast": {"enabled": False}},
            }
        )
    )
    router = [sys.executable, "-m", "koopguide", "zenoh-router", "--zenoh-config", str(path)]
    code, err = stopped_by_signal(router, signum, "koopguide zenoh-router:", False)
    assert code == 0, err
    assert "Traceback" not in err


@pytest.mark.timeout(30)
@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--duration", "0"], "--duration must be a positive number of seconds, got 0"),
        (["--zenoh-config", "/nonexistent/zenoh.json5", "--once"], "/nonexistent/zenoh.json5: zenoh configuration"),
    ],
)
def test_monitor_user_errors_are_one_line(args, expected):
    result = run([*MONITOR, *args])
    assert result.returncode == 2
    assert expected in result.stderr and len(result.stderr.strip().splitlines()) == 1


@pytest.mark.timeout(30)
def test_example_subscriber_prints_states_and_positions(tmp_path: Path):
    port = free_port()
    with publishing("boat1", port):
        result = run(
            [
                sys.executable,
                "examples/zenoh_subscriber.py",
                "--duration",
                "1.0",
                "--zenoh-config",
                str(config_file(tmp_path, port)),
            ]
        )
    assert result.returncode == 0, result.stderr
    first = result.stdout.splitlines()[0].split()
    assert first == ["boat1", "guiding", "N", "12.50", "m", "E", "-3.25", "m"]


# ------------------------------------------------------------------------ access control
def secured(
    file: Path,
    port: int,
    credentials: Path,
    user: str | None = None,
    password: str | None = None,
) -> zenoh.Config:
    """A shipped access-control template on ``port``: the router (with ``credentials``) or a client."""
    cfg = default_zenoh_config(port, file=file)
    if user is None:
        cfg.insert_json5("transport/auth/usrpwd/dictionary_file", json.dumps(str(credentials)))
    else:
        cfg.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
        cfg.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
    return cfg


def test_behind_the_access_control_router_a_peer_without_rights_cannot_publish_a_status(tmp_path: Path):
    credentials = tmp_path / "credentials.txt"
    credentials.write_text("koopguide-service:s3rvice\nkoopguide-viewer:v1ewer\nintruder:1ntruder\n")
    port = free_port()
    router = zenoh.open(secured(ACL_ROUTER_CONFIG_FILE, port, credentials))

    def client(user: str, password: str) -> zenoh.Config:
        return secured(ACL_CLIENT_CONFIG_FILE, port, credentials, user, password)

    monitor = Monitor.open(client("koopguide-viewer", "v1ewer"))
    service = zenoh.open(client("koopguide-service", "s3rvice"))
    with pytest.raises(zenoh.ZError):  # a service's name with a wrong password: the router refuses it
        zenoh.open(client("koopguide-service", "guessed")).close()
    forgers = [
        zenoh.open(client("intruder", "1ntruder")),  # known to the router, but without rights
        zenoh.open(client("koopguide-viewer", "v1ewer")),
    ]  # a viewer trying to publish
    try:
        time.sleep(0.5)  # let the sessions connect (or fail to)
        for seq in range(1, 41):
            service.put("koopguide/boat1/status", encode_status(sample_status("boat1", seq=seq)))
            for forger in forgers:
                forger.put(
                    "koopguide/boat1/status", encode_status(sample_status("boat1", seq=10**6 + seq, state="arrived"))
                )
                forger.put("koopguide/ghost/status", encode_status(sample_status("ghost", seq=seq)))
            time.sleep(0.01)
        view = wait_for(
            lambda: (
                monitor.poll() >= 0
                and monitor.state.vehicles.get("boat1")
                and monitor.state.vehicles["boat1"].statuses == 40
                and monitor.state.vehicles["boat1"]
            )
        )
        time.sleep(0.3)
        monitor.poll()
        assert view.status["state"] == "guiding" and view.status["seq"] == 40
        assert view.suspect == 0  # the forgeries never reached the monitor at all
        assert "ghost" not in monitor.state.vehicles
    finally:
        for session in (*forgers, service):
            session.close()
        monitor.close()
        router.close()
