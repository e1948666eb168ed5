"""Link: the one owner of a MAVLink connection, on the running asyncio event loop.

It opens an :class:`~koopguide.mavlink.endpoint.Endpoint` (UDP in/out, TCP server/client, serial), parses
what arrives per source (:mod:`koopguide.mavlink.intake`), hands trusted messages to ``on_message``, and
frames what is sent with one :class:`~koopguide.mavlink.wire.Encoder` per own (system, component) id.
Both the guidance service and the simulator use it; everything runs on the loop's thread.

Trust (docs/mavlink.md "Security"): with a signing key only correctly signed frames pass and all that
is sent is signed. With ``vehicle`` set (the service), other (system, component) ids are foreign; a
listening endpoint locks onto the address of the vehicle's first autopilot HEARTBEAT, drops the vehicle's
ids from other addresses (``wrong_source``) until the pinned one is silent for ``repin_after_s`` or a
signed HEARTBEAT arrives, and sends to the pinned address only. Without ``vehicle`` (the simulator) udpin
answers the ``max_peers`` most recent addresses that sent trusted messages. UDP ports are exclusive.
A stream link (tcp client, serial) that closes is reopened with exponential back-off.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import os
import socket
import time
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any

from koopguide.mavlink.datagram import MAX_DATAGRAM_BYTES, MAX_DATAGRAMS_PER_WAKE, open_udp
from koopguide.mavlink.endpoint import SERIAL, TCP_IN, TCP_OUT, UDP_IN, UDP_OUT, Endpoint, EndpointError, PortInUseError
from koopguide.mavlink.intake import Intake, LinkStats
from koopguide.mavlink.link_settings import LinkSettings
from koopguide.mavlink.rover import is_autopilot_heartbeat
from koopguide.mavlink.serial_port import open_serial
from koopguide.mavlink.signing import SignatureCheck
from koopguide.mavlink.wire import Encoder

log = logging.getLogger(__name__)

MessageHandler = Callable[["Link", Any, float], None]  # (link, message, arrival time.perf_counter() [s])
REPORT_EVERY_S = 10.0  # dropped-message warnings of one link at most this often [s]
MAX_TCP_BACKLOG_BYTES = 1 << 20  # a TCP client that stops reading loses messages beyond this [B]
SERIAL_READ_BYTES = 4096
_warned_unsigned = False  # the "signing is off" warning is given once per process


class Link:
    """Build with :meth:`create`; ``send`` from the loop's thread; ``await close()`` when done."""

    def __init__(self, settings: LinkSettings, on_message: MessageHandler) -> None:
        self.settings = settings
        self.endpoint = settings.endpoint
        self.on_message = on_message
        self.stats = LinkStats()
        key = settings.signing_key
        self.intake = Intake(self.stats, SignatureCheck(key) if key else None, settings.max_parsers)
        self.encoders = {
            system: Encoder(self, system, comp, key, settings.link_id) for system, comp in settings.sources
        }
        self.local_address: tuple[str, int] = (self.endpoint.host, self.endpoint.port)
        self.pinned: Hashable | None = None  # the vehicle's address (listening endpoints with ``vehicle``)
        self._pinned_heard = -float("inf")
        self._peers: OrderedDict[Hashable, None] = OrderedDict()  # udpin without ``vehicle``: who we answer
        self._udp: socket.socket | None = None
        self._server: asyncio.Server | None = None
        self._clients: dict[Hashable, asyncio.Transport] = {}  # tcpin: connections; tcp: the one
        self._serial_fd: int | None = None
        self._reopen: asyncio.Task | None = None
        self._closed = False
        self._last_report = -float("inf")

    @classmethod
    async def create(cls, settings: LinkSettings, on_message: MessageHandler) -> Link:
        """Open the endpoint; EndpointError (one line, naming it) when that fails. A stream endpoint
        with ``retry_first_open`` keeps trying in the background instead."""
        link = cls(settings, on_message)
        global _warned_unsigned
        key = settings.signing_key
        if key is not None:
            log.info("MAVLink %s: signing on (key %s from %s)", link.endpoint, key.fingerprint, key.source)
        elif not _warned_unsigned:
            _warned_unsigned = True
            log.warning("MAVLink signing is off: anyone who can reach %s is trusted (docs/mavlink.md)", link.endpoint)
        try:
            await link._open()
        except OSError as exc:
            if not (link.endpoint.stream and settings.retry_first_open):
                raise _open_error(link.endpoint, exc) from None
            log.warning("MAVLink %s: cannot open (%s); retrying", link.endpoint, exc.strerror or exc)
            link._schedule_reopen()
        return link

    # ------------------------------------------------------------------------------ open / close
    async def _open(self) -> None:
        loop = asyncio.get_running_loop()
        ep = self.endpoint
        if ep.kind in (UDP_IN, UDP_OUT):
            self._udp = await open_udp(ep)  # no SO_REUSEADDR: the port is ours alone
            self.local_address = self._udp.getsockname()[:2]
            loop.add_reader(self._udp.fileno(), self._udp_readable)
        elif ep.kind == TCP_IN:
            self._server = await loop.create_server(lambda: _Stream(self), ep.host, ep.port)
            self.local_address = self._server.sockets[0].getsockname()[:2]
        elif ep.kind == TCP_OUT:
            await loop.create_connection(lambda: _Stream(self), ep.host, ep.port)
        else:
            self._serial_fd = open_serial(ep)
            loop.add_reader(self._serial_fd, self._serial_readable)
        log.info("MAVLink %s open", ep.with_port(self.local_address[1]) if ep.listens else ep)

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
                log.info("MAVLink %s: reopen failed (%s); next try in %.1f s", self.endpoint, exc, delay)
            else:
                self.stats.reconnects += 1
                return

    def _lost(self, why: str) -> None:
        """A stream link closed: reopen it with back-off."""
        if self._closed:
            return
        log.warning("MAVLink %s lost (%s); reconnecting", self.endpoint, why)
        self._close_serial()
        self._schedule_reopen()

    def _close_serial(self) -> None:
        if self._serial_fd is not None:
            asyncio.get_running_loop().remove_reader(self._serial_fd)
            with contextlib.suppress(OSError):
                os.close(self._serial_fd)
            self._serial_fd = None

    async def close(self) -> None:
        """Close the endpoint (idempotent); the counters stay readable."""
        self._closed = True
        if self._reopen is not None:
            self._reopen.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._reopen
        if self._udp is not None:
            asyncio.get_running_loop().remove_reader(self._udp.fileno())
            self._udp.close()
            self._udp = None
        for transport in list(self._clients.values()):
            transport.close()
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()
        self._close_serial()

    # ------------------------------------------------------------------------------ read
    def received(self, source: Hashable, data: bytes, datagram: bool) -> None:
        """Bytes from one source: parse (per source), check, pin, hand trusted messages on."""
        arrived = time.perf_counter()
        for msg in self.intake.feed(source, data, datagram):
            self._deliver(source, msg, arrived)

    def _deliver(self, source: Hashable, msg: Any, arrived: float) -> None:
        s, st = self.settings, self.stats
        if s.vehicle is not None and (msg.get_srcSystem(), msg.get_srcComponent()) != s.vehicle:
            st.foreign += 1
            self._report(f"{msg.get_type()} from {msg.get_srcSystem()}/{msg.get_srcComponent()} ignored "
                         f"(the vehicle is {s.vehicle[0]}/{s.vehicle[1]})")  # fmt: skip
            return
        if self.endpoint.listens:
            if s.vehicle is not None:
                if source != self.pinned and not self._take_over(source, msg):
                    if self.pinned is None:
                        st.before_heartbeat += 1
                        return
                    st.wrong_source += 1
                    self._report(f"{msg.get_type()} as the vehicle from {_name(source)} dropped "
                                 f"(the vehicle is at {_name(self.pinned)})")  # fmt: skip
                    return
                self._pinned_heard = time.monotonic()
            elif self.endpoint.kind == UDP_IN:
                self._remember_peer(source)
        st.received += 1
        self.on_message(self, msg, arrived)

    def _take_over(self, source: Hashable, msg: Any) -> bool:
        """May ``source`` become the vehicle's address? Only with an autopilot HEARTBEAT, and only if no
        address is pinned, the pinned one went silent, or the HEARTBEAT is signed."""
        if not is_autopilot_heartbeat(msg):
            return False
        silent_s = time.monotonic() - self._pinned_heard
        if self.pinned is not None and not msg.get_signed() and silent_s < self.settings.repin_after_s:
            return False
        old, self.pinned = self.pinned, source
        if old is None:
            log.info("MAVLink %s: vehicle found at %s", self.endpoint, _name(source))
        else:
            self.stats.source_changes += 1
            log.warning(
                "MAVLink %s: the vehicle's address changed from %s to %s (%s)",
                self.endpoint,
                _name(old),
                _name(source),
                "signed" if msg.get_signed() else f"old one silent for {silent_s:.1f} s",
            )
        return True

    def _remember_peer(self, source: Hashable) -> None:
        if source in self._peers:
            self._peers.move_to_end(source)
            return
        self._peers[source] = None
        while len(self._peers) > self.settings.max_peers:
            self._peers.popitem(last=False)
            self.stats.peers_dropped += 1

    def _udp_readable(self) -> None:
        for _ in range(MAX_DATAGRAMS_PER_WAKE):
            if self._udp is None:
                return
            try:
                data, addr = self._udp.recvfrom(MAX_DATAGRAM_BYTES)
            except BlockingIOError:
                return
            except OSError:  # an ICMP error for an earlier send (udpout with nobody listening)
                self.stats.send_errors += 1
                continue
            self.received(addr[:2], data, datagram=True)

    def _serial_readable(self) -> None:
        try:
            data = os.read(self._serial_fd, SERIAL_READ_BYTES) if self._serial_fd is not None else b""
        except BlockingIOError:
            return
        except OSError as exc:
            self._lost(exc.strerror or str(exc))
            return
        if not data:
            self._lost("end of file")
            return
        self.received("serial", data, datagram=False)

    def _report(self, what: str) -> None:
        now = time.monotonic()
        if now - self._last_report >= REPORT_EVERY_S:
            self._last_report = now
            st = self.stats
            log.warning("MAVLink %s: %s (totals: %d foreign, %d wrong source, %d unsigned, %d bad signature, "
                        "%d corrupt)", self.endpoint, what, st.foreign, st.wrong_source, st.unsigned,
                        st.bad_signature, st.corrupt)  # fmt: skip

    # ------------------------------------------------------------------------------ write
    @property
    def peers(self) -> tuple[Hashable, ...]:
        """Where a message sent now goes (addresses, or TCP peer names)."""
        ep = self.endpoint
        if ep.kind == TCP_OUT:
            return tuple(self._clients)
        if ep.kind in (UDP_OUT, SERIAL):
            return (str(ep),) if self.connected else ()
        if self.settings.vehicle is not None:
            return (self.pinned,) if self.pinned is not None and self._reachable(self.pinned) else ()
        return tuple(self._peers) if ep.kind == UDP_IN else tuple(self._clients)

    @property
    def connected(self) -> bool:
        """The transport is open (UDP, serial) or connected (TCP)."""
        return self._udp is not None or self._serial_fd is not None or bool(self._clients)

    def _reachable(self, peer: Hashable) -> bool:
        return self.endpoint.kind == UDP_IN or peer in self._clients

    def send(self, msg: Any, system: int | None = None) -> bool:
        """Frame ``msg`` as our ``system`` (default: the first source) and send it now; False when there is
        nobody to send to (link down, vehicle not yet heard). Nothing is queued for later."""
        if not self.peers:
            return False
        encoder = self.encoders[system] if system is not None else next(iter(self.encoders.values()))
        encoder.send(msg)
        return True

    def transmit(self, frame: bytes) -> None:
        """Send one framed message to every peer (the encoders call this)."""
        peers = self.peers
        if not peers:
            return
        st = self.stats
        if self._udp is not None:
            for peer in peers:
                try:
                    if self.endpoint.kind == UDP_OUT:
                        self._udp.send(frame)
                    else:
                        self._udp.sendto(frame, peer)
                except BlockingIOError:
                    st.dropped_out += 1
                    continue
                except OSError:  # e.g. nobody listening on a udpout port (ICMP port unreachable)
                    st.send_errors += 1
                    continue
                st.bytes_out += len(frame)
        elif self._serial_fd is not None:
            try:
                written = os.write(self._serial_fd, frame)
            except BlockingIOError:
                written = 0
            except OSError as exc:
                st.send_errors += 1
                self._lost(exc.strerror or str(exc))
                return
            if written < len(frame):
                st.dropped_out += 1
            st.bytes_out += written
        else:
            for peer in peers:
                transport = self._clients.get(peer)
                if transport is None or transport.is_closing():
                    continue
                if transport.get_write_buffer_size() > MAX_TCP_BACKLOG_BYTES:
                    st.dropped_out += 1
                    continue
                transport.write(frame)
                st.bytes_out += len(frame)
        st.sent += 1


class _Stream(asyncio.Protocol):
    """One TCP connection (a tcpin client, or the tcp client link itself)."""

    def __init__(self, link: Link) -> None:
        self.link = link
        self.peer: Hashable = ("tcp", id(self))

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        name = transport.get_extra_info("peername")
        self.peer = tuple(name[:2]) if name else self.peer
        self.link._clients[self.peer] = transport
        log.info("MAVLink %s: connected to %s", self.link.endpoint, _name(self.peer))

    def data_received(self, data: bytes) -> None:
        self.link.received(self.peer, data, datagram=False)

    def connection_lost(self, exc: Exception | None) -> None:
        link = self.link
        link._clients.pop(self.peer, None)
        link.intake.forget(self.peer)
        if link.pinned == self.peer:
            link.pinned = None
        if link.endpoint.kind == TCP_OUT:
            link._lost(str(exc) if exc else "closed by the other end")
        else:
            log.info("MAVLink %s: %s disconnected", link.endpoint, _name(self.peer))


def _open_error(ep: Endpoint, exc: OSError) -> EndpointError:
    if exc.errno == errno.EADDRINUSE:
        return PortInUseError(
            f"MAVLink endpoint {ep}: port {ep.port} is already in use by another process (only one may own it)"
        )
    return EndpointError(f"MAVLink endpoint {ep}: cannot open ({exc.strerror or exc})")


def _name(source: Hashable) -> str:
    if isinstance(source, tuple) and len(source) == 2 and isinstance(source[1], int):
        return f"{source[0]}:{source[1]}"
    return str(source)
