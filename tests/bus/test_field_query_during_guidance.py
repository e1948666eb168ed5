"""A dashboard asking for the field (the largest grid, repeatedly) never holds up the control loop.

The service guides a scripted vehicle over real loopback UDP and publishes on a real zenoh session; a
dashboard-like process asks ``koopguide/<id>/field?n=200`` (40,000 field evaluations, 1.4 MB of JSON)
three times while the vehicle counts the setpoints it receives, in its own time. The asker is a process
of its own, as a dashboard is: decoding 1.4 MB of JSON here would stall this process's event loop.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import sys

import pytest

from koopguide.bus.zenoh_config import default_zenoh_config
from koopguide.guidance.daemon import GuidanceDaemon
from koopguide.harness.mission import free_udp_port
from tests.guidance.test_service_failsafes import config, until
from tests.support.scripted_vehicle import ScriptedVehicle
from tests.support.status_samples import free_port

ASKER = """
import json, zenoh
from koopguide.bus.zenoh_config import default_zenoh_config
with zenoh.open(default_zenoh_config({port})) as session:
    for _ in range(3):
        for reply in session.get("koopguide/fq/field?n=200", timeout=20.0):
            grid = json.loads(reply.ok.payload.to_string()) if reply.ok is not None else {{"error": str(reply.err)}}
            print(json.dumps({{"n": grid.get("n"), "points": len(grid.get("position_ned", []))}}), flush=True)
"""


@pytest.mark.timeout(90)
def test_field_queries_during_guidance_leave_no_setpoint_gap_over_two_command_intervals(zshape_model):
    port, zport = free_udp_port(), free_port()
    cfg = config(port, vehicle_id="fq")
    period = 1.0 / cfg.command.rate_hz
    asker_code = ASKER.format(port=zport)

    async def scenario() -> None:
        daemon = await GuidanceDaemon.create(cfg, zshape_model, default_zenoh_config(zport))
        task = asyncio.create_task(daemon.run())
        try:
            with ScriptedVehicle(port, start_ned=(1.5, -1.5)) as boat:
                await until(lambda: daemon.state.value == "guiding", 15.0)
                t0 = boat.t
                asker = await asyncio.create_subprocess_exec(
                    sys.executable, "-c", asker_code, stdout=asyncio.subprocess.PIPE
                )
                out, _ = await asyncio.wait_for(asker.communicate(), 60.0)
                await asyncio.sleep(max(0.0, 1.5 - (boat.t - t0)))  # a window of 1.5 s at least around the queries
                t1 = boat.t
                times = [r.t for r in boat.setpoints(since=t0) if r.t <= t1]
                gaps = [b - a for a, b in itertools.pairwise(times)]
                replies = [json.loads(line) for line in out.decode().splitlines()]
                assert replies == [{"n": 200, "points": 200 * 200}] * 3, replies
                assert t1 - t0 > 1.0 and max(gaps) <= 2 * period, (
                    f"largest setpoint gap {max(gaps):.3f} s (period {period} s)"
                )
        finally:
            daemon.stop()
            await task

    asyncio.run(scenario())
