"""The MAVLink intake under garbage: per-source parsers, datagrams parsed afresh, and fuzzing (hypothesis) of
the intake and of a service link's whole receive path."""

from __future__ import annotations

import os

from hypothesis import given, settings
from hypothesis import strategies as st

from koopguide.mavlink.endpoint import Endpoint
from koopguide.mavlink.intake import Intake, LinkStats
from koopguide.mavlink.link import Link
from koopguide.mavlink.link_settings import LinkSettings
from koopguide.mavlink.signing import SignatureCheck, SigningKey
from tests.support.mavlink_frames import encoder, frame, local_position, vehicle_heartbeat

KEY = SigningKey(bytes(range(1, 33)), "test")
HEADER_FLOOD = bytes([0xFD, 255, 0, 0, 0, 1, 1, 32, 0, 0])  # a MAVLink 2 header claiming a 255-byte payload
VALID = frame(encoder(), local_position(1000, 3.0, 4.0))


def intake(check: SignatureCheck | None = None, max_sources: int = 64) -> Intake:
    return Intake(LinkStats(), check, max_sources)


def test_header_garbage_from_one_source_does_not_blind_another_on_a_stream() -> None:
    taken = intake()
    vehicle = encoder()
    got = []
    for k in range(100):
        assert taken.feed("attacker", HEADER_FLOOD, datagram=False) == []  # never completes a frame
        got += taken.feed("vehicle", frame(vehicle, local_position(k, 1.0, 2.0)), datagram=False)
    assert len(got) == 100 and all(m.get_type() == "LOCAL_POSITION_NED" for m in got)


def test_a_truncated_frame_in_one_datagram_does_not_swallow_the_next() -> None:
    taken = intake()
    got = []
    for _ in range(100):
        got += taken.feed(("10.0.0.1", 5), HEADER_FLOOD, datagram=True)
        got += taken.feed(("10.0.0.1", 5), VALID, datagram=True)
    assert len(got) == 100
    assert taken.stats.corrupt >= 99 and taken.stats.garbage_bytes >= 99 * len(HEADER_FLOOD)


def test_parsers_are_kept_for_a_bounded_number_of_sources() -> None:
    taken = intake(max_sources=16)
    for port in range(10_000):
        taken.feed(("10.0.0.1", port), HEADER_FLOOD, datagram=True)
    assert taken.sources == 16


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=600), st.booleans())
def test_random_bytes_never_raise_and_never_blind_the_next_datagram(junk: bytes, datagram: bool) -> None:
    taken = intake()
    taken.feed("peer", junk, datagram=datagram)
    if not any(b in (0xFD, 0xFE) for b in junk):  # no frame can start anywhere: every byte is garbage
        assert taken.stats.garbage_bytes == len(junk) and taken.stats.received == 0
    got = taken.feed("peer", VALID, datagram=True)
    assert [m.get_type() for m in got] == ["LOCAL_POSITION_NED"] and (got[0].x, got[0].y) == (3.0, 4.0)
    assert taken.stats.bytes_in == len(junk) + len(VALID)


mutation = st.tuples(st.integers(0, 63), st.integers(0, 255), st.sampled_from(["flip", "cut", "insert"]))


@settings(max_examples=300, deadline=None)
@given(st.lists(mutation, min_size=1, max_size=4), st.booleans())
def test_mutated_signed_frames_are_never_accepted_and_never_raise(edits: list, datagram: bool) -> None:
    """Any change to a signed frame is caught: only the untouched original may pass."""
    mav = encoder(key=KEY)
    original = frame(mav, vehicle_heartbeat(mode=0))
    data = bytearray(original)
    for where, value, how in edits:
        i = where % (len(data) + 1)
        if how == "flip" and i < len(data):
            data[i] ^= value or 1
        elif how == "cut":
            del data[i:]
        else:
            data[i:i] = bytes([value])
    taken = intake(SignatureCheck(KEY))
    got = taken.feed("peer", bytes(data), datagram=datagram)
    assert all(bytes(m.get_msgbuf()) == original for m in got)
    if original not in bytes(data):  # noise around an intact frame is skipped; anything else is refused
        assert got == []
    assert [m.get_type() for m in taken.feed("peer", frame(mav, vehicle_heartbeat()), datagram=True)] == ["HEARTBEAT"]


def test_signed_intake_drops_and_counts_unsigned_and_foreign_keyed_frames() -> None:
    taken = intake(SignatureCheck(KEY))
    assert taken.feed("a", frame(encoder(), vehicle_heartbeat()), datagram=True) == []
    assert taken.feed("a", frame(encoder(key=SigningKey(os.urandom(32), "x")), vehicle_heartbeat()), True) == []
    good = taken.feed("a", frame(encoder(key=KEY), vehicle_heartbeat()), datagram=True)
    assert len(good) == 1 and good[0].get_signed()
    assert (taken.stats.unsigned, taken.stats.bad_signature) == (1, 1)


VEHICLE_ADDR, ATTACKER_ADDR = ("127.0.0.1", 40001), ("127.0.0.1", 40002)
step = st.tuples(
    st.sampled_from([VEHICLE_ADDR, ATTACKER_ADDR]),
    st.one_of(st.binary(max_size=300), st.just(HEADER_FLOOD), st.sampled_from(["position", "heartbeat"])),
    st.booleans(),
)


@settings(max_examples=200, deadline=None)
@given(st.lists(step, max_size=40))
def test_the_service_transport_never_raises_and_never_believes_another_address(steps: list) -> None:
    """Random bytes, header garbage and valid frames from two addresses into a service link: the vehicle's
    datagrams all arrive, nothing from the other address is believed, nothing raises."""
    got: list = []
    settings_ = LinkSettings(Endpoint.parse("udpin:127.0.0.1:0"), ((255, 191),), vehicle=(1, 1))
    link = Link(settings_, lambda _link, msg, _arrived: got.append(msg))
    real, fake = encoder(1, 1), encoder(1, 1)
    link.received(VEHICLE_ADDR, frame(real, vehicle_heartbeat()), datagram=True)
    sent_by_vehicle = 0
    for source, payload, stream in steps:
        mav = real if source == VEHICLE_ADDR else fake
        if payload == "position":
            x = 1.0 if source == VEHICLE_ADDR else 9.0
            data = frame(mav, local_position(0, x, x))
            sent_by_vehicle += source == VEHICLE_ADDR
        elif payload == "heartbeat":
            data = frame(mav, vehicle_heartbeat(mode=0 if source == VEHICLE_ADDR else 4))
        elif source == VEHICLE_ADDR:
            continue  # the vehicle itself sends no garbage in this test
        else:
            data = payload
        link.received(source, data, datagram=not stream or source == VEHICLE_ADDR)
    positions = [m for m in got if m.get_type() == "LOCAL_POSITION_NED"]
    assert len(positions) == sent_by_vehicle and all(m.x == 1.0 for m in positions)
    assert all(m.custom_mode == 0 for m in got if m.get_type() == "HEARTBEAT")
    assert link.pinned == VEHICLE_ADDR and link.stats.source_changes == 0
