"""Whole missions: the real simulator (speed-up 10, slower when it cannot keep that pace) and the real
service over loopback MAVLink, with currents, zenoh status and the field queryable. Ground truth comes
from the simulator's recorder."""

from __future__ import annotations

import asyncio
import json
import math
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import zenoh

from koopguide.bus.status import STATUS_FIELDS, decode_status
from koopguide.bus.zenoh_config import default_zenoh_config
from koopguide.guidance import settings
from koopguide.harness import mission
from sitl import config as sitl_config
from tests.support.status_samples import free_port

pytestmark = pytest.mark.flight  # closed-loop flights: `make test` runs them on two workers (pyproject.toml)

SPEEDUP = 10.0  # mission.fly_paced flies a run again slower if the simulator could not keep this pace
ARRIVE_M = 0.15


def fly(model: Path, start: int, flow: dict | None, zenoh_port: int | None = None, timeout_s: float = 120.0):
    cfg, sim_cfg, pose = mission.demo_mission(model, start, 0.0, SPEEDUP)
    if flow is not None:
        sim_cfg = sitl_config.load(
            overrides=mission.sim_overrides(
                pose,
                int(cfg.mavlink.endpoint.rsplit(":", 1)[1]),
                {"north_m": list(sim_cfg.world.north_m), "east_m": list(sim_cfg.world.east_m)},
                SPEEDUP,
                flow,
            )
        )
    zenoh_config = default_zenoh_config(zenoh_port) if zenoh_port else None
    return cfg, asyncio.run(mission.fly_paced(cfg, model, sim_cfg, timeout_s, settle_s=20.0, zenoh_config=zenoh_config))


def first_time_within(result: mission.MissionResult, radius: float) -> float | None:
    d = np.hypot(result.track[:, 1], result.track[:, 2])
    inside = np.nonzero(d <= radius)[0]
    return float(result.track[inside[0], 0]) if len(inside) else None


def current(direction_deg: float) -> dict:
    return {"kinds": ["uniform"], "uniform": {"speed_mps": 0.03, "direction_deg": direction_deg}}


GYRE = {"kinds": ["double_gyre"], "double_gyre": {"origin_ned_m": [-1.0, -2.5], "scale_m": 1.5, "amplitude_mps": 0.02}}


@pytest.mark.timeout(120)
def test_done_when_mission_reaches_the_goal_in_a_cross_current_with_zenoh_status(zshape_model: Path) -> None:
    """Zshape start, goal NED (0, 0), scale 0.04, heading 90, 0.3 m/s, 0.03 m/s current across the final leg."""
    port = free_port()
    listener = zenoh.open(default_zenoh_config(port))
    statuses = listener.declare_subscriber("koopguide/demo/status", zenoh.handlers.RingChannel(4096))
    field_replies: list = []

    def ask_field() -> None:  # while the mission runs: a dashboard asks for the field
        deadline = time.monotonic() + 20
        while not field_replies and time.monotonic() < deadline:
            field_replies.extend(r for r in listener.get("koopguide/demo/field?n=12", timeout=2.0) if r.ok)
            time.sleep(0.2)

    asker = threading.Thread(target=ask_field)
    asker.start()
    try:
        _, result = fly(zshape_model, 3, current(180.0), zenoh_port=port)
        asker.join()
        received = []
        while (sample := statuses.try_recv()) is not None:
            received.append(decode_status(sample.payload.to_bytes()))
    finally:
        listener.close()
    t_in = first_time_within(result, ARRIVE_M)
    t0 = result.track[0, 0]
    assert result.arrived and t_in is not None
    assert result.arrival_time_s <= 75.0, result.arrival_time_s
    assert result.max_setpoint_mps <= 0.3
    assert result.max_distance_after_arrival_m <= 0.2, result.max_distance_after_arrival_m
    assert t_in - t0 <= 75.0 + 5.0  # ground truth agrees (5 s: the simulator starts before the first setpoint)
    states = [s["state"] for s in received]
    assert "guiding" in states and "arrived" in states
    assert states.index("arrived") > states.index("guiding")
    assert all(set(STATUS_FIELDS) <= set(s) for s in received)
    last = received[-1]
    assert last["state"] == "arrived" and last["mode"] == "GUIDED" and last["armed"] is True  # keeping station
    assert last["goal_ned"] == [0.0, 0.0]
    cn, ce = last["current_ned"]  # the estimated current: 0.03 m/s toward the south
    assert cn == pytest.approx(-0.03, abs=0.008) and ce == pytest.approx(0.0, abs=0.008)
    assert last["loop_latency_ms"]["p99"] is not None
    assert field_replies, "the field queryable did not answer"
    grid = json.loads(field_replies[0].ok.payload.to_string())
    assert grid["n"] == 12 and len(grid["position_ned"]) == 144
    assert max(math.hypot(*v) for v in grid["velocity_ned"]) <= 0.3 + 1e-6


@pytest.mark.timeout(120)
@pytest.mark.parametrize(
    ("start", "flow"),
    [(0, current(0.0)), (1, current(0.0)), (2, GYRE), (4, current(180.0)), (5, current(270.0)), (6, current(90.0))],
)
def test_missions_from_demo_starts_arrive_in_currents_and_keep_station(
    zshape_model: Path, start: int, flow: dict
) -> None:
    cfg, result = fly(zshape_model, start, flow)
    assert result.arrived, f"final distance {result.final_distance_m:.2f} m"
    assert result.arrival_time_s <= 75.0, result.arrival_time_s
    assert first_time_within(result, ARRIVE_M + 0.01) is not None  # the true boat, not only the estimate
    assert result.max_setpoint_mps <= cfg.command.max_speed_mps
    assert [s for _, s in result.transitions][:3] == ["waiting", "guiding", "arrived"]
    # the boat arrives facing into the current and keeps station: it does not drift off with it
    bound = 0.5 if flow is GYRE else 0.2  # a gyre's current changes along the way; the estimate lags it
    assert result.max_distance_after_arrival_m <= bound, result.max_distance_after_arrival_m


@pytest.mark.timeout(120)
def test_arriving_across_the_current_the_boat_stays_within_0_2_m(zshape_model: Path) -> None:
    """The demo's case: the final leg runs east, the current north, across it."""
    _, result = fly(zshape_model, 0, current(0.0))
    assert result.arrived and result.arrival_time_s <= 75.0
    assert result.max_distance_after_arrival_m <= 0.2, result.max_distance_after_arrival_m


@pytest.mark.timeout(120)
def test_on_arrival_loiter_settles_onto_the_goal_then_hands_over_to_loiter(zshape_model: Path) -> None:
    cfg, sim_cfg, _ = mission.demo_mission(zshape_model, 3, 0.0, SPEEDUP)
    cfg = replace(cfg, arrival=replace(cfg.arrival, on_arrival=settings.ArrivalAction.LOITER))
    result = asyncio.run(
        mission.fly_paced(cfg, zshape_model, sim_cfg, 120.0, settle_s=cfg.arrival.settle_timeout_s + 10)
    )
    assert result.arrived
    assert result.mode_before_exit == "LOITER"
    assert result.max_distance_after_arrival_m <= 0.2  # no current here: LOITER holds it
