"""Support for the MAVLink tests: frames built with pymavlink's own encoder (signed or not), bounded waits."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from typing import Any

from koopguide.mavlink.signing import SigningKey, configure_encoder
from koopguide.mavlink.wire import mavlink


class Capture:
    """A file-like sink that keeps every frame written to it."""

    def __init__(self) -> None:
        self.frames: list[bytes] = []

    def write(self, buf: bytes) -> None:
        self.frames.append(bytes(buf))


def encoder(system: int = 1, component: int = 1, key: SigningKey | None = None, link_id: int = 0) -> Any:
    """A pymavlink MAVLink 2 encoder whose frames land in ``encoder.file.frames``."""
    mav = mavlink.MAVLink(Capture(), srcSystem=system, srcComponent=component)
    if key is not None:
        configure_encoder(mav, key, link_id)
    return mav


def frame(mav: Any, msg: Any) -> bytes:
    mav.send(msg)
    return mav.file.frames[-1]


def vehicle_heartbeat(mode: int = 0, armed: bool = False) -> Any:
    base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mavlink.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
    return mavlink.MAVLink_heartbeat_message(
        mavlink.MAV_TYPE_SURFACE_BOAT, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, base, mode, mavlink.MAV_STATE_ACTIVE, 3
    )


def local_position(t_ms: int, n: float, e: float) -> Any:
    return mavlink.MAVLink_local_position_ned_message(t_ms, n, e, 0.0, 0.0, 0.0, 0.0)


async def until(predicate: Callable[[], Any], within_s: float = 10.0) -> None:
    """Wait (on the running loop) until ``predicate()`` holds; fail after ``within_s`` wall seconds."""
    deadline = time.monotonic() + within_s
    while not predicate():
        assert time.monotonic() < deadline, "condition not reached in time"
        await asyncio.sleep(0.01)
