"""Bytes in, trusted messages out: one parser per source, signature checks, and the link's counters.

Every source of bytes (a UDP peer address, a TCP connection, a serial device) gets its own pymavlink
parser, so one sender's garbage - say a MAVLink 2 header that claims a 255-byte payload - can only
swallow that sender's own frames. A UDP datagram is parsed from a clean state: a frame never spans
datagrams, so the unfinished tail of an earlier one is dropped (and counted) instead of eating the next.
Parsers are kept for the ``max_sources`` most recently heard sources (least recently heard dropped
first), so a flood from many addresses costs bounded memory. With a signing key, only frames with a
good signature pass (see :mod:`koopguide.mavlink.signing`). Nothing here raises on bad input: every
dropped byte or frame is counted in :class:`LinkStats`.
"""

from __future__ import annotations

import logging
import struct
from collections import OrderedDict
from collections.abc import Hashable
from dataclasses import dataclass
from typing import Any

from koopguide.mavlink.signing import SignatureCheck, Verdict
from koopguide.mavlink.wire import mavlink, new_decoder

log = logging.getLogger(__name__)

# What pymavlink's decoder may raise on malformed input even with robust parsing on (found by fuzzing).
DECODE_ERRORS = (mavlink.MAVError, struct.error, ValueError, IndexError, TypeError, UnicodeDecodeError)


@dataclass
class LinkStats:
    """Counters of one link since it was opened (all counts of messages/frames unless named bytes)."""

    received: int = 0  # messages accepted and handed on
    sent: int = 0  # messages framed and sent (to every peer: counted once)
    bytes_in: int = 0  # bytes read [B]
    bytes_out: int = 0  # bytes written [B]
    garbage_bytes: int = 0  # bytes that were not valid MAVLink (noise, bad CRC, truncated frames) [B]
    corrupt: int = 0  # frames or byte runs rejected by the decoder
    unknown: int = 0  # frames with a message id outside the ardupilotmega dialect
    foreign: int = 0  # valid messages from a system/component other than the one this link serves
    unsigned: int = 0  # signing on: frames without a signature, dropped
    bad_signature: int = 0  # signing on: wrong signature, replayed or stale timestamp, dropped
    before_heartbeat: int = 0  # the vehicle's ids before an autopilot HEARTBEAT located it (listening), dropped
    wrong_source: int = 0  # the vehicle's ids from an address other than the vehicle's (pinned) one, dropped
    source_changes: int = 0  # the vehicle's address changed (a new address took over)
    peers_dropped: int = 0  # listening endpoints: peers no longer sent to (the peer bound was reached)
    send_errors: int = 0  # transport errors on sending (e.g. nobody listening on a udpout port)
    dropped_out: int = 0  # messages not sent because the other end stopped reading (TCP, serial)
    reconnects: int = 0  # stream links (tcp client, serial) reopened after a loss

    #: The counters a guidance status carries (docs/zenoh.md, ``link``).
    STATUS_COUNTERS = (
        "received",
        "foreign",
        "corrupt",
        "sent",
        "reconnects",
        "unsigned",
        "bad_signature",
        "wrong_source",
        "source_changes",
    )

    def status_counters(self) -> dict[str, int]:
        return {name: getattr(self, name) for name in self.STATUS_COUNTERS}


class Intake:
    """Parses bytes per source; returns the messages that are well-formed (and well-signed)."""

    def __init__(self, stats: LinkStats, check: SignatureCheck | None, max_sources: int) -> None:
        self.stats = stats
        self.check = check
        self.max_sources = max_sources
        self._parsers: OrderedDict[Hashable, Any] = OrderedDict()

    def feed(self, source: Hashable, data: bytes, datagram: bool) -> list[Any]:
        """Parse ``data`` from ``source``; never raises. ``datagram``: a UDP datagram (parsed afresh)."""
        stats = self.stats
        stats.bytes_in += len(data)
        parser = self._parser(source)
        if datagram and parser.buf_len() > 0:  # the tail of a truncated frame in an earlier datagram
            stats.corrupt += 1
            stats.garbage_bytes += parser.buf_len()
            parser = self._parser(source, fresh=True)
        try:
            messages = parser.parse_buffer(data) or []
        except DECODE_ERRORS as exc:
            stats.corrupt += 1
            stats.garbage_bytes += len(data)
            log.debug("undecodable bytes from %s dropped (%s)", source, exc)
            self._parser(source, fresh=True)
            return []
        return [msg for msg in messages if self._trusted(msg)]

    def forget(self, source: Hashable) -> None:
        """Drop the parser of a source that went away (a closed TCP connection)."""
        self._parsers.pop(source, None)

    @property
    def sources(self) -> int:
        return len(self._parsers)

    def _parser(self, source: Hashable, fresh: bool = False) -> Any:
        parser = None if fresh else self._parsers.get(source)
        if parser is None:
            parser = new_decoder()
            self._parsers[source] = parser
            while len(self._parsers) > self.max_sources:
                self._parsers.popitem(last=False)
        self._parsers.move_to_end(source)
        return parser

    def _trusted(self, msg: Any) -> bool:
        stats = self.stats
        kind = msg.get_type()
        if kind == "BAD_DATA":
            stats.corrupt += 1
            stats.garbage_bytes += len(msg.data)
            return False
        if kind.startswith("UNKNOWN_"):  # no CRC extra known for the id: cannot be checked, ignored
            stats.unknown += 1
            return False
        if self.check is None:
            return True
        verdict = self.check.verify(msg.get_msgbuf())
        if verdict is Verdict.OK:
            msg._signed = True  # pymavlink's own flag, for get_signed()
            msg._link_id = msg.get_msgbuf()[-13]
            return True
        if verdict is Verdict.UNSIGNED:
            stats.unsigned += 1
        else:
            stats.bad_signature += 1
        log.debug("%s from %d/%d dropped: %s", kind, msg.get_srcSystem(), msg.get_srcComponent(), verdict.value)
        return False
