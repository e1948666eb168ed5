"""Fixtures for the simulator tests: a simulator on its own thread and a pymavlink GCS on loopback."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import pytest

from sitl.runner import SimulationThread
from tests.support.sitl_gcs import GCS_COMPONENT, GCS_SYSTEM, Gcs, mavutil, sim_config, sitl_config_merge


@pytest.fixture
def gcs_and_sim() -> Iterator[Callable[..., tuple[Gcs, SimulationThread]]]:
    """Factory: (gcs, simulator) with the simulator sending udpout to the GCS's bound loopback port."""
    opened: list[tuple[Any, SimulationThread]] = []

    def start(overrides: dict[str, Any] | None = None, records: list | None = None) -> tuple[Gcs, SimulationThread]:
        conn = mavutil.mavlink_connection(
            "udpin:127.0.0.1:0",
            source_system=GCS_SYSTEM,
            source_component=GCS_COMPONENT,
            dialect="ardupilotmega",
        )
        port = conn.port.getsockname()[1]
        cfg = sim_config(sitl_config_merge({"mavlink": {"endpoints": [f"udpout:127.0.0.1:{port}"]}}, overrides or {}))
        sim = SimulationThread(cfg, records)
        sim.__enter__()
        opened.append((conn, sim))
        gcs = Gcs(conn)
        gcs.wait_type("HEARTBEAT", sim_timeout=3.0)  # the GCS is now known to the boat's udpout link
        return gcs, sim

    yield start
    for conn, sim in opened:
        sim.close()
        conn.close()
