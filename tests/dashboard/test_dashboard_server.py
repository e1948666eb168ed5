"""The dashboard server without a browser: a real FleetHub on a real zenoh session fed by real
StatusBus publishers, the aiohttp app on a loopback port, and the command line's refusals."""

from __future__ import annotations

import asyncio
import json
import threading
import time
from pathlib import Path

import pytest
import zenoh
from aiohttp import ClientSession
from aiohttp.test_utils import TestServer

from koopguide import cli
from koopguide.bus.control import ControlInbox, control_key
from koopguide.bus.status_bus import StatusBus
from koopguide.bus.zenoh_config import default_zenoh_config
from koopguide.dashboard.hub import FleetHub
from koopguide.dashboard.server import Dashboard, Listen
from tests.support.status_samples import config_snapshot, field_sampler, free_port, publishing, sample_status

TOKEN = "server-test-token-0123456789"


async def _serve_and_ask(port: int, token: str | None) -> dict:
    hub = await asyncio.to_thread(FleetHub.open, default_zenoh_config(port))
    dashboard = Dashboard(hub, token)
    server = TestServer(dashboard.app, host="127.0.0.1", port=0)
    await server.start_server()
    await dashboard.start()
    out: dict = {}
    try:
        async with ClientSession() as http:
            base = f"http://127.0.0.1:{server.port}"
            async with http.ws_connect(f"{base}/ws") as ws:
                hello = json.loads((await ws.receive(timeout=5)).data)
                statuses = []
                deadline = time.monotonic() + 10
                while time.monotonic() < deadline and len(statuses) < 10:
                    msg = json.loads((await ws.receive(timeout=5)).data)
                    if msg["type"] == "status":
                        statuses.append(msg)
            out["hello"], out["statuses"] = hello, statuses
            async with http.get(f"{base}/api/state") as reply:
                out["state"] = await reply.json()
            async with http.get(f"{base}/") as reply:
                out["index"] = (reply.status, await reply.text())
            async with http.get(f"{base}/static/app.js") as reply:
                out["app"] = (reply.status, await reply.text())
            body = {"action": "hold", "vehicle_id": "boat7", "token": token or "x" * 20}
            async with http.post(f"{base}/api/control", json=body) as reply:
                out["control"] = (reply.status, await reply.json())
            async with http.post(
                f"{base}/api/control",
                json={**body, "token": "wrong-token-0123456789"},
                headers={"Origin": "http://elsewhere.example"},
            ) as reply:
                out["foreign"] = (reply.status, await reply.json())
        out["fields"] = {key: (e.queries, e.error, e.lines) for key, e in hub.fields.items()}
    finally:
        await dashboard.stop()
        await server.close()
        await asyncio.to_thread(hub.close)
    return out


@pytest.mark.timeout(60)
def test_read_only_dashboard_streams_statuses_and_refuses_control():
    port = free_port()
    with publishing("boat7", port, period=0.05):
        out = asyncio.run(_serve_and_ask(port, None))
    assert out["hello"]["type"] == "hello" and out["hello"]["control"] is False
    received = [v for m in out["statuses"] for v in m["vehicles"] if v["vehicle_id"] == "boat7"]
    assert len(received) >= 5
    seqs = [v["status"]["seq"] for v in received]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)  # each status once, in order
    assert received[-1]["status"]["state"] == "guiding" and received[-1]["alive"] is True
    assert received[-1]["seq_regressions"] == 0  # one publisher counting up
    state = out["state"]["vehicles"][0]
    assert state["vehicle_id"] == "boat7" and len(state["trail"]) >= 5  # the trail comes with the snapshot
    assert out["index"][0] == 200 and "/static/app.js" in out["index"][1]
    assert out["app"][0] == 200 and "http://" not in out["app"][1].replace("location.protocol", "")  # no CDN
    assert out["control"][0] == 403 and "--allow-control" in out["control"][1]["error"]
    # the test publisher's field queryable answers with no grid: asked once, the fault kept, nothing drawn
    ((queries, error, lines),) = out["fields"].values()
    assert list(out["fields"]) == [("boat7", "zshape.pt")]
    assert queries == 1 and "field reply has no 'position_ned'" in error and lines is None


@pytest.mark.timeout(60)
def test_control_needs_the_right_token_a_known_vehicle_and_the_same_origin():
    port = free_port()
    with publishing("boat7", port, period=0.05):
        out = asyncio.run(_serve_and_ask(port, TOKEN))
    assert out["hello"]["control"] is True
    status, body = out["control"]  # right token, known vehicle: sent, one nonce
    assert status == 200 and list(body["sent"]) == ["boat7"] and len(body["sent"]["boat7"]) == 32
    assert out["foreign"][0] == 403 and "another origin" in out["foreign"][1]["error"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["dashboard", "--listen", "localhost:80"], "--listen must be IP:PORT"),
        (["dashboard", "--listen", "127.0.0.1:70000"], "port must be 0 .. 65535"),
        (["dashboard", "--allow-control"], "--allow-control needs --control-token-file"),
        (["dashboard", "--control-token-file", "t"], "only used with --allow-control"),
    ],
)
def test_bad_flags_are_one_line_errors(argv, message, capsys):
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("koopguide: error:") and message in err and "\n" not in err


def test_a_short_or_missing_token_file_is_refused(tmp_path: Path, capsys):
    short = tmp_path / "short"
    short.write_text("abc\n")
    assert cli.main(["dashboard", "--allow-control", "--control-token-file", str(short)]) == 2
    assert "at least 16 characters, got 3" in capsys.readouterr().err
    assert cli.main(["dashboard", "--allow-control", "--control-token-file", str(tmp_path / "none")]) == 2
    assert "control token file not found" in capsys.readouterr().err


def test_listen_parses_ipv4_and_ipv6():
    assert Listen.parse("127.0.0.1:0") == Listen("127.0.0.1", 0) and Listen.parse("127.0.0.1:0").loopback
    assert Listen.parse("[::1]:8080") == Listen("::1", 8080)
    assert not Listen.parse("0.0.0.0:8080").loopback


def obeying_service(vehicle_id: str, port: int, token: str, stop: threading.Event) -> None:
    """What the integrator wires into the service: control requests through a ControlInbox, the state
    ``hold`` while held, and ``control_ack`` in every status (docs/dashboard.md, "Control")."""

    async def run() -> None:
        bus = await StatusBus.create(vehicle_id, default_zenoh_config(port), field_sampler, config_snapshot)
        session = zenoh.open(default_zenoh_config(port))
        inbox = ControlInbox(vehicle_id, token)
        requests = session.declare_subscriber(control_key(vehicle_id), zenoh.handlers.RingChannel(16))
        state, seq = "guiding", 0
        try:
            while not stop.is_set():
                while (sample := requests.try_recv()) is not None:
                    request = inbox.receive(sample.payload.to_bytes(), time.time())
                    if request is not None:
                        state = "hold" if request.action == "hold" else "guiding"
                seq += 1
                bus.publish(
                    sample_status(
                        vehicle_id,
                        seq=seq,
                        state=state,
                        control_ack=inbox.ack,
                        reason="operator hold (dashboard)" if state == "hold" else None,
                    )
                )
                await asyncio.sleep(0.05)
        finally:
            requests.undeclare()
            session.close()
            await bus.close()

    asyncio.run(run())


async def _hold_and_watch(port: int) -> tuple[dict, list[dict]]:
    hub = await asyncio.to_thread(FleetHub.open, default_zenoh_config(port))
    dashboard = Dashboard(hub, TOKEN)
    server = TestServer(dashboard.app, host="127.0.0.1", port=0)
    await server.start_server()
    await dashboard.start()
    seen: list[dict] = []
    try:
        async with ClientSession() as http, http.ws_connect(f"http://127.0.0.1:{server.port}/ws") as ws:
            while not seen:  # until the service's first status: then it is connected to the dashboard
                msg = json.loads((await ws.receive(timeout=5)).data)
                seen += [v["status"] for v in msg.get("vehicles", []) if v["status"]]
            body = {"action": "hold", "vehicle_id": "*", "token": TOKEN}
            async with http.post(f"http://127.0.0.1:{server.port}/api/control", json=body) as reply:
                sent = await reply.json()
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline:
                msg = json.loads((await ws.receive(timeout=5)).data)
                seen += [v["status"] for v in msg.get("vehicles", []) if v["status"]]
                if seen and (seen[-1].get("control_ack") or {}).get("nonce") == sent["sent"]["boat3"]:
                    break
    finally:
        await dashboard.stop()
        await server.close()
        await asyncio.to_thread(hub.close)
    return sent, seen


@pytest.mark.timeout(60)
def test_a_hold_goes_to_the_service_and_its_acknowledgement_comes_back_to_the_page():
    port = free_port()
    stop = threading.Event()
    service = threading.Thread(target=obeying_service, args=("boat3", port, TOKEN, stop))
    service.start()
    try:
        sent, seen = asyncio.run(_hold_and_watch(port))
    finally:
        stop.set()
        service.join(10)
    nonce = sent["sent"]["boat3"]
    assert sent["action"] == "hold" and list(sent["sent"]) == ["boat3"]
    last = seen[-1]
    assert last["control_ack"] == {"nonce": nonce, "action": "hold", "accepted": True, "reason": None}
    assert last["state"] == "hold" and last["reason"] == "operator hold (dashboard)"
    assert seen[0]["state"] == "guiding"  # it was guiding before the operator's hold


@pytest.mark.timeout(60)
def test_a_second_publisher_on_a_vehicles_key_shows_as_seq_regressions():
    port = free_port()
    hub = FleetHub.open(default_zenoh_config(port))
    try:
        with publishing("boat5", port, period=0.05), publishing("boat5", port, period=0.05):
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline and hub.seq_regressions.get("boat5", 0) < 3:
                hub.poll()
                time.sleep(0.05)
        assert hub.seq_regressions["boat5"] >= 3
        assert hub.vehicle_message("boat5")["seq_regressions"] == hub.seq_regressions["boat5"]
    finally:
        hub.close()
