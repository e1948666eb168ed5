"""MAVLink endpoint strings, as pymavlink, MAVProxy and ArduPilot SITL users write them.

  udpin:HOST:PORT   bind HOST:PORT and listen (``udp:`` is the same); port 0 binds a free port
  udpout:HOST:PORT  send to HOST:PORT and accept its replies only
  tcpin:HOST:PORT   listen for TCP clients; port 0 binds a free port
  tcp:HOST:PORT     connect to a TCP server
  DEVICE[,BAUD]     a serial device (``/dev/ttyUSB0,57600``; ``COM3,115200`` on Windows), 115200 baud if not given

This is the one grammar of the project: the guidance service and the simulator both parse with it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

UDP_IN, UDP_OUT, TCP_IN, TCP_OUT, SERIAL = "udpin", "udpout", "tcpin", "tcp", "serial"
NETWORK_KINDS = {"udp": UDP_IN, "udpin": UDP_IN, "udpout": UDP_OUT, "tcpin": TCP_IN, "tcp": TCP_OUT}
LISTENING = frozenset({UDP_IN, TCP_IN})
DEFAULT_BAUD = 115200
HOST = re.compile(r"^[A-Za-z0-9_.\-]+$")
SERIAL_DEVICE = re.compile(r"^(/\S+|COM\d+)$", re.IGNORECASE)
STANDARD_BAUDS = frozenset(
    {1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 921600, 1000000, 1500000, 2000000}
)


class EndpointError(ValueError):
    """A MAVLink endpoint string that is malformed or cannot be opened; the message names it."""


class PortInUseError(EndpointError):
    """The endpoint's port is bound by another process (only one may own it)."""


@dataclass(frozen=True)
class Endpoint:
    kind: str  # one of udpin, udpout, tcpin, tcp, serial ("udp" is normalised to "udpin")
    host: str  # network: host name or address; serial: the device path
    port: int  # network: port (0 = any free port, listening kinds only); serial: 0
    baud: int = 0  # serial: line speed [bit/s]; network: 0

    @classmethod
    def parse(cls, text: str) -> Endpoint:
        """Parse an endpoint string; raises EndpointError naming the string and what is wrong."""
        text = text.strip()
        prefix, sep, rest = text.partition(":")
        if sep and prefix in NETWORK_KINDS:
            kind = NETWORK_KINDS[prefix]
            host, sep, port_text = rest.rpartition(":")
            if not sep or not HOST.match(host):
                raise EndpointError(f"MAVLink endpoint {text!r}: expected {prefix}:HOST:PORT")
            if not port_text.isdigit():
                raise EndpointError(f"MAVLink endpoint {text!r}: port {port_text!r} is not a number")
            port = int(port_text)
            lowest = 0 if kind in LISTENING else 1
            if not lowest <= port <= 65535:
                raise EndpointError(f"MAVLink endpoint {text!r}: port {port} is out of range {lowest} .. 65535")
            return cls(kind, host, port)
        device, _, baud_text = text.partition(",")
        if SERIAL_DEVICE.match(device):
            if baud_text and not baud_text.isdigit():
                raise EndpointError(f"MAVLink endpoint {text!r}: baud {baud_text!r} is not a number")
            baud = int(baud_text or DEFAULT_BAUD)
            if baud not in STANDARD_BAUDS:
                raise EndpointError(f"MAVLink endpoint {text!r}: baud {baud} is not a standard rate")
            return cls(SERIAL, device, 0, baud)
        raise EndpointError(
            f"MAVLink endpoint {text!r} not understood; use udpin:HOST:PORT (or udp:), udpout:HOST:PORT, "
            "tcpin:HOST:PORT, tcp:HOST:PORT or a serial device such as /dev/ttyUSB0,57600"
        )

    @property
    def listens(self) -> bool:
        """True for udpin/tcpin: peers come to us, and which of them we answer is our choice."""
        return self.kind in LISTENING

    @property
    def stream(self) -> bool:
        """True for a tcp client or a serial device: a link that closes is reopened."""
        return self.kind in (TCP_OUT, SERIAL)

    def with_port_offset(self, offset: int) -> Endpoint:
        """The same endpoint ``offset`` ports higher (port 0 and serial devices stay as they are)."""
        if offset == 0 or self.port == 0 or self.kind == SERIAL:
            return self
        port = self.port + offset
        if port > 65535:
            raise EndpointError(f"MAVLink endpoint {self}: port + {offset} exceeds 65535")
        return Endpoint(self.kind, self.host, port)

    def with_port(self, port: int) -> Endpoint:
        """This endpoint with the port actually bound (port 0 resolved)."""
        return Endpoint(self.kind, self.host, port, self.baud)

    def __str__(self) -> str:
        if self.kind == SERIAL:
            return f"{self.host},{self.baud}"
        return f"{self.kind}:{self.host}:{self.port}"
