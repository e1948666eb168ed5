"""The status schema, the zenoh configuration and StatusBus, with real zenoh sessions on loopback.

Every test uses the shipped default configuration moved to a free port of its own (never 7447, so a
running daemon is not disturbed); multicast scouting stays off everywhere.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import socket
import time
from pathlib import Path

import pytest
import zenoh

from koopguide.base.config import ConfigError
from koopguide.bus.status import (
    STATES,
    STATUS_FIELDS,
    StatusFormatError,
    decode_status,
    encode_status,
)
from koopguide.bus.status_bus import StatusBus
from koopguide.bus.zenoh_config import (
    DEFAULT_ZENOH_CONFIG_FILE,
    WELL_KNOWN_PORT,
    default_zenoh_config,
    load_zenoh_config,
)
from tests.support.status_samples import (
    async_wait_for,
    config_snapshot,
    field_sampler,
    free_port,
    sample_status,
)

BUS_LOGGER = "koopguide.bus.status_bus"


# ---------------------------------------------------------------------------------- helpers
def open_bus(vehicle_id: str, port: int) -> StatusBus:
    """Coroutine factory shortcut used inside asyncio tests."""
    return StatusBus.create(vehicle_id, default_zenoh_config(port), field_sampler, config_snapshot)


class Listener:
    """A plain zenoh session collecting statuses and liveliness events through ring channels."""

    def __init__(self, port: int) -> None:
        self.session = zenoh.open(default_zenoh_config(port))
        self.statuses = self.session.declare_subscriber("koopguide/*/status", zenoh.handlers.RingChannel(1024))
        self.alive = self.session.liveliness().declare_subscriber(
            "koopguide/*/alive", zenoh.handlers.RingChannel(64), history=True
        )
        self.received: list[zenoh.Sample] = []
        self.alive_events: list[tuple[str, zenoh.SampleKind]] = []

    def drain(self) -> None:
        while (sample := self.statuses.try_recv()) is not None:
            self.received.append(sample)
        while (event := self.alive.try_recv()) is not None:
            self.alive_events.append((str(event.key_expr), event.kind))

    def statuses_from(self, vehicle_id: str) -> list[dict]:
        self.drain()
        key = f"koopguide/{vehicle_id}/status"
        return [decode_status(s.payload.to_bytes()) for s in self.received if str(s.key_expr) == key]

    def close(self) -> None:
        self.session.close()


# ------------------------------------------------------------------------------ status schema
def test_round_trip_keeps_every_field_and_extras():
    status = sample_status(vehicle_time_s=12.5, link={"heartbeat_age_s": 0.2}, fault=None)
    payload = encode_status(status)
    assert b" " not in payload  # compact
    decoded = decode_status(payload)
    assert decoded == status
    assert tuple(decoded)[: len(STATUS_FIELDS)] == STATUS_FIELDS


def test_round_trip_of_the_nullable_fields_and_integer_numbers():
    status = sample_status(
        state="waiting",
        mode=None,
        armed=None,
        position_ned=None,
        velocity_ned=None,
        goal_ned=None,
        distance_to_goal_m=None,
        position_age_s=None,
        loop_latency_ms={"p50": None, "p99": None},
        t=1_700_000_000,
        speed_limit_mps=2,
        cmd_velocity_ned=(0, 0),
    )
    decoded = decode_status(encode_status(status))
    assert decoded["mode"] is None and decoded["position_ned"] is None
    assert isinstance(decoded["t"], float) and isinstance(decoded["speed_limit_mps"], float)
    assert decoded["cmd_velocity_ned"] == [0.0, 0.0] and all(isinstance(v, float) for v in decoded["cmd_velocity_ned"])


def test_every_state_is_accepted():
    for state in STATES:
        assert decode_status(encode_status(sample_status(state=state)))["state"] == state


@pytest.mark.parametrize(
    ("changes", "expected"),
    [
        ({"t": "now"}, "'t'"),
        ({"t": True}, "'t'"),
        ({"t": math.nan}, "'t' must be finite"),
        ({"seq": -1}, "'seq'"),
        ({"seq": 1.5}, "'seq'"),
        ({"seq": False}, "'seq'"),
        ({"vehicle_id": "boat/1"}, "'vehicle_id'"),
        ({"vehicle_id": ""}, "'vehicle_id'"),
        ({"state": "sailing"}, "'state' must be one of idle, waiting, guiding, arrived, hold, fault"),
        ({"mode": 4}, "'mode'"),
        ({"armed": "yes"}, "'armed'"),
        ({"armed": 1}, "'armed'"),
        ({"position_ned": [1.0]}, "'position_ned'"),
        ({"position_ned": [1.0, math.inf]}, "'position_ned[1]' must be finite"),
        ({"velocity_ned": "fast"}, "'velocity_ned'"),
        ({"goal_ned": [None, 1.0]}, "'goal_ned[0]'"),
        ({"distance_to_goal_m": -1.0}, "'distance_to_goal_m' must be >= 0"),
        ({"cmd_velocity_ned": None}, "'cmd_velocity_ned'"),
        ({"cmd_velocity_ned": [math.nan, 0.0]}, "'cmd_velocity_ned[0]' must be finite"),
        ({"speed_limit_mps": -0.5}, "'speed_limit_mps'"),
        ({"speed_limit_mps": None}, "'speed_limit_mps'"),
        ({"position_age_s": -math.inf}, "'position_age_s' must be finite"),
        ({"loop_latency_ms": [1.0, 2.0]}, "'loop_latency_ms'"),
        ({"loop_latency_ms": {"p50": 1.0}}, "'loop_latency_ms' is missing 'p99'"),
        ({"loop_latency_ms": {"p50": 1.0, "p99": "slow"}}, "'loop_latency_ms.p99'"),
        ({"model": None}, "'model'"),
    ],
)
def test_encode_refuses_a_bad_field_naming_key_and_value(changes, expected):
    bad = sample_status(**changes)
    with pytest.raises(StatusFormatError, match="status key") as excinfo:
        encode_status(bad)
    message = str(excinfo.value)
    assert expected in message
    assert "got " in message  # the value seen is named
    # the same payload written by someone else is refused on decode too
    raw = json.dumps(bad, default=list).encode()
    with pytest.raises(StatusFormatError):
        decode_status(raw)


def test_encode_refuses_missing_keys_and_non_finite_extras():
    status = sample_status()
    del status["model"], status["seq"]
    with pytest.raises(StatusFormatError, match=r"missing required key.*seq, model"):
        encode_status(status)
    with pytest.raises(StatusFormatError, match=r"key 'current_ned' .*cannot be encoded"):
        encode_status(sample_status(current_ned=[0.1, math.nan]))
    with pytest.raises(StatusFormatError, match="key 'handle'"):
        encode_status(sample_status(handle=object()))
    with pytest.raises(StatusFormatError, match="must be a mapping"):
        encode_status([("t", 1.0)])  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("payload", "expected"),
    [
        (b"\xff\xfe", "not UTF-8"),
        (b"{not json", "not JSON"),
        (b"[1, 2]", "must be a JSON object, got list"),
        (b'"guiding"', "must be a JSON object, got str"),
        (encode_status(sample_status()).replace(b'"speed_limit_mps":1.5', b'"speed_limit_mps":NaN'), "NaN"),
        (encode_status(sample_status()).replace(b'"t":1700000000.25', b'"t":Infinity'), "Infinity"),
        (b'{"t": 1.0}', "missing required key"),
    ],
)
def test_decode_refuses_malformed_payloads(payload, expected):
    with pytest.raises(StatusFormatError, match=expected):
        decode_status(payload)


# ---------------------------------------------------------------------------- zenoh config
def test_default_config_is_loopback_peer_without_multicast():
    cfg = load_zenoh_config(None)
    assert json.loads(cfg.get_json("mode")) == "peer"
    assert json.loads(cfg.get_json("scouting/multicast/enabled")) is False
    assert json.loads(cfg.get_json("scouting/gossip/enabled")) is True
    assert json.loads(cfg.get_json("timestamping/enabled")) is True
    listen = json.loads(cfg.get_json("listen/endpoints"))
    connect = json.loads(cfg.get_json("connect/endpoints"))
    assert f"tcp/127.0.0.1:{WELL_KNOWN_PORT}" in listen and connect == [f"tcp/127.0.0.1:{WELL_KNOWN_PORT}"]
    assert all(e.startswith("tcp/127.0.0.1:") for e in listen + connect)
    # a process that cannot bind the rendezvous port must still start
    assert json.loads(cfg.get_json("listen/exit_on_failure")) is False
    assert json.loads(cfg.get_json("connect/exit_on_failure")) is False
    assert DEFAULT_ZENOH_CONFIG_FILE.name == "zenoh.json5"


def test_default_config_moved_to_another_port():
    cfg = default_zenoh_config(40123)
    assert json.loads(cfg.get_json("listen/endpoints")) == ["tcp/127.0.0.1:40123", "tcp/127.0.0.1:0"]
    assert json.loads(cfg.get_json("connect/endpoints")) == ["tcp/127.0.0.1:40123"]
    with pytest.raises(ValueError, match="70000"):
        default_zenoh_config(70000)


def test_a_given_file_replaces_the_default(tmp_path: Path):
    path = tmp_path / "mine.json5"
    path.write_text('{ // mine\n mode: "client", scouting: { multicast: { enabled: false } } }\n')
    cfg = load_zenoh_config(path)
    assert json.loads(cfg.get_json("mode")) == "client"
    assert json.loads(cfg.get_json("connect/endpoints")) == []  # nothing inherited from the default


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (None, "not found"),
        ("", "empty"),
        ('{ mode: "peer",, }', "line 1 column"),
        ('{ mood: "peer" }', "unknown field `mood`"),
        ('{ mode: "pear" }', "`pear`"),
    ],
)
def test_a_bad_config_file_is_one_line_naming_the_file(tmp_path: Path, text, expected):
    path = tmp_path / "zenoh.json5"
    if text is not None:
        path.write_text(text)
    with pytest.raises(ConfigError, match=expected) as excinfo:
        load_zenoh_config(path)
    message = str(excinfo.value)
    assert message.startswith(str(path)) and "\n" not in message and ".rs:" not in message


# ------------------------------------------------------------------------------- StatusBus
@pytest.mark.timeout(30)
@pytest.mark.parametrize("vehicle_id", ["", "boat/1", "boat*", "a$b", "what?", "x#", "boat 1", "b" * 65])
def test_bad_vehicle_id_is_refused(vehicle_id):
    with pytest.raises(ValueError, match="vehicle id"):
        asyncio.run(open_bus(vehicle_id, free_port()))


@pytest.mark.timeout(30)
def test_publish_reaches_a_subscriber_with_every_field():
    port = free_port()
    listener = Listener(port)

    async def main() -> list[dict]:
        async with await open_bus("boat1", port) as bus:
            assert bus.enabled
            seq = 0

            def published_and_received() -> list[dict]:
                nonlocal seq
                bus.publish(sample_status(seq=seq))
                seq += 1
                return listener.statuses_from("boat1")

            return await async_wait_for(published_and_received)

    try:
        received = asyncio.run(main())
        assert set(STATUS_FIELDS) <= set(received[0])
        assert received[0] == sample_status(seq=received[0]["seq"])
        sample = listener.received[0]
        assert sample.encoding == zenoh.Encoding.APPLICATION_JSON
        assert sample.timestamp is not None  # timestamping is on in the default config
    finally:
        listener.close()


@pytest.mark.timeout(30)
def test_liveliness_token_appears_and_goes_with_close():
    port = free_port()
    listener = Listener(port)
    key = "koopguide/boat1/alive"

    def events() -> list:
        listener.drain()
        return listener.alive_events

    async def main() -> None:
        bus = await open_bus("boat1", port)
        try:
            await async_wait_for(lambda: (key, zenoh.SampleKind.PUT) in events())
        finally:
            await bus.close()
        await async_wait_for(lambda: (key, zenoh.SampleKind.DELETE) in events())
        assert not bus.enabled
        bus.publish(sample_status())  # after close: a no-op, not an error

    try:
        asyncio.run(main())
    finally:
        listener.close()


def _get(session: zenoh.Session, selector: str) -> list[zenoh.Reply]:
    return list(session.get(selector, timeout=3.0))


@pytest.mark.timeout(30)
def test_field_and_config_queryables_answer_json():
    port = free_port()
    asker = zenoh.open(default_zenoh_config(port))

    async def main() -> tuple[list, list, list]:
        async with await open_bus("boat1", port):
            # a get before the peers are connected finds nobody: ask until the bus answers
            deadline = time.monotonic() + 5.0
            while not (
                field := [r for r in await asyncio.to_thread(_get, asker, "koopguide/boat1/field?n=4;extra=x") if r.ok]
            ):
                assert time.monotonic() < deadline, "the field queryable never answered"
                await asyncio.sleep(0.05)
            config = await asyncio.to_thread(_get, asker, "koopguide/boat1/config")
            bad = await asyncio.to_thread(_get, asker, "koopguide/boat1/field?n=1000")
            return field, config, bad

    try:
        field, config, bad = asyncio.run(main())
        assert len(field) == 1
        assert str(field[0].ok.key_expr) == "koopguide/boat1/field"
        assert field[0].ok.encoding == zenoh.Encoding.APPLICATION_JSON
        assert json.loads(field[0].ok.payload.to_string()) == {
            "n": 4,
            "north": [0.0, 1.0, 2.0, 3.0],
            "params": {"n": "4", "extra": "x"},
        }
        assert [json.loads(r.ok.payload.to_string()) for r in config] == [config_snapshot()]
        assert len(bad) == 1 and bad[0].err is not None
        assert bad[0].err.payload.to_string() == "grid size n must be 2..50, got 1000"
    finally:
        asker.close()


@pytest.mark.timeout(30)
def test_a_failing_callback_gives_an_error_reply_and_the_bus_keeps_serving(caplog: pytest.LogCaptureFixture):
    port = free_port()
    asker = zenoh.open(default_zenoh_config(port))

    async def broken_sampler(params: dict[str, str]) -> bytes:
        return json.dumps({"n": params["missing"]}).encode()  # KeyError: a bug in the daemon, not the asker's

    async def ask(selector: str) -> list[zenoh.Reply]:
        deadline = time.monotonic() + 5.0
        while not (replies := await asyncio.to_thread(_get, asker, selector)):
            assert time.monotonic() < deadline, f"nobody answered {selector}"
            await asyncio.sleep(0.05)
        return replies

    async def main() -> tuple[list, list, list]:
        cfg = default_zenoh_config(port)
        async with await StatusBus.create("boat1", cfg, broken_sampler, lambda: {"gain": math.nan}) as bus:
            field = await ask("koopguide/boat1/field")
            config = await ask("koopguide/boat1/config")
            bus.publish(sample_status())  # still alive and well
            again = await ask("koopguide/boat1/field?missing=3")
            return field, config, again

    try:
        with caplog.at_level(logging.WARNING, logger=BUS_LOGGER):
            field, config, again = asyncio.run(main())
    finally:
        asker.close()
    assert field[0].err.payload.to_string() == "internal error: KeyError: 'missing'"
    assert "not finite JSON" in config[0].err.payload.to_string()
    assert json.loads(again[0].ok.payload.to_string()) == {"n": "3"}
    assert [r.levelname for r in caplog.records if r.name == BUS_LOGGER] == ["ERROR", "ERROR"]


@pytest.mark.timeout(30)
def test_impossible_config_gives_a_disabled_bus_and_one_warning(caplog: pytest.LogCaptureFixture):
    with socket.socket() as holder:  # the endpoint is taken, and this config insists on it
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        port = holder.getsockname()[1]
        cfg = zenoh.Config.from_json5(
            json.dumps(
                {
                    "mode": "peer",
                    "listen": {"endpoints": [f"tcp/127.0.0.1:{port}"], "exit_on_failure": True},
                    "scouting": {"multicast": {"enabled": False}},
                }
            )
        )

        async def main() -> StatusBus:
            bus = await StatusBus.create("boat1", cfg, field_sampler, config_snapshot)
            for seq in range(5):
                bus.publish(sample_status(seq=seq))  # no-op, no error, no more logging
            await bus.close()
            return bus

        with caplog.at_level(logging.DEBUG, logger=BUS_LOGGER):
            bus = asyncio.run(main())
    assert not bus.enabled
    records = [r for r in caplog.records if r.name == BUS_LOGGER]
    assert len(records) == 1 and records[0].levelno == logging.WARNING
    assert "boat1" in records[0].getMessage() and "disabled" in records[0].getMessage()


@pytest.mark.timeout(30)
def test_a_failing_put_is_logged_once(caplog: pytest.LogCaptureFixture):
    async def main() -> StatusBus:
        bus = await open_bus("boat1", free_port())
        try:
            bus._declared.session.close()  # the transport goes away under the bus: every put now fails
            with caplog.at_level(logging.INFO, logger=BUS_LOGGER):
                for seq in range(10):
                    bus.publish(sample_status(seq=seq))
        finally:
            await bus.close()
        return bus

    bus = asyncio.run(main())
    assert bus.put_failures == 10
    warnings = [r for r in caplog.records if r.name == BUS_LOGGER and r.levelno >= logging.WARNING]
    assert len(warnings) == 1 and "koopguide/boat1/status" in warnings[0].getMessage()


@pytest.mark.timeout(30)
def test_a_malformed_status_is_a_bug_and_raises():
    async def main() -> None:
        async with await open_bus("boat1", free_port()) as bus:
            with pytest.raises(StatusFormatError, match="'state'"):
                bus.publish(sample_status(state="lost"))

    asyncio.run(main())


@pytest.mark.timeout(30)
def test_two_buses_and_a_subscriber_share_the_rendezvous_port():
    port = free_port()

    async def main() -> None:
        first = await open_bus("boat1", port)  # binds the rendezvous port
        second = await open_bus("boat-2", port)  # cannot bind it: connects to it, still starts
        listener = await asyncio.to_thread(Listener, port)  # the same, a third process would do this
        try:

            def both_heard() -> bool:
                first.publish(sample_status("boat1"))
                second.publish(sample_status("boat-2", state="arrived"))
                return bool(listener.statuses_from("boat1")) and bool(listener.statuses_from("boat-2"))

            await async_wait_for(both_heard)
            assert listener.statuses_from("boat-2")[-1]["state"] == "arrived"
            # the port's owner leaves: gossip has meshed the others directly, they keep talking
            await first.close()
            listener.received.clear()

            def heard_after_owner_left() -> bool:
                second.publish(sample_status("boat-2", seq=99))
                return any(s["seq"] == 99 for s in listener.statuses_from("boat-2"))

            await async_wait_for(heard_after_owner_left)
        finally:
            await first.close()
            await second.close()
            listener.close()

    asyncio.run(main())


@pytest.mark.timeout(30)
def test_cancelled_create_does_not_leak_a_session():
    async def main() -> None:
        task = asyncio.create_task(open_bus("boat1", free_port()))
        await asyncio.sleep(0)  # let it start opening on its worker thread
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
        await asyncio.sleep(0.5)  # the opening finishes and is closed behind the scenes

    asyncio.run(main())


# ------------------------------------------------------------------------------ fleets: the others' statuses
def test_a_bus_listening_to_others_hears_the_other_vehicle_not_itself_nor_garbage():
    async def scenario() -> tuple[list[dict], list[dict]]:
        port = free_port()
        config = default_zenoh_config(port)
        boat1 = await StatusBus.create("boat1", config, field_sampler, config_snapshot, listen_to_others=True)
        boat2 = await StatusBus.create("boat2", config, field_sampler, config_snapshot)  # not listening
        session = zenoh.open(default_zenoh_config(port))
        heard1: list[dict] = []
        try:
            for seq in range(1, 41):
                boat1.publish(sample_status("boat1", seq=seq))
                boat2.publish(sample_status("boat2", seq=seq, position_ned=[1.0, float(seq)]))
                session.put("koopguide/forged/status", b"{not json")
                heard1 += boat1.take_others()
                await asyncio.sleep(0.05)
            heard1 += boat1.take_others()
            return heard1, boat2.take_others()
        finally:
            session.close()
            await boat1.close()
            await boat2.close()

    heard1, heard2 = asyncio.run(scenario())
    assert heard1, "boat1 heard nothing from boat2"
    assert {s["vehicle_id"] for s in heard1} == {"boat2"}  # never its own status, never the malformed one
    seqs = [s["seq"] for s in heard1]
    assert seqs == sorted(seqs) and seqs[-1] >= 30  # in order, and the latest ones arrive
    assert heard1[-1]["position_ned"] == [1.0, float(seqs[-1])]
    assert heard2 == []  # a bus that does not listen has nothing to take
