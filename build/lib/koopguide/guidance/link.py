"""MavlinkLink: the one owner of the service's pymavlink connection, driven by the asyncio loop.

pymavlink is neither thread-safe nor asynchronous (FACTS "pymavlink"), so exactly one object owns the
connection: it opens it off the loop, reads it from ``loop.add_reader`` callbacks (draining everything
readable, never blocking), and writes from the loop's thread only. Messages from any system other than
the target vehicle (and any component other than its autopilot) are counted and ignored, so a second
sender on the link cannot spoof positions; corrupt bytes are counted and logged, never acted on.

Endpoints are the strings pymavlink and MAVProxy users know: ``udp:HOST:PORT`` / ``udpin:`` (listen),
``udpout:HOST:PORT``, ``tcp:HOST:PORT`` (client), ``tcpin:HOST:PORT`` (server), ``DEVICE[,BAUD]`` (serial).
A stream link that closes (TCP end of file, serial error) is reopened with exponential back-off.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import re
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

os.environ.setdefault("MAVLINK20", "1")  # before pymavlink.mavutil is imported (FACTS "pymavlink")

from pymavlink import mavutil

from koopguide.guidance.settings import MavlinkSettings

mavutil.set_dialect("ardupilotmega")
mavlink = mavutil.mavlink
log = logging.getLogger(__name__)

NETWORK_PREFIXES = ("udp:", "udpin:", "udpout:", "tcp:", "tcpin:")
LISTEN_PREFIXES = ("udp:", "udpin:", "tcpin:")
HOST_PORT = re.compile(r"^[A-Za-z0-9_.\-]+:\d{1,5}$")
STATS_LOG_EVERY_S = 10.0  # corrupt / foreign message warnings at most this often


class EndpointError(ValueError):
    """A MAVLink endpoint string that cannot be used; the message names it."""


@dataclass(frozen=True)
class Endpoint:
    text: str  # as given
    device: str  # as pymavlink takes it
    baud: int  # serial only
    stream: bool  # tcp client or serial: a closed link is reopened

    @classmethod
    def parse(cls, text: str) -> Endpoint:
        text = text.strip()
        for prefix in NETWORK_PREFIXES:
            if text.startswith(prefix):
                rest = text[len(prefix):]
                lowest = 0 if prefix in LISTEN_PREFIXES else 1  # port 0: any free port
                if not HOST_PORT.match(rest) or not lowest <= int(rest.rsplit(":", 1)[1]) <= 65535:
                    raise EndpointError(f"MAVLink endpoint {text!r}: expected {prefix}HOST:PORT")
                return cls(text, text, 0, prefix == "tcp:")
        if text.startswith("/") or text.upper().startswith("COM"):
            device, _, baud = text.partition(",")
            if baud and not baud.isdigit():
                raise EndpointError(f"MAVLink endpoint {text!r}: baud {baud!r} is not a number")
            return cls(text, device, int(baud or 115200), True)
        raise EndpointError(
            f"MAVLink endpoint {text!r} not understood; use udp:HOST:PORT (listen), udpout:HOST:PORT, "
            "tcp:HOST:PORT, tcpin:HOST:PORT or a serial device such as /dev/ttyUSB0,57600"
        )


@dataclass
class LinkStats:
    received: int = 0  # messages from the target vehicle
    foreign: int = 0  # messages from other systems/components, ignored
    corrupt: int = 0  # bad CRC / unparsable bytes, ignored
    sent: int = 0
    reconnects: int = 0


MessageHandler = Callable[[Any, float], None]  # (message, wall time of arrival from time.perf_counter)


class MavlinkLink:
    """Opens, reads, writes and reopens one MAVLink connection on the running event loop."""

    def __init__(self, settings: MavlinkSettings, endpoint: Endpoint, on_message: MessageHandler) -> None:
        self.settings = settings
        self.endpoint = endpoint
        self.on_message = on_message
        self.stats = LinkStats()
        self.conn: Any = None
        self._reader_fd: int | None = None
        self._reopen: asyncio.Task | None = None
        self._closed = False
        self._last_stats_log = 0.0

    @classmethod
    async def create(cls, settings: MavlinkSettings, on_message: MessageHandler) -> MavlinkLink:
        """Parse the endpoint (errors before anything opens), then open it; retries in the background."""
        link = cls(settings, Endpoint.parse(settings.endpoint), on_message)
        try:
            await link._open()
        except OSError as exc:
            if not link.endpoint.stream:
                raise EndpointError(f"MAVLink endpoint {settings.endpoint!r}: cannot open ({exc})") from None
            log.warning("MAVLink %s: cannot open (%s); retrying", settings.endpoint, exc)
            link._schedule_reopen()
        return link

    # ------------------------------------------------------------------------------ open / close
    async def _open(self) -> None:
        s, ep = self.settings, self.endpoint
        conn = await asyncio.to_thread(
            mavutil.mavlink_connection, ep.device, baud=ep.baud, source_system=s.source_system,
            source_component=s.source_component, dialect="ardupilotmega", autoreconnect=False, retries=0,
            robust_parsing=True,
        )
        if self._closed:
            conn.close()
            return
        self.conn = conn
        self._set_reader(conn.fd)
        log.info("MAVLink %s open", ep.text)

    def _drop(self, why: str) -> None:
        """The stream link closed: stop reading, close, reopen with back-off."""
        log.warning("MAVLink %s lost (%s); reconnecting", self.endpoint.text, why)
        self._close_conn()
        self._schedule_reopen()

    def _close_conn(self) -> None:
        if self._reader_fd is not None:
            asyncio.get_running_loop().remove_reader(self._reader_fd)
            self._reader_fd = None
        if self.conn is not None:
            try:
                self.conn.close()
            except OSError as exc:
                log.debug("closing %s: %s", self.endpoint.text, exc)
            self.conn = None

    def _schedule_reopen(self) -> None:
        if not self._closed and (self._reopen is None or self._reopen.done()):
            self._reopen = asyncio.get_running_loop().create_task(self._reopen_with_backoff())

    async def _reopen_with_backoff(self) -> None:
        delay = self.settings.reconnect_min_s
        while not self._closed:
            await asyncio.sleep(delay)
            try:
                await self._open()
            except OSError as exc:
                delay = min(2.0 * delay, self.settings.reconnect_max_s)
                log.info("MAVLink %s: reconnect failed (%s); next try in %.1f s", self.endpoint.text, exc, delay)
            else:
                self.stats.reconnects += 1
                return

    async def close(self) -> None:
        self._closed = True
        if self._reopen is not None:
            self._reopen.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._reopen
        self._close_conn()

    # ------------------------------------------------------------------------------ read
    def _readable(self) -> None:
        arrived = time.perf_counter()
        try:
            data = self._read_bytes()
        except OSError as exc:
            if self.endpoint.stream:
                self._drop(str(exc))
            else:
                log.warning("MAVLink %s: read error %s", self.endpoint.text, exc)
            return
        if data is None:
            self._drop("closed by the other end")
            return
        if not data:
            return
        try:
            messages = self.conn.mav.parse_buffer(data) or []
        except mavlink.MAVError as exc:  # robust parsing reports bad data as messages; this is the rest
            self.stats.corrupt += 1
            self._report(f"unparsable bytes ({exc})")
            return
        for msg in messages:
            self._dispatch(msg, arrived)

    def _read_bytes(self) -> bytes | None:
        """Everything readable now; None when a stream closed (end of file)."""
        if self.endpoint.device.startswith("tcpin:"):
            return self._read_tcp_server()
        if self.endpoint.device.startswith("tcp:"):
            try:
                data = self.conn.port.recv(65536)
            except BlockingIOError:
                return b""
            return data if data else None
        chunks = []
        while True:  # UDP: one datagram per recv (keeps pymavlink's peer bookkeeping); serial: available bytes
            data = self.conn.recv(65536)
            if not data:
                break
            chunks.append(bytes(data) if not isinstance(data, bytes) else data)
            if len(chunks) >= 64:
                break
        return b"".join(chunks)

    def _read_tcp_server(self) -> bytes:
        """tcpin: accept one client; when it leaves, listen again (the link itself stays open)."""
        conn = self.conn
        if conn.port is None:
            try:
                client, _ = conn.listen.accept()
            except BlockingIOError:
                return b""
            client.setblocking(False)
            conn.port, conn.fd = client, client.fileno()
            self._set_reader(client.fileno())
            log.info("MAVLink %s: client connected", self.endpoint.text)
            return b""
        try:
            data = conn.port.recv(65536)
        except BlockingIOError:
            return b""
        except OSError:
            data = b""
        if not data:
            log.warning("MAVLink %s: client left; waiting for another", self.endpoint.text)
            conn.port.close()
            conn.port, conn.fd = None, conn.listen.fileno()
            self._set_reader(conn.listen.fileno())
        return data

    def _set_reader(self, fd: int) -> None:
        loop = asyncio.get_running_loop()
        if self._reader_fd is not None:
            loop.remove_reader(self._reader_fd)
        self._reader_fd = fd
        loop.add_reader(fd, self._readable)

    def _dispatch(self, msg: Any, arrived: float) -> None:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            self.stats.corrupt += 1
            self._report(f"corrupt data ({getattr(msg, 'reason', 'bad CRC')})")
            return
        s = self.settings
        if msg.get_srcSystem() != s.target_system or msg.get_srcComponent() != s.target_component:
            self.stats.foreign += 1
            if msg.get_srcSystem() != s.target_system:
                self._report(f"{kind} from system {msg.get_srcSystem()} ignored (target is {s.target_system})")
            return
        self.stats.received += 1
        self.on_message(msg, arrived)

    def _report(self, what: str) -> None:
        now = time.monotonic()
        if now - self._last_stats_log >= STATS_LOG_EVERY_S:
            self._last_stats_log = now
            st = self.stats
            log.warning("MAVLink %s: %s (totals: %d corrupt, %d foreign)", self.endpoint.text, what, st.corrupt,
                        st.foreign)

    # ------------------------------------------------------------------------------ write
    def send(self, msg: Any) -> bool:
        """Send ``msg`` now; False when the link is down (nothing is queued for later)."""
        if self.conn is None:
            return False
        try:
            self.conn.mav.send(msg)
        except OSError as exc:
            log.debug("MAVLink %s: send failed: %s", self.endpoint.text, exc)
            return False
        self.stats.sent += 1
        return True
