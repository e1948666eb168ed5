"""Helpers for socket-free vehicle tests: one boat in open water (no walls), stepped by hand.

``run`` holds fixed actuator commands (open loop); ``fly`` runs the boat's own autopilot (50 Hz) on
top of the physics (100 Hz), resending a guided setpoint at 5 Hz the way a guidance service does.
Trajectories are numpy arrays with columns (t [s], N [m], E [m], psi [rad], V_N [m/s], V_E [m/s]) of
ground truth.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sitl.autopilot import MODE_NUMBERS, Frame, interpret_position_target
from sitl.boat import Boat
from sitl.flow import Flow
from sitl.vehicles import VehicleParams
from sitl.world import Tank
from tests.support.sitl_gcs import sim_config, sitl_config_merge

DT = 0.01  # physics step [s]
CONTROL_EVERY = 2  # autopilot at 50 Hz
SETPOINT_EVERY = 20  # setpoints at 5 Hz


def current(speed_mps: float, toward_deg: float) -> dict[str, Any]:
    return {"flow": {"kinds": ["uniform"], "uniform": {"speed_mps": speed_mps, "direction_deg": toward_deg}}}


def make_boat(kind: str, pose=(0.0, 0.0, 0.0), overrides: dict[str, Any] | None = None) -> tuple[Boat, Flow]:
    cfg = sim_config(sitl_config_merge({"world": {"walls": False}, "vehicle": kind}, overrides or {}))
    vehicle = VehicleParams.from_config(cfg.vessel, cfg.vehicle)
    flow = Flow(cfg.flow, np.random.default_rng(0))
    boat = Boat(1, cfg, vehicle, flow, Tank(cfg.world, 0.2), pose, np.random.default_rng(1))
    return boat, flow


def _row(boat: Boat) -> tuple[float, ...]:
    truth = boat.truth()
    return (boat.t, truth.n, truth.e, truth.psi, truth.vn, truth.ve)


def run(boat: Boat, flow: Flow, seconds: float, commands: tuple[float, ...]) -> np.ndarray:
    """Hold fixed actuator commands for ``seconds`` of simulated time."""
    boat.autopilot.commands = commands
    rows = []
    for _ in range(round(seconds / DT)):
        boat.physics_step(boat.t, DT)
        flow.advance(DT)
        rows.append(_row(boat))
    return np.array(rows)


def fly(
    boat: Boat,
    flow: Flow,
    seconds: float,
    mode: str = "GUIDED",
    mask: int | None = None,
    velocity: tuple[float, float] = (0.0, 0.0),
    yaw: float = 0.0,
    position: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """Arm in ``mode`` (after the first position fix) and run the autopilot, resending a setpoint."""
    ap = boat.autopilot
    while not boat.navigation().position_ok:
        boat.physics_step(boat.t, DT)
        flow.advance(DT)
    if ap.mode != MODE_NUMBERS[mode]:
        assert ap.set_mode(MODE_NUMBERS[mode], boat.navigation()) == 0
    if not ap.armed:
        assert ap.arm(True, False, boat.navigation()) == 0
    rows = []
    for k in range(round(seconds / DT)):
        if mask is not None and k % SETPOINT_EVERY == 0:
            nav = boat.navigation()
            cap = ap.params.get("WP_SPEED")
            target = interpret_position_target(mask, Frame.LOCAL_NED, position, velocity, yaw, 0.0, nav, cap)
            assert ap.set_guided_target(target, boat.t, (nav.n, nav.e))
        boat.physics_step(boat.t, DT)
        flow.advance(DT)
        if k % CONTROL_EVERY == CONTROL_EVERY - 1:
            boat.control_step(CONTROL_EVERY * DT)
        rows.append(_row(boat))
    return np.array(rows)
