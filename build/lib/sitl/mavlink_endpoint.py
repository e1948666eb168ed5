"""MAVLink links of the simulator: endpoint strings, asyncio transports, framing and counters.

Endpoint strings are the ones ArduPilot SITL and MAVProxy users write:
  udpout:HOST:PORT   send to HOST:PORT (and accept the replies) - the default, to a GCS on 14550
  udpin:HOST:PORT    bind HOST:PORT, reply to every peer that has sent (``udp:`` is the same)
  tcpin:HOST:PORT    listen; any number of clients, each gets every message
  tcp:HOST:PORT      connect to a listening ground station
Port 0 on udpin/tcpin binds a free port (``Link.local_address`` tells which).

MAVLink 2 framing and the ardupilotmega dialect come from pymavlink's generated v2.0 module, imported
directly (no global dialect switch). Each link is owned by the event loop thread: one decoder per peer,
one encoder (with its own sequence number) per boat. Bytes that are not valid MAVLink are dropped and
counted in ``LinkStats``; they never raise.
"""

from __future__ import annotations

import asyncio
import logging
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

log = logging.getLogger(__name__)

KINDS = ("udpout", "udpin", "udp", "tcpin", "tcp")
MAX_TCP_BACKLOG_BYTES = 1 << 20  # a TCP client that stops reading loses messages beyond this


class EndpointError(ValueError):
    """An endpoint string is malformed or cannot be opened; the message names the endpoint."""


@dataclass(frozen=True)
class Endpoint:
    kind: str  # one of KINDS ("udp" is normalised to "udpin")
    host: str
    port: int

    @classmethod
    def parse(cls, text: str) -> Endpoint:
        """Parse ``kind:host:port``; raises EndpointError naming the string and what is wrong."""
        parts = text.split(":")
        if len(parts) != 3 or parts[0] not in KINDS:
            raise EndpointError(
                f"MAVLink endpoint {text!r}: expected KIND:HOST:PORT with KIND one of {', '.join(KINDS)} "
                "(serial devices are not supported by the simulator)"
            )
        kind, host, port_text = parts
        try:
            port = int(port_text)
        except ValueError:
            raise EndpointError(f"MAVLink endpoint {text!r}: port {port_text!r} is not a number") from None
        if not 0 <= port <= 65535 or (port == 0 and kind in ("udpout", "tcp")):
            raise EndpointError(f"MAVLink endpoint {text!r}: port {port} is out of range")
        if not host:
            raise EndpointError(f"MAVLink endpoint {text!r}: host is empty")
        return cls("udpin" if kind == "udp" else kind, host, port)

    def with_port_offset(self, offset: int) -> Endpoint:
        if offset == 0 or self.port == 0:
            return self
        port = self.port + offset
        if port > 65535:
            raise EndpointError(f"MAVLink endpoint {self}: port + {offset} exceeds 65535")
        return Endpoint(self.kind, self.host, port)

    def __str__(self) -> str:
        return f"{self.kind}:{self.host}:{self.port}"


@dataclass
class LinkStats:
    bytes_in: int = 0
    bytes_out: int = 0
    messages_in: int = 0
    messages_out: int = 0
    garbage_bytes: int = 0  # bytes dropped because they were not valid MAVLink (bad CRC, noise)
    bad_messages: int = 0  # frames or byte runs rejected by the decoder
    unknown_messages: int = 0  # frames with a message id outside the ardupilotmega dialect, ignored
    send_errors: int = 0  # transport errors (e.g. nobody listening on a udpout port)
    dropped_out: int = 0  # messages not sent because a TCP client stopped reading


def new_decoder() -> mavlink.MAVLink:
    """A MAVLink 2 decoder that reports bad bytes as BAD_DATA instead of raising."""
    decoder = mavlink.MAVLink(None, 0, 0)
    decoder.robust_parsing = True
    return decoder


MessageHandler = Callable[["Link", Any], None]


class _Peer:
    """One source of bytes (a UDP link or a TCP connection) and its decoder state."""

    def __init__(self, link: Link, transport: asyncio.BaseTransport | None):
        self.link = link
        self.transport = transport
        self.decoder = new_decoder()

    def feed(self, data: bytes, datagram: bool = False) -> None:
        """Decode bytes; a datagram starts afresh (a frame never spans UDP datagrams)."""
        link = self.link
        link.stats.bytes_in += len(data)
        if datagram:
            leftover = self.decoder.buf_len()
            if leftover > 0:  # the tail of a truncated frame in an earlier datagram
                link.stats.bad_messages += 1
                link.stats.garbage_bytes += leftover
                self.decoder = new_decoder()
        try:
            messages = self.decoder.parse_buffer(data) or []
        except (mavlink.MAVError, struct.error, ValueError, IndexError) as exc:
            link.stats.bad_messages += 1
            link.stats.garbage_bytes += len(data)
            log.debug("%s: undecodable bytes dropped (%s)", link.endpoint, exc)
            self.decoder = new_decoder()
            return
        for msg in messages:
            kind = msg.get_type()
            if kind == "BAD_DATA":
                link.stats.bad_messages += 1
                link.stats.garbage_bytes += len(msg.data)
                continue
            if kind.startswith("UNKNOWN_"):  # an id outside the dialect: no CRC check possible, ignored
                link.stats.unknown_messages += 1
                continue
            link.stats.messages_in += 1
            link.on_message(link, msg)


class _UdpProtocol(asyncio.DatagramProtocol):
    def __init__(self, link: Link):
        self.link = link

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        link = self.link
        if link.endpoint.kind == "udpin":
            link._udp_peers.add(addr)
        link._udp_peer.feed(data, datagram=True)

    def error_received(self, exc: Exception) -> None:
        self.link.stats.send_errors += 1


class _TcpProtocol(asyncio.Protocol):
    def __init__(self, link: Link):
        self.link = link
        self.peer: _Peer | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.peer = _Peer(self.link, transport)
        self.link._tcp_peers.append(self.peer)
        log.info("%s: client connected from %s", self.link.endpoint, transport.get_extra_info("peername"))

    def data_received(self, data: bytes) -> None:
        assert self.peer is not None
        self.peer.feed(data)

    def connection_lost(self, exc: Exception | None) -> None:
        if self.peer in self.link._tcp_peers:
            self.link._tcp_peers.remove(self.peer)
        log.info("%s: client disconnected", self.link.endpoint)


class _Writer:
    """File-like sink that pymavlink's encoder writes framed messages to."""

    def __init__(self, link: Link):
        self.link = link

    def write(self, buf: bytes) -> None:
        self.link.transmit(buf)


class Link:
    """One MAVLink endpoint, serving one or more boats (system ids)."""

    def __init__(self, endpoint: Endpoint, systems: tuple[int, ...], on_message: MessageHandler):
        self.endpoint = endpoint
        self.systems = systems
        self.on_message = on_message
        self.stats = LinkStats()
        self.encoders = {
            sysid: mavlink.MAVLink(
                _Writer(self), srcSystem=sysid, srcComponent=mavlink.MAV_COMP_ID_AUTOPILOT1
            )
            for sysid in systems
        }
        self._udp_transport: asyncio.DatagramTransport | None = None
        self._udp_peer = _Peer(self, None)
        self._udp_peers: set[tuple[str, int]] = set()
        self._tcp_peers: list[_Peer] = []
        self._server: asyncio.Server | None = None
        self.local_address: tuple[str, int] = (endpoint.host, endpoint.port)

    @classmethod
    async def create(cls, endpoint: Endpoint, systems: tuple[int, ...], on_message: MessageHandler) -> Link:
        """Open the endpoint; raises EndpointError naming it when that fails."""
        link = cls(endpoint, systems, on_message)
        loop = asyncio.get_running_loop()
        try:
            if endpoint.kind == "udpout":
                transport, _ = await loop.create_datagram_endpoint(
                    lambda: _UdpProtocol(link), remote_addr=(endpoint.host, endpoint.port)
                )
                link._udp_transport = transport
                link.local_address = transport.get_extra_info("sockname")[:2]
            elif endpoint.kind == "udpin":
                transport, _ = await loop.create_datagram_endpoint(
                    lambda: _UdpProtocol(link), local_addr=(endpoint.host, endpoint.port)
                )
                link._udp_transport = transport
                link.local_address = transport.get_extra_info("sockname")[:2]
            elif endpoint.kind == "tcpin":
                link._server = await loop.create_server(
                    lambda: _TcpProtocol(link), endpoint.host, endpoint.port, reuse_address=True
                )
                link.local_address = link._server.sockets[0].getsockname()[:2]
            else:
                await loop.create_connection(lambda: _TcpProtocol(link), endpoint.host, endpoint.port)
        except OSError as exc:
            raise EndpointError(f"MAVLink endpoint {endpoint}: cannot open ({exc.strerror or exc})") from exc
        log.info("MAVLink %s open for system(s) %s", endpoint, ",".join(map(str, systems)))
        return link

    def transmit(self, buf: bytes) -> None:
        """Send one framed message to every peer of this link."""
        self.stats.messages_out += 1
        transport = self._udp_transport
        if transport is not None:
            if self.endpoint.kind == "udpout":
                transport.sendto(buf)
            else:
                for addr in self._udp_peers:
                    transport.sendto(buf, addr)
            self.stats.bytes_out += len(buf)
            return
        for peer in self._tcp_peers:
            writer = peer.transport
            assert isinstance(writer, asyncio.WriteTransport)
            if writer.is_closing():
                continue
            if writer.get_write_buffer_size() > MAX_TCP_BACKLOG_BYTES:
                self.stats.dropped_out += 1
                continue
            writer.write(buf)
            self.stats.bytes_out += len(buf)

    @property
    def connected_clients(self) -> int:
        """Peers that can hear this link now (udpout always counts as one)."""
        if self.endpoint.kind == "udpout":
            return 1
        if self.endpoint.kind == "udpin":
            return len(self._udp_peers)
        return len(self._tcp_peers)

    async def close(self) -> None:
        if self._udp_transport is not None:
            self._udp_transport.close()
        for peer in list(self._tcp_peers):
            if peer.transport is not None:
                peer.transport.close()
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()
