"""Two guidance services, each with its own MAVLink link and zenoh session, steer two simulated boats on
crossing courses: they hear each other only through their zenoh statuses, keep min_separation_m (ground
truth) and both arrive at their rendezvous slots."""

from __future__ import annotations

import asyncio
import socket
import time
from pathlib import Path

import numpy as np
import pytest

from koopguide.base import data
from koopguide.bus.zenoh_config import default_zenoh_config
from koopguide.harness import fleet_demo
from koopguide.harness.mission import pace_limit_s

SPEEDUP = 3.0


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.timeout(150)
def test_two_services_on_crossing_courses_keep_separation_and_reach_their_slots(zshape_model: Path) -> None:
    start = data.load_lasa("Zshape").trajectories[0][0]
    # boat1's field runs East into the goal, boat2's (its frame turned 180 deg) West; boat1 gets the east
    # slot and boat2 the west one, so that their courses cross at the goal
    cfgs, sim_cfg, poses = fleet_demo.fleet_setup(zshape_model, [start, start], SPEEDUP, [90.0, 270.0], crossing=True)
    assert cfgs[0].frame.goal_ned[1] > 0 > cfgs[1].frame.goal_ned[1] and poses[0][1] < 0 < poses[1][1]
    port = free_tcp_port()
    zenoh_configs = [default_zenoh_config(port), default_zenoh_config(port)]  # two sessions, peers on loopback
    result = asyncio.run(fleet_demo.fly_fleet(cfgs, zshape_model, sim_cfg, 120.0, zenoh_configs, settle_s=8.0))
    for boat in result.boats:
        print(
            f"{boat.vehicle_id}: slot {boat.slot_ned}, arrival {boat.arrival_time_s} s, "
            f"slot error {boat.slot_error_m:.3f} m, separation filter seen: {boat.separation_seen}"
        )
    print(f"minimum separation (ground truth): {result.min_separation_m:.3f} m")
    d_min = cfgs[0].fleet.min_separation_m
    assert result.min_separation_m >= d_min, result.min_separation_m  # never closer, from the simulator's record
    assert all(b.arrival_time_s is not None for b in result.boats), [b.arrival_time_s for b in result.boats]
    assert all(b.slot_error_m <= 0.15 for b in result.boats), [b.slot_error_m for b in result.boats]
    assert any(b.separation_seen for b in result.boats)  # the courses crossed: the filter had to act
    slots = np.array([b.slot_ned for b in result.boats])
    assert np.linalg.norm(slots[0] - slots[1]) == pytest.approx(cfgs[0].fleet.slot_separation_m)


async def fly_with_stalls(cfgs: list, model: Path, sim_cfg: object, stall_s: float) -> fleet_demo.FleetResult:
    """A short fleet run while, every 1.5 s of wall clock, something holds the services' event loop for
    ``stall_s`` (a busy machine: 0 is no stall)."""

    async def stalls() -> None:
        while True:
            await asyncio.sleep(1.5)
            time.sleep(stall_s)  # noqa: ASYNC251 -- blocking the loop is the point

    stall = asyncio.create_task(stalls())
    port = free_tcp_port()
    try:
        return await fleet_demo.fly_fleet(cfgs, model, sim_cfg, 6.0, [default_zenoh_config(port)] * 2, settle_s=1.0)
    finally:
        stall.cancel()


@pytest.mark.timeout(120)
def test_a_fleet_run_whose_services_were_starved_reads_as_behind_its_pace(zshape_model: Path) -> None:
    """The encounter harness flies a run again slower when it fell behind its pace (fleet_encounters.fly): a stall
    of the loop the services run on must show in ``behind_max_s`` (wall stall x speed-up), a free run must not."""
    start = data.load_lasa("Zshape").trajectories[0][0]
    cfgs, sim_cfg, _ = fleet_demo.fleet_setup(zshape_model, [start, start], SPEEDUP, [90.0, 270.0], crossing=True)
    limit_s = pace_limit_s(cfgs[0])
    free = asyncio.run(fly_with_stalls(cfgs, zshape_model, sim_cfg, 0.0))
    cfgs, sim_cfg, _ = fleet_demo.fleet_setup(zshape_model, [start, start], SPEEDUP, [90.0, 270.0], crossing=True)
    starved = asyncio.run(fly_with_stalls(cfgs, zshape_model, sim_cfg, 0.4))
    print(f"behind its pace: free {free.behind_max_s:.3f} s, starved {starved.behind_max_s:.3f} s (limit {limit_s} s)")
    assert free.behind_max_s <= limit_s, free.behind_max_s
    assert starved.behind_max_s >= 0.9 * 0.4 * SPEEDUP > limit_s, starved.behind_max_s
