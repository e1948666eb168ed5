"""``koopguide dashboard``: a local web page of every vehicle over its field, live over a WebSocket.

Routes (aiohttp):

``GET /``             the page (``static/index.html``); every asset is package data, nothing from a CDN
``GET /static/...``   ``app.js``, ``style.css``
``GET /ws``           WebSocket, server to browser only, JSON text messages:
                      ``{"type": "hello", "control": bool, "vehicles": [...], "fields": [...]}`` once, then
                      ``{"type": "status", "t": unix s, "malformed": n, "vehicles": [...]}`` as statuses arrive (each
                      vehicle: ``vehicle_id, alive, status, received_at, statuses, malformed, last_error``;
                      ``trail`` [[N, E], ...] m in ``hello`` only) and
                      ``{"type": "field", "vehicle_id", "model", "streamlines": [[[N, E], ...], ...],
                      "corners_ned", "goal_ned", "arrival_radius_m"}`` (NED metres) when a vehicle's field is known
``GET /api/state``    the same as ``hello``, as plain JSON
``POST /api/control`` only with ``--allow-control``: ``{"action": "hold"|"resume", "vehicle_id": ID|"*",
                      "token": TOKEN}``; a wrong token is 403. See ``control.py`` for the zenoh message.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import ipaddress
import json
import logging
import signal
import socket
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh
from aiohttp import WSMsgType, web

from koopguide.bus import control
from koopguide.dashboard.hub import FieldEntry, FleetHub, run_fields

log = logging.getLogger(__name__)

STATIC_DIR = Path(__file__).resolve().parent / "static"
#: How often zenoh's channels are drained and news pushed to the browsers [s].
POLL_S = 0.02
#: A browser that takes longer than this to accept one message is dropped [s].
SEND_TIMEOUT_S = 2.0
#: Wait after a wrong token, so guessing is slow [s].
WRONG_TOKEN_DELAY_S = 0.5


@dataclass(frozen=True)
class Listen:
    """Where to serve: ``host`` (an IP address) and ``port`` (0: any free one)."""

    host: str
    port: int

    @classmethod
    def parse(cls, text: str) -> Listen:
        host, sep, port_text = text.rpartition(":")
        host = host.strip("[]")
        try:
            ipaddress.ip_address(host)
            port = int(port_text)
        except ValueError:
            raise ValueError(f"--listen must be IP:PORT, e.g. 127.0.0.1:8080, got {text!r}") from None
        if not sep or not 0 <= port <= 65535:
            raise ValueError(f"--listen port must be 0 .. 65535, got {text!r}")
        return cls(host, port)

    @property
    def loopback(self) -> bool:
        return ipaddress.ip_address(self.host).is_loopback


class Dashboard:
    """The web app over one :class:`FleetHub`. ``token`` set means control is allowed."""

    def __init__(self, hub: FleetHub, token: str | None) -> None:
        self.hub = hub
        self.token = token
        self.clients: set[web.WebSocketResponse] = set()
        self.app = web.Application()
        self.app.router.add_get("/", self.index)
        self.app.router.add_get("/ws", self.websocket)
        self.app.router.add_get("/api/state", self.state)
        self.app.router.add_post("/api/control", self.control)
        self.app.router.add_static("/static", STATIC_DIR, show_index=False)
        self._tasks: list[asyncio.Task[None]] = []

    # -------------------------------------------------------------------------------- routes
    async def index(self, _request: web.Request) -> web.FileResponse:
        return web.FileResponse(STATIC_DIR / "index.html", headers={"Cache-Control": "no-store"})

    def hello(self) -> dict[str, Any]:
        return {
            "type": "hello",
            "control": self.token is not None,
            "t": time.time(),
            "vehicles": self.hub.snapshot(),
            "fields": self.hub.ready_fields(),
            "malformed": self.hub.state.malformed,
        }

    async def state(self, _request: web.Request) -> web.Response:
        return web.json_response(self.hello())

    async def websocket(self, request: web.Request) -> web.WebSocketResponse:
        ws = web.WebSocketResponse(heartbeat=10.0)
        await ws.prepare(request)
        await ws.send_str(json.dumps(self.hello(), allow_nan=False))
        self.clients.add(ws)
        try:
            async for msg in ws:  # the browser sends nothing; this waits for it to close
                if msg.type == WSMsgType.ERROR:
                    break
        finally:
            self.clients.discard(ws)
        return ws

    async def control(self, request: web.Request) -> web.Response:
        if self.token is None:
            return _error(403, "control is off: start the dashboard with --allow-control --control-token-file FILE")
        origin = request.headers.get("Origin")
        if origin is not None and origin.split("://", 1)[-1] != request.host:
            return _error(403, f"control request from another origin {origin!r} refused")
        try:
            body = await request.json()
        except ValueError:
            return _error(400, "control request body must be JSON")
        if not isinstance(body, dict):
            return _error(400, "control request body must be a JSON object")
        token = body.get("token")
        if not isinstance(token, str) or not hmac.compare_digest(token.encode(), self.token.encode()):
            await asyncio.sleep(WRONG_TOKEN_DELAY_S)
            return _error(403, "wrong control token")
        action, target = body.get("action"), body.get("vehicle_id")
        if action not in control.ACTIONS:
            return _error(400, f"action must be one of {', '.join(control.ACTIONS)}, got {action!r}")
        known = sorted(v.vehicle_id for v in self.hub.state.vehicles.values() if v.status is not None)
        if target == "*":
            targets = [vid for vid in known if self.hub.state.vehicles[vid].alive is not False]
        elif target in known:
            targets = [target]
        else:
            return _error(400, f"vehicle_id must be '*' or one of {known}, got {target!r}")
        source = f"dashboard@{socket.gethostname()}"
        nonces = await asyncio.to_thread(self.hub.send_control, action, targets, self.token, source)
        log.info("operator %s sent to %s", action, ", ".join(targets) or "no vehicle")
        return web.json_response({"action": action, "sent": nonces})

    # ------------------------------------------------------------------------------ push loop
    async def start(self) -> None:
        self._tasks = [
            asyncio.create_task(self._pump(), name="dashboard statuses"),
            asyncio.create_task(run_fields(self.hub, self._field_ready), name="dashboard fields"),
        ]

    async def stop(self) -> None:
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        for ws in list(self.clients):
            with contextlib.suppress(ConnectionError, RuntimeError):
                await ws.close()

    async def _pump(self) -> None:
        while True:
            changed = self.hub.poll()
            if changed and self.clients:
                message = {
                    "type": "status",
                    "t": time.time(),
                    "malformed": self.hub.state.malformed,
                    "vehicles": [self.hub.vehicle_message(vid) for vid in changed],
                }
                await self.broadcast(message)
            await asyncio.sleep(POLL_S)

    def _field_ready(self, entry: FieldEntry) -> None:
        task = asyncio.get_running_loop().create_task(self.broadcast(entry.message()))
        self._tasks.append(task)
        task.add_done_callback(lambda t: self._tasks.remove(t) if t in self._tasks else None)

    async def broadcast(self, message: dict[str, Any]) -> None:
        text = json.dumps(message, separators=(",", ":"), allow_nan=False)
        for ws in list(self.clients):
            try:
                await asyncio.wait_for(ws.send_str(text), SEND_TIMEOUT_S)
            except (TimeoutError, ConnectionError, RuntimeError):
                self.clients.discard(ws)  # gone or too slow; its handler ends when the socket closes
                with contextlib.suppress(ConnectionError, RuntimeError):
                    await ws.close()


def _error(status: int, text: str) -> web.Response:
    return web.json_response({"error": text}, status=status)


async def serve(zenoh_config: zenoh.Config, listen: Listen, token: str | None, print_url: Any = print) -> int:
    """Serve until SIGINT/SIGTERM; ``print_url`` gets one line with the URL once the port is bound."""
    hub = await asyncio.to_thread(FleetHub.open, zenoh_config)
    dashboard = Dashboard(hub, token)
    runner = web.AppRunner(dashboard.app, access_log=None, handle_signals=False)
    stopped = asyncio.Event()
    loop = asyncio.get_running_loop()
    try:
        await runner.setup()
        site = web.TCPSite(runner, listen.host, listen.port)
        try:
            await site.start()
        except OSError as exc:
            raise ValueError(f"cannot listen on {listen.host}:{listen.port}: {exc.strerror or exc}") from None
        await dashboard.start()
        host, port = runner.addresses[0][:2]
        shown = f"[{host}]" if ":" in host else host
        print_url(f"koopguide dashboard: http://{shown}:{port}/ ({'control allowed' if token else 'read-only'})")
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stopped.set)
        await stopped.wait()
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
        await dashboard.stop()
        await runner.cleanup()
        await asyncio.to_thread(hub.close)
    return 0
