"""The one endpoint grammar: what users of pymavlink, MAVProxy and ArduPilot SITL write is accepted."""

from __future__ import annotations

import pytest

from koopguide.mavlink.endpoint import Endpoint, EndpointError


@pytest.mark.parametrize(
    ("text", "kind", "host", "port", "baud"),
    [
        ("udp:127.0.0.1:14550", "udpin", "127.0.0.1", 14550, 0),
        ("udpin:0.0.0.0:0", "udpin", "0.0.0.0", 0, 0),
        ("udpout:10.0.0.2:14550", "udpout", "10.0.0.2", 14550, 0),
        ("tcp:localhost:5760", "tcp", "localhost", 5760, 0),
        ("tcpin:127.0.0.1:5760", "tcpin", "127.0.0.1", 5760, 0),
        ("/dev/ttyUSB0,57600", "serial", "/dev/ttyUSB0", 0, 57600),
        ("/dev/ttyACM0", "serial", "/dev/ttyACM0", 0, 115200),
        ("COM3,921600", "serial", "COM3", 0, 921600),
    ],
)
def test_endpoints_users_know_are_accepted(text: str, kind: str, host: str, port: int, baud: int) -> None:
    ep = Endpoint.parse(text)
    assert (ep.kind, ep.host, ep.port, ep.baud) == (kind, host, port, baud)
    assert Endpoint.parse(str(ep)) == ep  # the canonical form parses back to the same endpoint


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("udp:127.0.0.1", "expected udp:HOST:PORT"),
        ("tcp:host:99999", "99999 is out of range"),
        ("udpout:h:0", "0 is out of range 1"),
        ("tcp:host:port", "'port' is not a number"),
        ("serial", "not understood"),
        ("/dev/ttyUSB0,fast", "'fast' is not a number"),
        ("/dev/ttyUSB0,12345", "12345 is not a standard rate"),
        ("udpin:bad host:14550", "expected udpin:HOST:PORT"),
    ],
)
def test_bad_endpoints_are_refused_in_one_line_naming_them(text: str, says: str) -> None:
    with pytest.raises(EndpointError) as err:
        Endpoint.parse(text)
    message = str(err.value)
    assert isinstance(err.value, ValueError) and "\n" not in message
    assert repr(text) in message and says in message


def test_port_offsets_for_several_boats() -> None:
    ep = Endpoint.parse("udpout:127.0.0.1:14550")
    assert ep.with_port_offset(20).port == 14570
    assert Endpoint.parse("tcpin:127.0.0.1:0").with_port_offset(10).port == 0  # any free port stays any
    assert Endpoint.parse("/dev/ttyUSB0").with_port_offset(10) == Endpoint.parse("/dev/ttyUSB0")
    with pytest.raises(EndpointError, match="exceeds 65535"):
        Endpoint.parse("udpout:h:65530").with_port_offset(10)
