"""Issue 11 end to end: the guidance service and the simulator with signing keys, under a spoofer without
the key; an unsigned vehicle against a keyed service; a second service on the same port; bad key files."""

from __future__ import annotations

import asyncio
import math
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from koopguide.guidance import settings
from koopguide.guidance.daemon import GuidanceDaemon
from koopguide.harness.mission import free_udp_port
from koopguide.mavlink import rover
from koopguide.mavlink.signing import SigningKey
from koopguide.mavlink.wire import mavlink
from sitl import config as sitl_config
from sitl.runner import SimulationThread
from tests.support.mavlink_frames import encoder, frame, local_position, until, vehicle_heartbeat
from tests.support.scripted_vehicle import ScriptedVehicle

FAKE_NED = (9.0, 9.0)  # where the spoofer claims the boat is [m]
FAKE_TARGET = (7.77, -7.77)  # the position target the spoofer asks the vehicle for [m]


def key_file(tmp_path: Path) -> Path:
    path = tmp_path / "mavlink.key"
    path.write_text(os.urandom(32).hex() + "\n")
    path.chmod(0o600)
    return path


def service_config(port: int, key: Path | None):
    return settings.load(
        overrides={
            "arm": True,
            "mavlink": {"endpoint": f"udp:127.0.0.1:{port}", "link_timeout_s": 1.0,
                        "signing_key": None if key is None else str(key)},
            "frame": {"goal_ned": [0.0, 0.0], "scale": 0.04, "heading_deg": 90.0},
        }
    )  # fmt: skip


@pytest.mark.timeout(120)
def test_with_keys_on_both_sides_a_spoofer_moves_nothing(zshape_model: Path, tmp_path: Path) -> None:
    key = key_file(tmp_path)
    port = free_udp_port()
    sim_cfg = sitl_config.load(
        overrides={
            "speedup": 3.0,
            "start_poses": [[1.5, -1.5, 90.0]],
            "world": {"walls": False},
            "mavlink": {"endpoints": [f"udpout:127.0.0.1:{port}", "tcpin:127.0.0.1:0"], "signing_key": str(key)},
        }
    )
    cfg = service_config(port, key)

    async def scenario() -> None:
        with SimulationThread(sim_cfg) as sim:
            daemon = await GuidanceDaemon.create(cfg, zshape_model)
            task = asyncio.create_task(daemon.run())
            try:
                await until(lambda: daemon.state.value == "guiding")
                gcs_port = sim.call(lambda s: s.links[1].local_address[1])
                spoof_vehicle = socket.create_connection(("127.0.0.1", gcs_port))
                spoof_service = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                as_vehicle = [encoder(1, 1), encoder(1, 1, key=SigningKey(os.urandom(32), "random"))]
                as_gcs = [encoder(255, 191), encoder(255, 191, key=SigningKey(os.urandom(32), "random"))]
                target = mavlink.MAVLink_set_position_target_local_ned_message(
                    0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, 0b110111111000, *FAKE_TARGET, 0.0, 0, 0, 0, 0, 0, 0, 0, 0
                )
                errors, states, sent_before = [], [], daemon.setpoints_sent
                for k in range(200):  # 2 s at 100 Hz
                    fake = as_vehicle[k % 2]
                    spoof_service.sendto(frame(fake, local_position(10**6 + 10 * k, *FAKE_NED)), ("127.0.0.1", port))
                    if k % 10 == 0:
                        spoof_service.sendto(frame(fake, vehicle_heartbeat(rover.MANUAL)), ("127.0.0.1", port))
                        gcs = as_gcs[(k // 10) % 2]
                        spoof_vehicle.sendall(frame(gcs, rover.set_mode((1, 1), rover.HOLD)))
                        spoof_vehicle.sendall(frame(gcs, rover.command_long((1, 1), 400, 0, 21196)))  # force disarm
                        spoof_vehicle.sendall(frame(gcs, target))
                    await asyncio.sleep(0.01)
                    status = daemon.status()
                    states.append(status["state"])
                    truth = sim.call(lambda s: (s.boat(1).state[:2], s.boat(1).autopilot))
                    (n, e), ap = truth
                    if status["position_ned"] is not None:
                        errors.append(math.dist(status["position_ned"], (n, e)))
                    assert ap.mode == rover.GUIDED and ap.armed, "the vehicle obeyed a spoofed command"
                    assert ap.target is None or (ap.target.n, ap.target.e) != FAKE_TARGET
                spoof_vehicle.close()
                spoof_service.close()
                assert set(states) == {"guiding"}, "the spoofer changed the service's state"
                assert max(errors) < 0.5, f"the estimate moved toward the fake position (max error {max(errors):.2f} m)"
                assert daemon.setpoints_sent > sent_before + 10  # guidance went on throughout
                st = daemon.link.stats
                assert st.unsigned >= 100 and st.bad_signature >= 100 and st.wrong_source == 0
                sim_stats = sim.call(lambda s: s.links[1].stats)
                assert sim_stats.unsigned >= 30 and sim_stats.bad_signature >= 30 and sim_stats.received == 0
            finally:
                daemon.stop()
                await task

    asyncio.run(scenario())


@pytest.mark.timeout(60)
def test_a_keyed_service_does_not_trust_an_unsigned_vehicle(zshape_model: Path, tmp_path: Path) -> None:
    port = free_udp_port()

    async def scenario() -> None:
        daemon = await GuidanceDaemon.create(service_config(port, key_file(tmp_path)), zshape_model)
        task = asyncio.create_task(daemon.run())
        try:
            with ScriptedVehicle(port, start_ned=(1.5, -1.5)) as boat:
                await until(lambda: daemon.link.stats.unsigned >= 40, 10.0)
                assert daemon.state.value == "waiting" and daemon.supervisor.heartbeat_wall is None
                assert daemon.link.stats.received == 0 and boat.setpoints() == []
        finally:
            daemon.stop()
            await task

    asyncio.run(scenario())


def koopguide(*args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "koopguide", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


@pytest.mark.timeout(90)
def test_a_second_service_on_the_same_port_exits_2_with_one_line(zshape_model: Path) -> None:
    port = free_udp_port()
    first = koopguide("run", "--model", str(zshape_model), "--mavlink", f"udp:127.0.0.1:{port}")
    try:
        assert first.stderr is not None
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:  # wait until the first one owns the port
            line = first.stderr.readline()
            assert line, "the first service ended early"
            if f"MAVLink udpin:127.0.0.1:{port} open" in line:
                break
        second = koopguide("run", "--model", str(zshape_model), "--mavlink", f"udp:127.0.0.1:{port}")
        _out, err = second.communicate(timeout=60)
        lines = [line for line in err.splitlines() if line.startswith("koopguide:")]
        assert second.returncode == 2, err
        assert len(lines) == 1 and f"port {port} is already in use by another process" in lines[0], err
        assert first.poll() is None, "the first service must keep running"
    finally:
        first.terminate()
        first.communicate(timeout=30)


@pytest.mark.timeout(60)
@pytest.mark.parametrize("command", ["run", "sitl"])
def test_a_bad_key_file_is_refused_in_one_line(command: str, zshape_model: Path, tmp_path: Path) -> None:
    bad = tmp_path / "short.key"
    bad.write_text("0123abcd\n")
    args = ["--model", str(zshape_model)] if command == "run" else ["--duration", "1"]
    proc = koopguide(command, *args, "--signing-key", str(bad))
    _out, err = proc.communicate(timeout=50)
    assert proc.returncode == 2, err
    assert (
        err.strip()
        == f"koopguide: error: signing key {bad}: 9 bytes; expected 32 raw bytes or 64 hexadecimal characters"
    )
