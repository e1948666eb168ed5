"""The simulator's MAVLink links: the shared transport (koopguide.mavlink) set up as an autopilot's.

Endpoint strings are the ones ArduPilot SITL and MAVProxy users write (:mod:`koopguide.mavlink.endpoint`):
``udpout:HOST:PORT`` (the default, to a GCS on 14550), ``udpin:``/``udp:`` (answers the most recent peers
that sent valid MAVLink), ``tcpin:`` (any number of clients), ``tcp:``, or a serial device. Each link frames
messages as every boat it serves (system id = boat, component MAV_COMP_ID_AUTOPILOT1), with its own
sequence numbers. With a signing key it behaves as ArduPilot does once SETUP_SIGNING has set one: it signs
everything and drops unsigned or badly signed frames (counted in ``Link.stats``).
"""

from __future__ import annotations

from koopguide.mavlink.endpoint import Endpoint
from koopguide.mavlink.link import Link, MessageHandler
from koopguide.mavlink.link_settings import LinkSettings
from koopguide.mavlink.signing import SigningKey
from koopguide.mavlink.wire import mavlink

__all__ = ["Link", "open_link"]

MAX_UDP_PEERS = 8  # udpin: answer at most this many ground stations (the most recently heard)


async def open_link(
    endpoint: Endpoint,
    systems: tuple[int, ...],
    key: SigningKey | None,
    link_id: int,
    on_message: MessageHandler,
) -> Link:
    """Open one endpoint serving ``systems``; EndpointError naming it when it cannot be opened."""
    settings = LinkSettings(
        endpoint=endpoint,
        sources=tuple((sysid, mavlink.MAV_COMP_ID_AUTOPILOT1) for sysid in systems),
        signing_key=key,
        link_id=link_id % 256,
        max_peers=MAX_UDP_PEERS,
        retry_first_open=False,
    )
    return await Link.create(settings, on_message)
