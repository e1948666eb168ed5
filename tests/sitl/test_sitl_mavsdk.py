"""A real third-party client, MAVSDK-Python, sees a connected, armable boat with position, home and mode."""

from __future__ import annotations

import asyncio

import pytest

from sitl.runner import Simulation
from tests.support.sitl_gcs import sim_config

mavsdk = pytest.importorskip("mavsdk.asyncio", reason="mavsdk is in the dev extra")
telemetry = pytest.importorskip("mavsdk.asyncio.plugins.telemetry")

WALL_LIMIT_S = 60.0


async def first(stream, predicate=lambda _: True):
    async for item in stream:
        if predicate(item):
            return item
    raise AssertionError("stream ended")


async def mavsdk_session() -> dict:
    cfg = sim_config({"speedup": 5.0, "mavlink": {"endpoints": ["tcpin:127.0.0.1:0"]}})
    async with await Simulation.create(cfg) as sim:
        port = sim.links[0].local_address[1]
        runner = asyncio.create_task(sim.run())
        config = mavsdk.Configuration.create_with_component_type(mavsdk.ComponentType.GROUND_STATION)
        async with mavsdk.Mavsdk(config) as client:
            await client.add_any_connection(f"tcpout://127.0.0.1:{port}")
            system = await client.first_autopilot(timeout_s=20.0)
            assert system is not None, "MAVSDK found no autopilot"
            tel = telemetry.TelemetryAsync(system)
            out = {
                "connected": await system.is_connected(),
                "position": await first(tel.subscribe_position()),
                "home": await tel.home(),  # requested by MAVSDK at connection, before any subscription
                "mode": await first(tel.subscribe_flight_mode()),
                "armed": await first(tel.subscribe_armed()),
                "armable": await first(tel.subscribe_health(), lambda h: h.is_armable),
                "sim_home": sim.boat(1).autopilot.home,
            }
        sim.stop()
        await runner
    return out


def test_mavsdk_sees_a_connected_armable_boat():
    result = asyncio.run(asyncio.wait_for(mavsdk_session(), WALL_LIMIT_S))
    assert result["connected"]
    position = result["position"]
    assert abs(position.latitude_deg - (-35.363261)) < 1e-3
    assert abs(position.longitude_deg - 149.16523) < 1e-3
    home = result["home"]
    assert abs(home.latitude_deg - (-35.363261 + 2.25 / 111195.0)) < 2e-6  # the start pose
    assert result["mode"] == telemetry.FlightMode.MANUAL  # Rover custom mode 0
    assert result["armed"] is False
    assert result["armable"].is_armable
