"""The MAVLink 2 wire format: the pinned dialect, decoders and encoders.

The ardupilotmega MAVLink 2 module is imported directly, so nothing depends on pymavlink's global
dialect switch (``mavutil.set_dialect``) or on the ``MAVLINK20`` environment variable being set before
the first import. pymavlink objects are not thread-safe: every decoder and encoder belongs to one link,
used from its event loop's thread only.
"""

from __future__ import annotations

from typing import Any, Protocol

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from koopguide.mavlink.signing import SigningKey, advance_clock, configure_encoder

__all__ = ["Encoder", "FrameSink", "mavlink", "new_decoder"]


def new_decoder() -> mavlink.MAVLink:
    """A MAVLink 2 decoder that reports bad bytes as BAD_DATA instead of raising, and checks no signature
    (signatures are checked by :class:`koopguide.mavlink.signing.SignatureCheck`)."""
    decoder = mavlink.MAVLink(None, 0, 0)
    decoder.robust_parsing = True
    return decoder


class FrameSink(Protocol):
    def transmit(self, frame: bytes) -> None: ...


class _SinkFile:
    """The file-like object pymavlink's encoder writes each framed message to."""

    def __init__(self, sink: FrameSink) -> None:
        self.sink = sink

    def write(self, frame: bytes) -> None:
        self.sink.transmit(bytes(frame))


class Encoder(mavlink.MAVLink):
    """Frames messages as (system, component) with its own sequence number; signs them if given a key.

    Use it like pymavlink's MAVLink object: ``encoder.send(msg)`` or ``encoder.heartbeat_send(...)``.
    """

    def __init__(self, sink: FrameSink, system: int, component: int, key: SigningKey | None, link_id: int) -> None:
        super().__init__(_SinkFile(sink), srcSystem=system, srcComponent=component)
        if key is not None:
            configure_encoder(self, key, link_id)

    def send(self, mavmsg: Any, force_mavlink1: bool = False) -> None:
        if self.signing.sign_outgoing:
            advance_clock(self)
        super().send(mavmsg, force_mavlink1=False)
