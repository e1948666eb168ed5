"""The UDP socket of a link, owned directly (not through pymavlink or an asyncio transport).

Bound without SO_REUSEADDR, so the port belongs to one process: a second one gets EADDRINUSE (pymavlink
sets SO_REUSEADDR, which lets a second process bind the port and take the vehicle's datagrams). A udpout
socket is connected, so the kernel delivers datagrams from that address only. Reading drains up to
``MAX_DATAGRAMS_PER_WAKE`` datagrams per wake-up of the event loop (an asyncio datagram transport reads
one per loop pass, and fell behind an in-process simulator at 20x). The kernel's default receive buffer
is kept on purpose: a larger one only lets a backlog of stale positions grow when the loop falls behind.
"""

from __future__ import annotations

import asyncio
import socket

from koopguide.mavlink.endpoint import UDP_IN, Endpoint

MAX_DATAGRAMS_PER_WAKE = 64
MAX_DATAGRAM_BYTES = 65535


async def open_udp(ep: Endpoint) -> socket.socket:
    """A non-blocking UDP socket bound (udpin) or connected (udpout) to the endpoint; OSError if not."""
    infos = await asyncio.get_running_loop().getaddrinfo(ep.host, ep.port, type=socket.SOCK_DGRAM)
    family, kind, proto, _, address = infos[0]
    sock = socket.socket(family, kind, proto)
    try:
        sock.setblocking(False)
        if ep.kind == UDP_IN:
            sock.bind(address)
        else:
            sock.connect(address)
    except OSError:
        sock.close()
        raise
    return sock
