"""The service's MAVLink link: the guidance configuration mapped onto the shared transport.

The transport itself - endpoint grammar, per-source parsing, signing, source pinning, reconnects - is
:mod:`koopguide.mavlink.link` (docs/mavlink.md). The service talks to one vehicle: it accepts messages
from ``target_system``/``target_component`` only, pins a listening endpoint to the vehicle's address, and
sends only to the vehicle.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from koopguide.guidance.settings import MavlinkSettings
from koopguide.mavlink.endpoint import Endpoint
from koopguide.mavlink.link import Link
from koopguide.mavlink.link_settings import LinkSettings
from koopguide.mavlink.signing import SigningKey

SERVICE_LINK_ID = 0  # the signing link id of what the service sends
MAX_SOURCES = 64  # per-address parsers kept on a listening endpoint


def link_settings(settings: MavlinkSettings) -> LinkSettings:
    """Parse the endpoint and read the signing key: EndpointError / SigningKeyError before anything opens."""
    return LinkSettings(
        endpoint=Endpoint.parse(settings.endpoint),
        sources=((settings.source_system, settings.source_component),),
        vehicle=(settings.target_system, settings.target_component),
        signing_key=SigningKey.load(settings.signing_key) if settings.signing_key is not None else None,
        link_id=SERVICE_LINK_ID,
        max_peers=1,
        max_parsers=MAX_SOURCES,
        repin_after_s=settings.link_timeout_s,
        reconnect_min_s=settings.reconnect_min_s,
        reconnect_max_s=settings.reconnect_max_s,
    )


async def open_link(settings: MavlinkSettings, on_message: Callable[[Any, float], None]) -> Link:
    """Open the vehicle link; ``on_message(msg, arrival time.perf_counter() [s])`` gets the vehicle's messages."""
    return await Link.create(link_settings(settings), lambda _link, msg, arrived: on_message(msg, arrived))
