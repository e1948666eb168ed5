"""MAVLink 2 message signing: the key file, and the check of incoming signatures.

MAVLink 2 signing (mavlink.io "Message Signing"): a signed frame carries a 13-byte block after the CRC,
``link_id`` (1 byte), ``timestamp`` (6 bytes, little-endian, units of 10 us since 2015-01-01 00:00 UTC)
and ``signature`` (6 bytes) = the first 48 bits of SHA-256(secret_key + header + payload + CRC +
link_id + timestamp). A receiver accepts a frame only if

* the signature matches (checked first, so a forged frame cannot touch the replay state below),
* its timestamp is newer than the last one accepted on the same stream (link_id, system, component) -
  the replay window - and
* for a stream not seen before, the timestamp is at most one minute behind the receiver's own clock.

pymavlink's own check records the timestamp of a stream before it verifies the signature, so one forged
frame with a far-future timestamp would lock the real sender out; that is why the check is done here,
with pymavlink used for framing only. Outgoing frames are signed by pymavlink's encoder
(``signing.sign_outgoing``), with the timestamp kept at or ahead of the wall clock.

Key file (``--signing-key FILE``): either exactly 32 raw bytes, or 64 hexadecimal characters (surrounding
whitespace ignored). A MAVProxy passphrase becomes such a file with
``printf %s 'PASSPHRASE' | sha256sum | cut -c1-64 > FILE`` (MAVProxy's key is SHA-256 of the passphrase).
"""

from __future__ import annotations

import enum
import hashlib
import hmac
import logging
import stat
import string
import time
from dataclasses import dataclass, field
from pathlib import Path

from koopguide.base.flags import Flag

log = logging.getLogger(__name__)

KEY_BYTES = 32
SIGNATURE_BLOCK_BYTES = 13  # link_id (1) + timestamp (6) + signature (6)
MAVLINK2_MARKER = 0xFD
IFLAG_SIGNED = 0x01
HEADER_BYTES = 10  # MAVLink 2 header
CRC_BYTES = 2
EPOCH_2015_UNIX_S = 1420070400  # 2015-01-01 00:00:00 UTC
TICKS_PER_S = 100_000  # signing timestamps count 10 us ticks
NEW_STREAM_MAX_AGE_TICKS = 60 * TICKS_PER_S  # a new stream may start at most one minute behind our clock

#: ``--signing-key FILE`` of ``koopguide run`` and ``koopguide sitl``: sets ``mavlink.signing_key`` of either config.
SIGNING_KEY_FLAG = Flag(
    "--signing-key",
    "mavlink.signing_key",
    str,
    "MAVLink 2 signing key: 32 raw bytes or 64 hex characters (docs/mavlink.md)",
    metavar="FILE",
)


class SigningKeyError(ValueError):
    """A signing key file that cannot be used; the message names the file and what is wrong."""


@dataclass(frozen=True)
class SigningKey:
    secret: bytes = field(repr=False)  # the 32-byte shared secret [-]
    source: str  # where it came from (a file path), for messages

    def __post_init__(self) -> None:
        if len(self.secret) != KEY_BYTES:
            raise SigningKeyError(f"signing key {self.source}: {len(self.secret)} bytes, expected {KEY_BYTES}")

    @classmethod
    def load(cls, path: str | Path) -> SigningKey:
        """Read a key file: 32 raw bytes or 64 hex characters; SigningKeyError otherwise."""
        path = Path(path)
        try:
            data = path.read_bytes()
            mode = path.stat().st_mode
        except OSError as exc:
            raise SigningKeyError(f"signing key {path}: cannot read ({exc.strerror or exc})") from None
        text = data.strip()
        if len(text) == 2 * KEY_BYTES and all(chr(c) in string.hexdigits for c in text):
            key = cls(bytes.fromhex(text.decode("ascii")), str(path))
        elif len(data) == KEY_BYTES:
            key = cls(data, str(path))
        else:
            raise SigningKeyError(
                f"signing key {path}: {len(data)} bytes; expected 32 raw bytes or 64 hexadecimal characters"
            )
        if mode & (stat.S_IRWXG | stat.S_IRWXO):
            log.warning("signing key %s is readable by other users (mode %o); chmod 600 it", path, mode & 0o777)
        return key

    @property
    def fingerprint(self) -> str:
        """First 8 hex digits of SHA-256(secret): names a key in logs without revealing it."""
        return hashlib.sha256(self.secret).hexdigest()[:8]


def timestamp_now() -> int:
    """The signing clock now: 10 us ticks since 2015-01-01 UTC."""
    return max(0, int((time.time() - EPOCH_2015_UNIX_S) * TICKS_PER_S))


class Verdict(enum.Enum):
    OK = "ok"
    UNSIGNED = "unsigned"  # no signature block (or MAVLink 1)
    BAD_SIGNATURE = "bad signature"  # wrong key, or altered in transit
    REPLAY = "replayed"  # timestamp not newer than the stream's last accepted one
    STALE = "stale"  # a new stream more than a minute behind our clock


def signature(secret: bytes, frame: bytes | bytearray) -> bytes:
    """The 6-byte signature of a frame whose last 6 bytes are (to be) the signature."""
    return hashlib.sha256(secret + bytes(frame[:-6])).digest()[:6]


class SignatureCheck:
    """Checks the signature block of incoming frames with one key; holds the replay window of a link."""

    def __init__(self, key: SigningKey) -> None:
        self.key = key
        self.stream_timestamps: dict[tuple[int, int, int], int] = {}  # (link_id, system, component) -> ticks
        self.clock = timestamp_now()  # the newest timestamp seen or sent [10 us ticks]

    def verify(self, frame: bytes | bytearray) -> Verdict:
        """Judge one complete frame (header to signature) and, if it is good, advance its stream."""
        if (
            len(frame) < HEADER_BYTES + CRC_BYTES + SIGNATURE_BLOCK_BYTES
            or frame[0] != MAVLINK2_MARKER
            or not frame[2] & IFLAG_SIGNED
            or len(frame) != HEADER_BYTES + frame[1] + CRC_BYTES + SIGNATURE_BLOCK_BYTES
        ):
            return Verdict.UNSIGNED
        if not hmac.compare_digest(signature(self.key.secret, frame), bytes(frame[-6:])):
            return Verdict.BAD_SIGNATURE
        link_id = frame[-SIGNATURE_BLOCK_BYTES]
        stamp = int.from_bytes(frame[-12:-6], "little")
        stream = (link_id, frame[5], frame[6])
        last = self.stream_timestamps.get(stream)
        if last is not None:
            if stamp <= last:
                return Verdict.REPLAY
        elif stamp + NEW_STREAM_MAX_AGE_TICKS < max(self.clock, timestamp_now()):
            return Verdict.STALE
        self.stream_timestamps[stream] = stamp
        self.clock = max(self.clock, stamp)
        return Verdict.OK


def configure_encoder(mav: object, key: SigningKey, link_id: int) -> None:
    """Make a pymavlink MAVLink encoder sign what it sends (see :func:`advance_clock` before each send)."""
    signing = mav.signing  # type: ignore[attr-defined]
    signing.secret_key = key.secret
    signing.sign_outgoing = True
    signing.link_id = link_id
    signing.timestamp = timestamp_now()


def advance_clock(mav: object) -> None:
    """Keep an encoder's signing timestamp at or ahead of the wall clock (monotonic: pymavlink adds 1 per frame)."""
    signing = mav.signing  # type: ignore[attr-defined]
    signing.timestamp = max(signing.timestamp, timestamp_now())
