"""Status documents, stand-in callbacks and waiting helpers shared by the zenoh-side tests."""

from __future__ import annotations

import asyncio
import socket
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import pytest

from koopguide.bus.status_bus import StatusBus
from koopguide.bus.zenoh_config import default_zenoh_config


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def sample_status(vehicle_id: str = "boat1", **changes: Any) -> dict[str, Any]:
    status = {
        "t": 1_700_000_000.25,
        "seq": 7,
        "vehicle_id": vehicle_id,
        "state": "guiding",
        "reason": "following_the_field",
        "degraded": False,
        "mode": "GUIDED",
        "armed": True,
        "position_ned": [12.5, -3.25],
        "velocity_ned": [0.5, 0.25],
        "goal_ned": [0.0, 0.0],
        "distance_to_goal_m": 12.92,
        "cmd_velocity_ned": [-0.75, 0.5],
        "speed_limit_mps": 1.5,
        "position_age_s": 0.04,
        "loop_latency_ms": {"p50": 0.8, "p99": 2.5},
        "model": "zshape.pt",
    }
    status.update(changes)
    return status


def wait_for(predicate: Callable[[], Any], timeout: float = 5.0, poll: float = 0.02) -> Any:
    """Poll ``predicate`` until it returns something truthy; fail after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        result = predicate()
        if result:
            return result
        time.sleep(poll)
    pytest.fail(f"condition not met within {timeout} s")


async def async_wait_for(predicate: Callable[[], Any], within: float = 5.0) -> Any:
    deadline = time.monotonic() + within
    while time.monotonic() < deadline:
        result = predicate()
        if result:
            return result
        await asyncio.sleep(0.02)
    pytest.fail(f"condition not met within {within} s")


def field_sampler(params: dict[str, str]) -> dict:
    n = int(params.get("n", "3"))
    if not 2 <= n <= 50:
        raise ValueError(f"grid size n must be 2..50, got {n}")
    return {"n": n, "north": [float(i) for i in range(n)], "params": params}


def config_snapshot() -> dict:
    return {"vehicle_id": "boat1", "command": {"max_speed_mps": 1.5}}


@contextmanager
def publishing(vehicle_id: str, port: int, state: str = "guiding", period: float = 0.05) -> Iterator[None]:
    """A StatusBus publishing ``state`` every ``period`` s on a thread of its own, until the block ends."""
    stop = threading.Event()
    ready = threading.Event()
    errors: list[BaseException] = []

    async def run() -> None:
        bus = await StatusBus.create(vehicle_id, default_zenoh_config(port), field_sampler, config_snapshot)
        try:
            assert bus.enabled
            ready.set()
            seq = 0
            while not stop.is_set():
                bus.publish(sample_status(vehicle_id, seq=seq, state=state))
                seq += 1
                await asyncio.sleep(period)
        finally:
            await bus.close()

    def thread_main() -> None:
        try:
            asyncio.run(run())
        except BaseException as exc:  # reported by the test thread below
            errors.append(exc)
            ready.set()

    thread = threading.Thread(target=thread_main, name=f"publisher {vehicle_id}")
    thread.start()
    try:
        assert ready.wait(10), "publisher did not start"
        assert not errors, errors
        yield
    finally:
        stop.set()
        thread.join(10)
    assert not errors, errors
