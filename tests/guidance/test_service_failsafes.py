"""The service against a scripted ArduPilot-like vehicle over real loopback UDP: stale positions, link
loss, a foreign system, garbage bytes, clean shutdown, and refusal of bad input before anything is sent."""

from __future__ import annotations

import asyncio
import contextlib
import math
import signal
import subprocess
import sys
import time
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from koopguide.guidance import settings
from koopguide.guidance.daemon import GuidanceDaemon
from koopguide.harness.mission import free_udp_port
from tests.support.scripted_vehicle import GUIDED, LOITER, ScriptedVehicle


def config(port: int, **overrides):
    base = {
        "arm": True,
        "mavlink": {"endpoint": f"udp:127.0.0.1:{port}", "link_timeout_s": 1.0},
        "frame": {"goal_ned": [0.0, 0.0], "scale": 0.04, "heading_deg": 90.0},
    }
    return settings.load(overrides={**base, **overrides})


def speed(r) -> float:
    return math.hypot(r.msg.vx, r.msg.vy)


async def until(predicate, within_s: float = 10.0) -> None:
    deadline = time.monotonic() + within_s
    while not predicate():
        assert time.monotonic() < deadline, "condition not reached in time"
        await asyncio.sleep(0.02)


@contextlib.asynccontextmanager
async def guiding(model: Path, cfg) -> AsyncIterator[tuple[GuidanceDaemon, ScriptedVehicle]]:
    """A running service and a scripted boat it is already guiding; both stopped at exit."""
    port = int(cfg.mavlink.endpoint.rsplit(":", 1)[1])
    daemon = await GuidanceDaemon.create(cfg, model)
    task = asyncio.create_task(daemon.run())
    try:
        with ScriptedVehicle(port, start_ned=(1.5, -1.5)) as boat:
            await until(lambda: daemon.state.value == "guiding")
            yield daemon, boat
            assert not task.done(), "the service must not exit by itself"
    finally:
        daemon.stop()
        await task


@pytest.mark.timeout(60)
def test_stale_positions_give_zero_velocity_within_a_cycle_then_guidance_resumes(zshape_model: Path) -> None:
    cfg = config(free_udp_port())

    async def scenario() -> None:
        async with guiding(zshape_model, cfg) as (daemon, boat):
            assert boat.mode == GUIDED and boat.armed
            await asyncio.sleep(1.0)
            assert max(speed(r) for r in boat.setpoints()) > 0.1
            boat.pause_positions = True
            t_gap = boat.t
            await asyncio.sleep(2.5)
            during = boat.setpoints(since=t_gap)
            # stale after 0.5 s, +1 command period (0.1 s) +latency margin: every later setpoint is zero
            late = [r for r in during if r.t > t_gap + 0.5 + 0.1 + 0.1]
            assert len(late) >= 10, "setpoints must keep coming (zero) while positions are missing"
            assert all(speed(r) == 0.0 for r in late)
            assert daemon.state.value == "hold"
            boat.pause_positions = False
            t_back = boat.t
            await until(lambda: daemon.state.value == "guiding", 5.0)
            await asyncio.sleep(0.5)
            assert any(speed(r) > 0.05 for r in boat.setpoints(since=t_back))
            # every setpoint in LOCAL_NED, never above the limit; moving: velocity only (3559); zero (the
            # hold): velocity + yaw at the boat's heading (2535), so that Rover does not turn north
            for r in boat.setpoints():
                assert r.msg.coordinate_frame == 1 and speed(r) <= cfg.command.max_speed_mps  # as received (float32)
                assert r.msg.type_mask == (3559 if speed(r) > 0 else 2535)
            held = [r for r in late if r.msg.type_mask == 2535]
            assert held and all(abs(r.msg.yaw - held[0].msg.yaw) < 1e-6 for r in held)

    asyncio.run(scenario())


@pytest.mark.timeout(60)
def test_link_loss_waits_and_recovers_without_exiting(zshape_model: Path) -> None:
    port = free_udp_port()

    async def scenario() -> None:
        async with guiding(zshape_model, config(port)) as (daemon, boat):
            boat.silent = True
            await until(lambda: daemon.state.value == "hold", 2.0)  # positions stale first
            await until(lambda: daemon.state.value == "waiting", 3.0)  # then the heartbeat is missed
            boat.silent = False
            await until(lambda: daemon.state.value == "guiding", 5.0)
            states = [s for _, s in daemon.transitions]
            assert states[-4:] == ["guiding", "hold", "waiting", "guiding"]

    asyncio.run(scenario())


@pytest.mark.timeout(60)
def test_foreign_system_and_garbage_are_ignored(zshape_model: Path) -> None:
    port = free_udp_port()

    async def scenario() -> None:
        async with guiding(zshape_model, config(port)) as (daemon, boat):
            spoofer = ScriptedVehicle(port, start_ned=(40.0, 40.0), sysid=2)
            with spoofer:
                spoofer.mode, spoofer.armed = 0, False
                for _ in range(20):
                    spoofer.conn.write(b"\xfd\x09garbage-bytes-not-mavlink\x00\x01")
                    await asyncio.sleep(0.02)
                await asyncio.sleep(1.0)
            p, _ = daemon.estimate()
            assert math.hypot(p[0] - boat.n, p[1] - boat.e) < 0.2, "the spoofed position must not be used"
            assert daemon.supervisor.mode == GUIDED and daemon.supervisor.armed
            assert daemon.link.stats.foreign > 10 and daemon.link.stats.corrupt > 0
            assert daemon.state.value == "guiding"

    asyncio.run(scenario())


def run_service(args: list[str]) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "koopguide", "run", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


@pytest.mark.timeout(60)
def test_sigterm_sends_zero_velocity_then_loiter_and_exits_0(zshape_model: Path, tmp_path: Path) -> None:
    port = free_udp_port()
    zenoh_file = tmp_path / "zenoh.json5"
    zenoh_file.write_text(
        '{ mode: "peer", scouting: { multicast: { enabled: false } }, '
        f'listen: {{ endpoints: ["tcp/127.0.0.1:{free_udp_port()}"] }} }}'
    )
    proc = run_service(
        [
            "--model",
            str(zshape_model),
            "--mavlink",
            f"udp:127.0.0.1:{port}",
            "--arm",
            "--goal-ned",
            "0,0",
            "--zenoh-config",
            str(zenoh_file),
        ]
    )
    try:
        with ScriptedVehicle(port, start_ned=(1.5, -1.5)) as boat:
            assert boat.wait_for(lambda: any(speed(r) > 0.05 for r in boat.setpoints()), 20.0), proc.stderr
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(10) == 0
            sps = boat.setpoints()
            assert speed(sps[-1]) == 0.0
            modes = [int(r.msg.param2) for r in boat.of_kind("COMMAND_LONG") if r.msg.command == 176]
            assert modes[0] == GUIDED and modes[-1] == LOITER and boat.mode == LOITER
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()


@pytest.mark.timeout(60)
@pytest.mark.parametrize("case", ["corrupt_model", "missing_model", "unknown_key", "bad_type", "bad_endpoint"])
def test_bad_input_is_refused_before_anything_is_sent(case: str, zshape_model: Path, tmp_path: Path) -> None:
    port = free_udp_port()
    model = zshape_model
    extra: list[str] = []
    mavlink = f"udp:127.0.0.1:{port}"
    if case == "corrupt_model":
        model = tmp_path / "bad.pt"
        model.write_bytes(zshape_model.read_bytes()[:500])
    elif case == "missing_model":
        model = tmp_path / "absent.pt"
    elif case in ("unknown_key", "bad_type"):
        cfg = tmp_path / "g.yaml"
        cfg.write_text("command:\n  rate_hz: fast\n" if case == "bad_type" else "command:\n  rat_hz: 10\n")
        extra = ["--config", str(cfg)]
    else:
        mavlink = "bogus:127.0.0.1"
    with ScriptedVehicle(port) as boat:
        proc = run_service(["--model", str(model), "--mavlink", mavlink, *extra])
        _out, err = proc.communicate(timeout=30)
        time.sleep(0.3)
        assert proc.returncode == 2, err
        lines = [line for line in err.strip().splitlines() if line]
        assert len(lines) == 1 and lines[0].startswith("koopguide: error:"), err
        expected = {
            "corrupt_model": "bad.pt",
            "missing_model": "absent.pt",
            "unknown_key": "command.rat_hz",
            "bad_type": "command.rate_hz",
            "bad_endpoint": "bogus",
        }[case]
        assert expected in lines[0]
        assert boat.received == [], "nothing may reach the vehicle"


@pytest.mark.timeout(90)
def test_a_lost_tcp_link_is_reopened_with_back_off(zshape_model: Path) -> None:
    """The vehicle (the simulator, serving tcpin) goes away and comes back on the same port."""
    from sitl import config as sitl_config
    from sitl.runner import SimulationThread

    port = free_udp_port()
    sim_cfg = sitl_config.load(
        overrides={
            "speedup": 5.0,
            "start_poses": [[1.5, -1.5, 90.0]],
            "world": {"walls": False},
            "mavlink": {"endpoints": [f"tcpin:127.0.0.1:{port}"]},
        }
    )
    cfg = config(port, mavlink={"endpoint": f"tcp:127.0.0.1:{port}", "reconnect_min_s": 0.2, "reconnect_max_s": 1.0})

    async def scenario() -> None:
        daemon = None
        try:
            with SimulationThread(sim_cfg):
                daemon = await GuidanceDaemon.create(cfg, zshape_model)
                task = asyncio.create_task(daemon.run())
                await until(lambda: daemon.state.value == "guiding", 15.0)
            await until(lambda: daemon.state.value != "guiding", 5.0)  # the vehicle is gone
            await asyncio.sleep(2.0)  # a few failed reconnects with back-off, and the service keeps running
            assert not task.done() and not daemon.link.connected
            with SimulationThread(sim_cfg):
                await until(lambda: daemon.link.stats.reconnects >= 1, 10.0)
                await until(
                    lambda: (
                        daemon.supervisor.link_up(time.monotonic())
                        and daemon.position_age() is not None
                        and daemon.position_age() < 0.5
                    ),
                    10.0,
                )
        finally:
            if daemon is not None:
                daemon.stop()
                await task

    asyncio.run(scenario())
