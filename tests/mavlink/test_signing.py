"""MAVLink 2 signing: the key file, and the signature / replay-window check of incoming frames."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from koopguide.mavlink.signing import (
    NEW_STREAM_MAX_AGE_TICKS,
    SignatureCheck,
    SigningKey,
    SigningKeyError,
    Verdict,
    timestamp_now,
)
from koopguide.mavlink.wire import mavlink, new_decoder
from tests.support.mavlink_frames import encoder, frame, local_position, vehicle_heartbeat

KEY = SigningKey(bytes(range(32)), "test")


def test_key_files_hex_or_raw_are_read(tmp_path: Path) -> None:
    secret = os.urandom(32)
    hex_file = tmp_path / "k.hex"
    hex_file.write_text(secret.hex().upper() + "\n")
    raw_file = tmp_path / "k.bin"
    raw_file.write_bytes(secret)
    assert SigningKey.load(hex_file).secret == secret
    assert SigningKey.load(raw_file).secret == secret
    assert secret.hex() not in repr(SigningKey.load(hex_file))  # never printed


@pytest.mark.parametrize(
    ("content", "says"),
    [(b"abc\n", "4 bytes; expected 32 raw bytes or 64 hexadecimal"), (b"z" * 64, "64 bytes; expected 32")],
)
def test_bad_key_files_are_refused_in_one_line(tmp_path: Path, content: bytes, says: str) -> None:
    path = tmp_path / "bad.key"
    path.write_bytes(content)
    with pytest.raises(SigningKeyError, match=says) as err:
        SigningKey.load(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value) and isinstance(err.value, ValueError)
    with pytest.raises(SigningKeyError, match="cannot read"):
        SigningKey.load(tmp_path / "absent.key")


def test_good_frames_pass_once_and_replays_unsigned_and_foreign_keys_do_not() -> None:
    check = SignatureCheck(KEY)
    mav = encoder(key=KEY)
    first = frame(mav, vehicle_heartbeat())
    second = frame(mav, local_position(100, 1.0, 2.0))
    assert check.verify(first) is Verdict.OK
    assert check.verify(second) is Verdict.OK
    assert check.verify(first) is Verdict.REPLAY  # timestamp not newer than the stream's last
    assert check.verify(frame(encoder(), vehicle_heartbeat())) is Verdict.UNSIGNED
    other = SigningKey(os.urandom(32), "random")
    assert check.verify(frame(encoder(key=other), vehicle_heartbeat())) is Verdict.BAD_SIGNATURE
    altered = bytearray(frame(mav, local_position(200, 1.0, 2.0)))
    altered[12] ^= 0x01  # one payload bit
    assert check.verify(altered) is Verdict.BAD_SIGNATURE


def test_a_new_stream_more_than_a_minute_behind_is_stale() -> None:
    check = SignatureCheck(KEY)
    old = encoder(system=7, key=KEY)
    old.signing.timestamp = timestamp_now() - NEW_STREAM_MAX_AGE_TICKS - 100_000  # 61 s ago
    assert check.verify(frame(old, vehicle_heartbeat())) is Verdict.STALE
    recent = encoder(system=8, key=KEY)
    recent.signing.timestamp = timestamp_now() - NEW_STREAM_MAX_AGE_TICKS // 2  # 30 s ago: fine
    assert check.verify(frame(recent, vehicle_heartbeat())) is Verdict.OK


def test_a_forged_far_future_timestamp_does_not_lock_the_real_sender_out() -> None:
    """pymavlink records a stream's timestamp before checking the signature; this check does not."""
    check = SignatureCheck(KEY)
    real = encoder(key=KEY)
    assert check.verify(frame(real, vehicle_heartbeat())) is Verdict.OK
    forger = encoder(key=SigningKey(os.urandom(32), "forger"))
    forger.signing.timestamp = timestamp_now() + 10**12  # years ahead, same (link, system, component)
    assert check.verify(frame(forger, vehicle_heartbeat())) is Verdict.BAD_SIGNATURE
    assert check.verify(frame(real, local_position(1, 0.0, 0.0))) is Verdict.OK


def test_our_signatures_are_the_ones_pymavlink_and_ardupilot_expect() -> None:
    """pymavlink's own verifier (the reference MAVProxy uses) accepts what our encoder signs."""
    decoder = new_decoder()
    decoder.signing.secret_key = KEY.secret
    mav = encoder(key=KEY, link_id=3)
    (msg,) = decoder.parse_buffer(frame(mav, local_position(5, 1.5, -2.5)))
    assert msg.get_type() == "LOCAL_POSITION_NED" and msg.get_signed() and msg.get_link_id() == 3
    assert (msg.x, msg.y) == (1.5, -2.5)
    decoder.signing.secret_key = os.urandom(32)
    (bad,) = decoder.parse_buffer(frame(mav, local_position(6, 1.5, -2.5)))
    assert bad.get_type() == "BAD_DATA" and decoder.signing.badsig_count == 1
    assert mavlink.MAVLINK_IFLAG_SIGNED == 1
