"""Issue 11 without signing: the service against a scripted vehicle over real loopback UDP, and attackers
on the same port - a 100 Hz position spoofer, a MANUAL heartbeat (plain and signed with a random key),
10,000 source ports, and a flood of MAVLink 2 headers that claim 255-byte payloads."""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import socket
import time
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from koopguide.guidance import settings
from koopguide.guidance.daemon import GuidanceDaemon
from koopguide.harness.mission import free_udp_port
from koopguide.mavlink import rover
from koopguide.mavlink.signing import SigningKey
from tests.support.mavlink_frames import encoder, frame, local_position, until, vehicle_heartbeat
from tests.support.scripted_vehicle import ScriptedVehicle

HEADER_FLOOD = bytes([0xFD, 255, 0, 0, 0, 1, 1, 32, 0, 0])  # a MAVLink 2 header claiming a 255-byte payload


@contextlib.asynccontextmanager
async def guiding(model: Path) -> AsyncIterator[tuple[GuidanceDaemon, ScriptedVehicle, tuple[str, int]]]:
    port = free_udp_port()
    cfg = settings.load(
        overrides={
            "arm": True,
            "mavlink": {"endpoint": f"udp:127.0.0.1:{port}", "link_timeout_s": 1.0},
            "frame": {"goal_ned": [0.0, 0.0], "scale": 0.04, "heading_deg": 90.0},
        }
    )
    daemon = await GuidanceDaemon.create(cfg, model)
    task = asyncio.create_task(daemon.run())
    try:
        with ScriptedVehicle(port, start_ned=(1.5, -1.5)) as boat:
            await until(lambda: daemon.state.value == "guiding")
            yield daemon, boat, ("127.0.0.1", port)
            assert not task.done(), "the service must not exit by itself"
    finally:
        daemon.stop()
        await task


def estimate_error(daemon: GuidanceDaemon, boat: ScriptedVehicle) -> float:
    position = daemon.status()["position_ned"]
    with boat.lock:
        return math.dist(position, (boat.n, boat.e))


@pytest.mark.timeout(60)
def test_a_100_hz_position_spoofer_and_manual_heartbeats_from_another_address_are_dropped(zshape_model: Path) -> None:
    async def scenario() -> None:
        async with guiding(zshape_model) as (daemon, boat, addr):
            spoofer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            fake = [encoder(1, 1), encoder(1, 1, key=SigningKey(os.urandom(32), "random"))]
            errors, states = [], []
            for k in range(150):  # 1.5 s at 100 Hz: positions at the tank wall, and MANUAL heartbeats
                spoofer.sendto(frame(fake[0], local_position(int(boat.t * 1000) + 50, 9.0, 9.0)), addr)
                if k % 10 == 0:
                    spoofer.sendto(frame(fake[(k // 10) % 2], vehicle_heartbeat(rover.MANUAL, armed=True)), addr)
                await asyncio.sleep(0.01)
                errors.append(estimate_error(daemon, boat))
                states.append(daemon.state.value)
            spoofer.close()
            assert set(states) == {"guiding"} and daemon.supervisor.mode == rover.GUIDED
            assert max(errors) < 0.3, f"the estimate followed the spoofer (max error {max(errors):.2f} m)"
            assert daemon.link.stats.wrong_source >= 160 and daemon.link.stats.source_changes == 0

    asyncio.run(scenario())


@pytest.mark.timeout(90)
def test_ten_thousand_source_ports_get_nothing_and_guidance_stays_timely(
    zshape_model: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    async def scenario() -> dict[str, float]:
        async with guiding(zshape_model) as (daemon, boat, addr):
            await asyncio.sleep(1.0)
            p99_before = daemon.latency.percentiles()["p99"]
            cpu0, wall0 = time.process_time(), time.perf_counter()
            gcs = encoder(255, 190)
            kept = []
            for k in range(10_000):
                s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                s.setblocking(False)
                s.sendto(frame(gcs, vehicle_heartbeat()) if k % 2 else b"\xfe\x00garbage", addr)
                if k % 100 == 0:
                    kept.append(s)  # 100 of them stay open to see whether anything comes back
                else:
                    s.close()
                await asyncio.sleep(0)
            flood_cpu_s, flood_wall_s = time.process_time() - cpu0, time.perf_counter() - wall0
            cpu1, wall1, sent1 = time.process_time(), time.perf_counter(), daemon.link.stats.sent
            await asyncio.sleep(2.0)
            after_cpu = (time.process_time() - cpu1) / (time.perf_counter() - wall1)
            for s in kept:
                with pytest.raises(BlockingIOError):
                    s.recv(65536)  # nothing was sent to any of them
                s.close()
            assert daemon.link.peers == (("127.0.0.1", boat.conn.port.getsockname()[1]),)  # the vehicle only
            assert daemon.link.stats.sent - sent1 >= 15  # setpoints and heartbeats kept flowing to the vehicle
            assert daemon.state.value == "guiding"
            p99_after = daemon.latency.percentiles()["p99"]
            return {"flood_cpu_s": flood_cpu_s, "flood_wall_s": flood_wall_s, "cpu_share_after": after_cpu,
                    "latency_p99_ms_before": p99_before, "latency_p99_ms_after": p99_after}  # fmt: skip

    figures = asyncio.run(scenario())
    with capsys.disabled():
        print("\nservice, 10,000 source ports (machine shared, loaded): "
              + ", ".join(f"{k} {v:.3f}" for k, v in figures.items()))  # fmt: skip


@pytest.mark.timeout(60)
def test_a_header_garbage_flood_does_not_blind_the_service(zshape_model: Path) -> None:
    async def scenario() -> None:
        async with guiding(zshape_model) as (daemon, _boat, addr):
            attacker = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            received0, states = daemon.link.stats.received, []
            for _ in range(300):  # 3 s at 100 Hz
                attacker.sendto(HEADER_FLOOD, addr)
                await asyncio.sleep(0.01)
                states.append(daemon.state.value)
            attacker.close()
            assert set(states) == {"guiding"}
            assert daemon.link.stats.received - received0 >= 60  # the vehicle's 20 Hz positions still arrive
            assert daemon.position_age() is not None and daemon.position_age() < 0.5
            assert daemon.link.stats.corrupt >= 250

    asyncio.run(scenario())
