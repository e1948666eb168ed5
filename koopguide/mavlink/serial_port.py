"""A serial device for MAVLink: opened raw and non-blocking at the endpoint's baud (POSIX termios)."""

from __future__ import annotations

import errno
import os
import termios
import tty

from koopguide.mavlink.endpoint import Endpoint


def open_serial(ep: Endpoint) -> int:
    """Open a serial device raw, non-blocking, at the endpoint's baud; OSError when it cannot."""
    fd = os.open(ep.host, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        tty.setraw(fd)
        attrs = termios.tcgetattr(fd)
        attrs[4] = attrs[5] = getattr(termios, f"B{ep.baud}")
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
    except (termios.error, AttributeError) as exc:
        os.close(fd)
        raise OSError(errno.ENOTTY, f"not a usable serial device ({exc})") from None
    return fd
