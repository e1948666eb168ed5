"""The shared transport on real loopback sockets: source pinning, bounded peers, per-source parsers,
signing, an exclusive port, TCP and serial (a pseudo-terminal)."""

from __future__ import annotations

import asyncio
import os
import socket
import time
from typing import Any

import pytest
from pymavlink import mavutil

from koopguide.mavlink import rover
from koopguide.mavlink.endpoint import Endpoint, EndpointError, PortInUseError
from koopguide.mavlink.link import Link
from koopguide.mavlink.link_settings import LinkSettings
from koopguide.mavlink.signing import SigningKey
from koopguide.mavlink.wire import mavlink
from tests.support.mavlink_frames import encoder, frame, local_position, until, vehicle_heartbeat

SERVICE = (255, 191)
VEHICLE = (1, 1)
KEY = SigningKey(os.urandom(32), "test key")


class Received:
    def __init__(self) -> None:
        self.messages: list[Any] = []

    def __call__(self, link: Link, msg: Any, arrived: float) -> None:
        self.messages.append(msg)

    def of(self, kind: str) -> list[Any]:
        return [m for m in self.messages if m.get_type() == kind]


def udp_socket() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.setblocking(False)
    return s


def drain(s: socket.socket) -> list[bytes]:
    out = []
    while True:
        try:
            out.append(s.recv(65536))
        except BlockingIOError:
            return out


async def service_link(received: Received, **kw: Any) -> Link:
    settings = LinkSettings(Endpoint.parse("udpin:127.0.0.1:0"), (SERVICE,), vehicle=VEHICLE, **kw)
    return await Link.create(settings, received)


def test_the_link_pins_the_vehicle_and_drops_a_100_hz_position_spoofer() -> None:
    async def scenario() -> None:
        got = Received()
        link = await service_link(got, repin_after_s=0.5)
        addr = ("127.0.0.1", link.local_address[1])
        vehicle, spoofer = udp_socket(), udp_socket()
        real, fake = encoder(*VEHICLE), encoder(*VEHICLE)
        try:
            assert link.send(rover.heartbeat()) is False  # nobody to send to before the vehicle is heard
            vehicle.sendto(frame(real, vehicle_heartbeat()), addr)
            await until(lambda: link.pinned == vehicle.getsockname())
            for k in range(50):  # 0.5 s: the spoofer at 100 Hz, the vehicle at 20 Hz
                spoofer.sendto(frame(fake, local_position(k * 10, 99.0, 99.0)), addr)
                if k % 5 == 0:
                    vehicle.sendto(frame(real, local_position(k * 10, 1.0, 2.0)), addr)
                await asyncio.sleep(0.01)
            spoofer.sendto(frame(fake, vehicle_heartbeat(mode=rover.MANUAL)), addr)  # claims MANUAL
            await until(lambda: link.stats.wrong_source >= 51)
            positions = got.of("LOCAL_POSITION_NED")
            assert len(positions) == 10 and all((m.x, m.y) == (1.0, 2.0) for m in positions)
            assert [m.custom_mode for m in got.of("HEARTBEAT")] == [rover.MANUAL]  # the vehicle's own only
            assert link.stats.wrong_source == 51 and link.stats.source_changes == 0
            assert link.send(rover.heartbeat())
            await asyncio.sleep(0.05)
            assert len(drain(vehicle)) == 1 and drain(spoofer) == []  # only the vehicle hears us
            # the vehicle goes silent (a reboot from a new port): after repin_after_s a new address may take over
            await asyncio.sleep(0.6)
            rebooted = udp_socket()
            rebooted.sendto(frame(real, vehicle_heartbeat(mode=rover.HOLD)), addr)
            await until(lambda: link.pinned == rebooted.getsockname())
            assert link.stats.source_changes == 1
            rebooted.close()
        finally:
            vehicle.close()
            spoofer.close()
            await link.close()

    asyncio.run(scenario())


def test_ten_thousand_source_ports_do_not_become_peers(capsys: pytest.CaptureFixture[str]) -> None:
    async def scenario() -> dict[str, float]:
        got = Received()
        link = await service_link(got)
        addr = ("127.0.0.1", link.local_address[1])
        vehicle = udp_socket()
        real = encoder(*VEHICLE)
        gcs = encoder(255, 190)
        try:
            vehicle.sendto(frame(real, vehicle_heartbeat()), addr)
            await until(lambda: link.pinned is not None)

            def send_cost_us() -> float:
                t0 = time.perf_counter()
                for _ in range(100):
                    link.send(rover.heartbeat())
                return (time.perf_counter() - t0) / 100 * 1e6

            before_us = send_cost_us()
            received_bytes = sum(len(d) for d in drain(vehicle))
            cpu0, wall0 = time.process_time(), time.perf_counter()
            flood = [frame(gcs, vehicle_heartbeat()), frame(real, vehicle_heartbeat(mode=rover.MANUAL))]
            for k in range(10_000):
                s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                s.sendto(flood[k % 2], addr)  # half a ground station, half claiming to be the vehicle
                s.close()
                await asyncio.sleep(0)  # asyncio reads one datagram per loop pass; a faster sender overflows the
                # socket's receive buffer and the kernel drops the rest (which would also be harmless)
            await until(lambda: link.stats.foreign + link.stats.wrong_source >= 10_000, 60.0)
            flood_cpu_s, flood_wall_s = time.process_time() - cpu0, time.perf_counter() - wall0
            after_us = send_cost_us()
            assert link.peers == (vehicle.getsockname(),)
            assert link.stats.foreign == 5000 and link.stats.wrong_source == 5000
            assert link.intake.sources <= link.settings.max_parsers
            received_bytes += sum(len(d) for d in drain(vehicle))
            assert link.stats.bytes_out == received_bytes  # every byte sent went to the vehicle, nowhere else
            return {"flood_cpu_s": flood_cpu_s, "flood_wall_s": flood_wall_s, "send_us_before": before_us,
                    "send_us_after": after_us}  # fmt: skip
        finally:
            vehicle.close()
            await link.close()

    figures = asyncio.run(scenario())
    with capsys.disabled():
        print(
            "\n10,000 source ports (machine shared, loaded): " + ", ".join(f"{k} {v:.3f}" for k, v in figures.items())
        )


def test_a_simulator_style_listener_answers_a_bounded_set_of_recent_valid_peers() -> None:
    async def scenario() -> None:
        got = Received()
        settings = LinkSettings(Endpoint.parse("udpin:127.0.0.1:0"), ((1, 1),), max_peers=4)
        link = await Link.create(settings, got)
        addr = ("127.0.0.1", link.local_address[1])
        sockets = [udp_socket() for _ in range(10)]
        try:
            sockets[0].sendto(b"\x00garbage only", addr)
            for s in sockets[1:]:
                s.sendto(frame(encoder(255, 190), vehicle_heartbeat()), addr)
            await until(lambda: link.stats.received == 9)
            assert set(link.peers) == {s.getsockname() for s in sockets[-4:]}
            assert link.stats.peers_dropped == 5
        finally:
            for s in sockets:
                s.close()
            await link.close()

    asyncio.run(scenario())


def test_header_garbage_flood_from_another_address_does_not_blind_the_vehicle() -> None:
    async def scenario() -> None:
        got = Received()
        link = await service_link(got)
        addr = ("127.0.0.1", link.local_address[1])
        vehicle, attacker = udp_socket(), udp_socket()
        real = encoder(*VEHICLE)
        header = bytes([0xFD, 255, 0, 0, 0, 1, 1, 32, 0, 0])
        try:
            vehicle.sendto(frame(real, vehicle_heartbeat()), addr)
            for k in range(100):
                attacker.sendto(header, addr)
                attacker.sendto(header + frame(real, local_position(k, 5.0, 5.0))[:20], addr)
                vehicle.sendto(frame(real, local_position(k, 1.0, 2.0)), addr)
                await asyncio.sleep(0.002)
            await until(lambda: len(got.of("LOCAL_POSITION_NED")) == 100)
            assert all((m.x, m.y) == (1.0, 2.0) for m in got.of("LOCAL_POSITION_NED"))
            assert link.stats.corrupt >= 100
        finally:
            vehicle.close()
            attacker.close()
            await link.close()

    asyncio.run(scenario())


def test_with_a_key_only_signed_frames_pass_and_everything_sent_is_signed() -> None:
    async def scenario() -> None:
        got = Received()
        link = await service_link(got, signing_key=KEY)
        addr = ("127.0.0.1", link.local_address[1])
        vehicle = udp_socket()
        signed, unsigned = encoder(*VEHICLE, key=KEY), encoder(*VEHICLE)
        random_key = encoder(*VEHICLE, key=SigningKey(os.urandom(32), "random"))
        try:
            vehicle.sendto(frame(unsigned, vehicle_heartbeat()), addr)
            vehicle.sendto(frame(random_key, vehicle_heartbeat(mode=rover.MANUAL)), addr)
            vehicle.sendto(frame(signed, vehicle_heartbeat(mode=rover.GUIDED)), addr)
            replay = frame(signed, local_position(1, 1.0, 2.0))
            vehicle.sendto(replay, addr)
            vehicle.sendto(replay, addr)
            await until(lambda: link.stats.bad_signature >= 2)
            assert [m.get_type() for m in got.messages] == ["HEARTBEAT", "LOCAL_POSITION_NED"]
            assert got.messages[0].custom_mode == rover.GUIDED and got.messages[0].get_signed()
            assert (link.stats.unsigned, link.stats.bad_signature) == (1, 2)  # random key + replay
            assert link.send(rover.set_mode(VEHICLE, rover.HOLD))
            await asyncio.sleep(0.05)
            (data,) = drain(vehicle)
            checker = mavlink.MAVLink(None)
            checker.signing.secret_key = KEY.secret
            (msg,) = checker.parse_buffer(data)
            assert msg.get_type() == "COMMAND_LONG" and msg.get_signed() and msg.param2 == rover.HOLD
        finally:
            vehicle.close()
            await link.close()

    asyncio.run(scenario())


def test_the_port_is_exclusive() -> None:
    async def scenario() -> None:
        link = await service_link(Received())
        port = link.local_address[1]
        try:
            with pytest.raises(PortInUseError, match=f"port {port} is already in use by another process") as taken:
                await Link.create(LinkSettings(Endpoint.parse(f"udpin:127.0.0.1:{port}"), (SERVICE,)), Received())
            assert isinstance(taken.value, EndpointError)  # the CLI's one-line error for an endpoint it cannot open
            with pytest.raises(OSError):  # pymavlink's own udpin (SO_REUSEADDR) cannot share it either
                mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}")
        finally:
            await link.close()

    asyncio.run(scenario())


def test_tcp_client_and_server_and_a_serial_pty_carry_messages() -> None:
    async def scenario() -> None:
        server_got, client_got = Received(), Received()
        server = await Link.create(LinkSettings(Endpoint.parse("tcpin:127.0.0.1:0"), ((1, 1),)), server_got)
        client_settings = LinkSettings(Endpoint.parse(f"tcp:127.0.0.1:{server.local_address[1]}"), (SERVICE,))
        client = await Link.create(client_settings, client_got)
        master, slave = os.openpty()
        serial = await Link.create(LinkSettings(Endpoint.parse(f"{os.ttyname(slave)},57600"), (SERVICE,)), Received())
        try:
            await until(lambda: len(server.peers) == 1)
            assert server.send(vehicle_heartbeat())
            assert client.send(rover.heartbeat())
            await until(lambda: client_got.of("HEARTBEAT") and server_got.of("HEARTBEAT"))
            assert client_got.of("HEARTBEAT")[0].get_srcSystem() == 1
            assert server_got.of("HEARTBEAT")[0].get_srcSystem() == SERVICE[0]
            assert serial.send(rover.set_mode(VEHICLE, rover.GUIDED))
            os.set_blocking(master, False)
            await asyncio.sleep(0.05)
            (msg,) = mavlink.MAVLink(None).parse_buffer(os.read(master, 4096))
            assert msg.get_type() == "COMMAND_LONG" and msg.param2 == rover.GUIDED
            os.write(master, frame(encoder(*VEHICLE), local_position(7, 0.5, 0.25)))
            await until(lambda: serial.stats.received == 1)
        finally:
            await client.close()
            await server.close()
            await serial.close()
            os.close(master)
            os.close(slave)

    asyncio.run(scenario())
