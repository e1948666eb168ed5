"""The operator's hold end to end: the guidance service with a real zenoh session on loopback, a scripted
ArduPilot-like boat over real UDP, and signed requests put on ``koopguide/<id>/control`` by another zenoh
session (as the dashboard does). Conventions: local NED [m], [m/s]; the boat's own clock [s]."""

from __future__ import annotations

import asyncio
import json
import math
import time
from pathlib import Path

import pytest
import zenoh

from koopguide.base.config import ConfigError
from koopguide.bus.control import control_key, encode_control
from koopguide.bus.zenoh_config import default_zenoh_config
from koopguide.guidance.daemon import GuidanceDaemon
from koopguide.guidance.operator import DISABLED
from koopguide.harness.mission import free_udp_port
from tests.bus.test_status_bus import Listener
from tests.guidance.test_service_failsafes import config, speed, until
from tests.support.scripted_vehicle import ScriptedVehicle
from tests.support.status_samples import free_port

TOKEN = "operator-test-token-0123456789"


def write_token(tmp_path: Path, token: str = TOKEN) -> Path:
    path = tmp_path / "token"
    path.write_text(token + "\n")
    return path


async def put(session: zenoh.Session, vehicle_id: str, action: str, token: str) -> str:
    """Put one signed request; its nonce."""
    payload = encode_control(action, vehicle_id, token, time.time(), source="test@loopback")
    await asyncio.to_thread(session.put, control_key(vehicle_id), payload)
    return json.loads(payload)["nonce"]


def acked(listener: Listener, vehicle_id: str, nonce: str) -> dict | None:
    """The latest status that acknowledges ``nonce``."""
    matching = [s for s in listener.statuses_from(vehicle_id) if (s.get("control_ack") or {}).get("nonce") == nonce]
    return matching[-1] if matching else None


def boat_speed(boat: ScriptedVehicle) -> float:
    return math.hypot(boat.vn, boat.ve)


@pytest.mark.timeout(90)
def test_a_signed_hold_stops_the_boat_a_wrong_token_changes_nothing_and_resume_guides_again(
    zshape_model: Path, tmp_path: Path
) -> None:
    zport = free_port()
    cfg = config(
        free_udp_port(),
        vehicle_id="boat5",
        status={"rate_hz": 10.0, "control_token_file": str(write_token(tmp_path))},
    )
    listener = Listener(zport)
    asker = zenoh.open(default_zenoh_config(zport))

    async def scenario() -> None:
        udp = int(cfg.mavlink.endpoint.rsplit(":", 1)[1])
        daemon = await GuidanceDaemon.create(cfg, zshape_model, default_zenoh_config(zport))
        task = asyncio.create_task(daemon.run())
        try:
            with ScriptedVehicle(udp, start_ned=(1.5, -1.5)) as boat:
                await until(lambda: daemon.state.value == "guiding" and boat_speed(boat) > 0.05)
                await until(lambda: any(s["state"] == "guiding" for s in listener.statuses_from("boat5")))
                # a request signed with another token: refused, acknowledged as such, the boat keeps going
                wrong = await put(asker, "boat5", "hold", "not-the-token-0123456789")
                await until(lambda: acked(listener, "boat5", wrong) is not None)
                status = acked(listener, "boat5", wrong)
                assert status["control_ack"]["accepted"] is False and "wrong MAC" in status["control_ack"]["reason"]
                assert status["state"] == "guiding" and status["control_refused"] == 1
                await asyncio.sleep(0.5)
                assert daemon.state.value == "guiding" and boat_speed(boat) > 0.05
                # the right token: hold, zero velocity at once and every setpoint after
                nonce = await put(asker, "boat5", "hold", TOKEN)
                t_hold = boat.t
                await until(lambda: acked(listener, "boat5", nonce) is not None)
                status = acked(listener, "boat5", nonce)
                assert status["control_ack"] == {"nonce": nonce, "action": "hold", "accepted": True, "reason": None}
                assert status["state"] == "hold" and status["reason"] == "operator hold (test@loopback)"
                await asyncio.sleep(1.5)
                held = boat.setpoints(since=t_hold + 0.5)
                assert len(held) >= 8 and all(speed(r) == 0.0 for r in held)  # 10 Hz of zero velocity
                assert all(r.msg.type_mask == 2535 for r in held)  # zero at the current heading (with yaw)
                n0, e0 = boat.n, boat.e
                await asyncio.sleep(1.0)
                assert math.hypot(boat.n - n0, boat.e - e0) < 1e-6  # the boat stays put
                assert daemon.state.value == "hold"
                # resume: guiding again
                again = await put(asker, "boat5", "resume", TOKEN)
                await until(lambda: acked(listener, "boat5", again) is not None)
                await until(lambda: daemon.state.value == "guiding" and boat_speed(boat) > 0.05)
                assert acked(listener, "boat5", again)["control_ack"]["accepted"] is True
        finally:
            daemon.stop()
            await task

    try:
        asyncio.run(scenario())
    finally:
        asker.close()
        listener.close()


@pytest.mark.timeout(60)
def test_without_a_token_requests_are_refused_counted_and_change_nothing(zshape_model: Path) -> None:
    zport = free_port()
    cfg = config(free_udp_port(), vehicle_id="boat6", status={"rate_hz": 10.0})
    listener = Listener(zport)
    asker = zenoh.open(default_zenoh_config(zport))

    async def scenario() -> None:
        udp = int(cfg.mavlink.endpoint.rsplit(":", 1)[1])
        daemon = await GuidanceDaemon.create(cfg, zshape_model, default_zenoh_config(zport))
        task = asyncio.create_task(daemon.run())
        try:
            with ScriptedVehicle(udp, start_ned=(1.5, -1.5)) as boat:
                await until(lambda: daemon.state.value == "guiding" and boat_speed(boat) > 0.05)
                await until(lambda: listener.statuses_from("boat6") != [])
                nonce = await put(asker, "boat6", "hold", TOKEN)
                await until(lambda: acked(listener, "boat6", nonce) is not None)
                status = acked(listener, "boat6", nonce)
                assert status["control_ack"] == {
                    "nonce": nonce,
                    "action": "hold",
                    "accepted": False,
                    "reason": DISABLED,
                }
                assert status["control_refused"] == 1 and status["state"] == "guiding"
                await asyncio.sleep(0.5)
                assert daemon.state.value == "guiding" and boat_speed(boat) > 0.05
        finally:
            daemon.stop()
            await task

    try:
        asyncio.run(scenario())
    finally:
        asker.close()
        listener.close()


@pytest.mark.parametrize(
    ("token", "message"),
    [(None, "not found"), ("short", "at least 16 characters, got 5")],
)
def test_a_missing_or_short_token_file_is_refused_before_anything_opens(
    zshape_model: Path, tmp_path: Path, token: str | None, message: str
) -> None:
    path = tmp_path / "token" if token is None else write_token(tmp_path, token)
    cfg = config(free_udp_port(), status={"control_token_file": str(path)})
    with pytest.raises(ConfigError, match=message) as caught:
        asyncio.run(GuidanceDaemon.create(cfg, zshape_model))
    assert "status.control_token_file" in str(caught.value)
