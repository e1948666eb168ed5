"""A whole simulated mission: the bundled simulator and the guidance service, meeting over loopback MAVLink.

Used by ``koopguide demo`` and by the end-to-end tests. The simulator runs on its own thread
(:class:`sitl.runner.SimulationThread`) and sends to the service's listening UDP port; the service runs
on the caller's event loop, exactly as ``koopguide run`` does. Ground truth comes from the simulator's
recorder. Conventions: local NED metres, simulated (vehicle) seconds.
"""

from __future__ import annotations

import asyncio
import math
import socket
import sys
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from koopguide.guidance.law.command import GuidanceLaw
from koopguide.guidance.law.frames import ModelFrame
from koopguide.guidance.settings import GuidanceConfig
from koopguide.model.field import FlowField

R = TypeVar("R")

TANK_M = (4.5, 3.0)  # the paper's tank, N x E [m]
DEMO_SETTLE_S = 20.0  # simulated seconds the demo keeps watching after arrival


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def demo_start_pose(field_: FlowField, frame: ModelFrame, start: np.ndarray) -> tuple[float, float, float]:
    """(N, E, heading_deg) at a model point, heading along the field there."""
    n, e = frame.to_ned(start)
    vn, ve = frame.direction_to_ned(field_.velocity(start))
    return float(n), float(e), math.degrees(math.atan2(ve, vn))


def tank_around(points_ned: np.ndarray, margin_m: float = 0.6) -> dict[str, list[float]]:
    """A world box (the paper's tank size when it fits) containing ``points_ned`` with a margin."""
    lo, hi = points_ned.min(axis=0) - margin_m, points_ned.max(axis=0) + margin_m
    size = np.maximum(hi - lo, TANK_M)
    mid = 0.5 * (lo + hi)
    return {
        "north_m": [float(mid[0] - size[0] / 2), float(mid[0] + size[0] / 2)],
        "east_m": [float(mid[1] - size[1] / 2), float(mid[1] + size[1] / 2)],
    }


def sim_overrides(
    pose: tuple[float, float, float],
    port: int,
    world: dict[str, list[float]],
    speedup: float,
    flow: dict[str, Any] | None = None,
    seed: int = 0,
) -> dict[str, Any]:
    """The simulator config for one boat at ``pose`` sending MAVLink to the service on ``port``."""
    return {
        "seed": seed,
        "speedup": speedup,
        "start_poses": [list(pose)],
        "world": {"walls": True, **world},
        "mavlink": {"endpoints": [f"udpout:127.0.0.1:{port}"]},
        "flow": flow or {"kinds": ["none"]},
        "recorder": {"rate_hz": 10.0},
    }


@dataclass
class MissionResult:
    arrived: bool
    arrival_time_s: float | None  # simulated time from the service's first setpoint to arrival
    arrived_at_s: float | None  # simulated time of arrival (the clock of ``track``)
    track: np.ndarray  # (T, 3): t, N, E of the true boat [s, m, m]
    transitions: list[tuple[float, str]]
    max_setpoint_mps: float
    final_distance_m: float
    max_distance_after_arrival_m: float | None
    mode_before_exit: str | None  # the vehicle's mode when the service began to shut down
    law: GuidanceLaw  # the service's guidance law (its field, frame and speed gain)
    # the furthest the simulator fell behind its pace (simulated s): on a busy machine it catches up in
    # bursts while the service waits for positions, which a real vehicle never does
    sim_behind_max_s: float
    sim_speedup: float  # the simulator's speed-up in this run [-]

    def paced(self, cfg: GuidanceConfig) -> bool:
        """Whether the simulator kept its pace: it never fell behind by more than half of ``stale_after_s``
        (beyond that the service's holds for want of positions are the machine's, see :func:`fly_paced`)."""
        return self.sim_behind_max_s <= pace_limit_s(cfg)


def pace_limit_s(cfg: GuidanceConfig) -> float:
    """How far the simulator may fall behind its pace in a valid run: half the service's ``stale_after_s``."""
    return 0.5 * cfg.failsafe.stale_after_s


async def fly(
    cfg: GuidanceConfig,
    model: Path,
    sim_cfg: Any,
    timeout_s: float,
    settle_s: float = 20.0,
    zenoh_config: Any | None = None,
    progress: bool = False,
    log_path: Path | None = None,
) -> MissionResult:
    """Run one mission: until arrival plus ``settle_s`` simulated seconds, or ``timeout_s`` after start;
    ``log_path``: the service's mission log (MCAP, as ``koopguide run --log``)."""
    from koopguide.guidance.daemon import GuidanceDaemon
    from sitl.runner import SimulationThread

    records: list[dict[str, Any]] = []
    daemon = await GuidanceDaemon.create(cfg, model, zenoh_config, log_path)
    runner = asyncio.create_task(daemon.run())
    behind_s = 0.0
    try:
        with SimulationThread(sim_cfg, records) as sim:
            t_start = t_arrived = None
            last_print = -math.inf
            wall_guard = time.monotonic() + 10.0 + 3.0 * (timeout_s + settle_s) / max(sim_cfg.speedup, 0.5)
            while time.monotonic() < wall_guard and not runner.done():
                await asyncio.sleep(0.02)
                t = daemon.clock.now()
                if t_start is None and daemon.setpoints_sent > 0:
                    t_start = t
                    sim.call(lambda s: s.reset_pace())  # the pace counts from the first setpoint
                if t_arrived is None and daemon.arrived:
                    t_arrived = t
                if progress and t - last_print >= 5.0 and daemon.clock.started:
                    last_print = t
                    print_progress(daemon.status())
                if t_start is not None and t_arrived is None and t - t_start > timeout_s:
                    break
                if t_arrived is not None and t - t_arrived >= settle_s:
                    break
            behind_s = sim.behind_max_s
            daemon.stop()
            await runner
    finally:
        if not runner.done():
            daemon.stop()
            await runner
    return summarize(daemon, records, t_start, t_arrived, behind_s, sim_cfg.speedup)


class PaceError(RuntimeError):
    """The simulator could not keep its pace, even slowed down: the machine is too busy for a valid mission."""


async def fly_paced(
    cfg: GuidanceConfig, model: Path, sim_cfg: Any, timeout_s: float, attempts: int = 3, **kwargs: Any
) -> MissionResult:
    """:func:`fly`, flown again at half the speed-up while the simulator fell behind its pace by more than
    half the service's ``stale_after_s``. At speed-up X a pause of the process (a busy machine) of p wall
    seconds is X p simulated seconds in which the simulator catches up in a burst and the service, rightly,
    holds for want of fresh positions; such a run says nothing about guidance, so it is not counted.
    The verdict depends on the pace only, never on the mission's outcome. PaceError after ``attempts``."""

    async def at(speedup: float) -> MissionResult:
        return await fly(cfg, model, replace(sim_cfg, speedup=speedup), timeout_s, **kwargs)

    limit_s = pace_limit_s(cfg)
    return await slower_until_paced(at, lambda r: (r.sim_behind_max_s, limit_s), sim_cfg.speedup, attempts, "mission")


async def slower_until_paced(
    fly_at: Callable[[float], Awaitable[R]],
    pace: Callable[[R], tuple[float, float]],
    speedup: float,
    attempts: int,
    what: str,
) -> R:
    """``fly_at(speedup)``, flown again at half the speed-up while its result fell behind its pace by more than
    it may: ``pace(result)`` is (how far it fell behind, the limit: :func:`pace_limit_s`) in simulated seconds.
    PaceError after ``attempts``."""
    lags = []
    for _ in range(attempts):
        result = await fly_at(speedup)
        behind_s, limit_s = pace(result)
        if behind_s <= limit_s:
            return result
        lags.append(f"{behind_s:.2f} s at x{speedup:g}")
        print(f"{what}: fell behind its pace by {lags[-1]}; flying it again slower", file=sys.stderr)
        speedup *= 0.5
    raise PaceError(f"{what} fell behind its pace by more than {limit_s:.2f} s in every attempt: {lags}")


def summarize(
    daemon: Any,
    records: list[dict[str, Any]],
    t_start: float | None,
    t_arrived: float | None,
    behind_s: float,
    speedup: float,
) -> MissionResult:
    states = [r for r in records if r.get("kind") == "state"]
    track = np.array([[r["t"], r["n"], r["e"]] for r in states]) if states else np.zeros((0, 3))
    goal = daemon.law.goal_ned
    dist = np.hypot(track[:, 1] - goal[0], track[:, 2] - goal[1]) if len(track) else np.array([math.inf])
    after = None
    if t_arrived is not None and len(track):
        mask = track[:, 0] >= t_arrived
        after = float(dist[mask].max()) if mask.any() else None
    return MissionResult(
        arrived=t_arrived is not None,
        arrival_time_s=None if t_arrived is None or t_start is None else t_arrived - t_start,
        arrived_at_s=t_arrived,
        track=track,
        transitions=list(daemon.transitions),
        max_setpoint_mps=daemon.max_cmd_speed,
        final_distance_m=float(dist[-1]),
        max_distance_after_arrival_m=after,
        law=daemon.law,
        mode_before_exit=daemon.mode_before_exit,
        sim_behind_max_s=behind_s,
        sim_speedup=speedup,
    )


def print_progress(status: dict[str, Any]) -> None:
    pos = status["position_ned"]
    where = f"N {pos[0]:+.2f} E {pos[1]:+.2f} m" if pos else "no position yet"
    dist = status["distance_to_goal_m"]
    speed = math.hypot(*status["cmd_velocity_ned"])
    print(
        f"  t {status['vehicle_time_s']:6.1f} s  {status['state']:8s} {status['mode'] or '-':7s} {where}  "
        f"to goal {dist if dist is not None else float('nan'):.2f} m  cmd {speed:.2f} m/s",
        file=sys.stderr,
    )


def mission_at(
    model: Path,
    start_model: np.ndarray,
    speedup: float,
    flow: dict[str, Any] | None = None,
    vehicle_id: str = "demo",
    seed: int = 0,
    sim_extra: dict[str, Any] | None = None,
    guidance_extra: dict[str, Any] | None = None,
) -> tuple[GuidanceConfig, Any, tuple[float, float, float]]:
    """The README's mission set-up from any model point: goal at NED (0, 0), 0.04 m per unit, model +x
    East, 0.3 m/s top speed; the boat starts at ``start_model`` heading along the field, in a tank around
    the model's domain. ``flow`` is the simulator's ``flow`` section (None: calm water); ``sim_extra`` and
    ``guidance_extra`` are further overrides of the simulator's and the service's configs."""
    from koopguide.base import config
    from koopguide.guidance import settings
    from koopguide.model.field import load_field
    from sitl import config as sitl_config

    port = free_udp_port()
    cfg = settings.load(
        overrides=config.merge(
            {
                "vehicle_id": vehicle_id,
                "arm": True,
                "mavlink": {"endpoint": f"udp:127.0.0.1:{port}"},
                "frame": {"goal_ned": [0.0, 0.0], "scale": 0.04, "heading_deg": 90.0},
                "command": {"max_speed_mps": 0.3},
            },
            guidance_extra or {},
        )
    )
    field_ = load_field(model)
    frame = ModelFrame.place(field_.goal, cfg.frame)
    pose = demo_start_pose(field_, frame, np.asarray(start_model, dtype=float))
    lo, hi = field_.bounds
    corners = frame.to_ned(np.array([lo, hi, [lo[0], hi[1]], [hi[0], lo[1]]]))
    world = tank_around(np.vstack([corners, [pose[:2]]]))
    overrides = config.merge(sim_overrides(pose, port, world, speedup, flow, seed), sim_extra or {})
    return cfg, sitl_config.load(overrides=overrides), pose


def demo_mission(
    model: Path, start_index: int, current_mps: float, speedup: float, vehicle_id: str = "demo", seed: int = 0
) -> tuple[GuidanceConfig, Any, tuple[float, float, float]]:
    """The README's mission from a Zshape demo start, in a uniform current toward the north (across the
    field's final leg)."""
    from koopguide.base import data

    starts = data.load_lasa("Zshape").trajectories
    if not 0 <= start_index < len(starts):
        raise ValueError(f"--start must be 0 .. {len(starts) - 1}, got {start_index}")
    flow = {"kinds": ["uniform"], "uniform": {"speed_mps": current_mps, "direction_deg": 0.0}} if current_mps else None
    return mission_at(model, starts[start_index][0], speedup, flow, vehicle_id, seed)


def run_demo(args: Any) -> int:
    """``koopguide demo``: train Zshape if no cached model, fly the mission in the simulator (logged as MCAP),
    plot it and animate its log."""
    import logging

    from koopguide.base import data
    from koopguide.bus.missionlog import read_mission
    from koopguide.bus.zenoh_config import load_zenoh_config
    from koopguide.dashboard.replay import render_replay
    from koopguide.harness.mission_plot import plot_mission
    from koopguide.model.learn.export import train_to_file
    from sitl.flow import Flow

    if args.speedup <= 0:
        raise ValueError(f"--speedup must be > 0, got {args.speedup}")
    zenoh_config = load_zenoh_config(args.zenoh_config)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    args.out.mkdir(parents=True, exist_ok=True)
    model = args.out / "zshape.pt"
    if not model.is_file():
        print(f"koopguide demo: no cached model; training Zshape into {model}", file=sys.stderr)
        train_to_file(data.load_lasa("Zshape"), model, seed=0)
    cfg, sim_cfg, pose = demo_mission(model, args.start, args.current_mps, args.speedup)
    print(
        f"koopguide demo: boat at N {pose[0]:.2f} E {pose[1]:.2f} m heading {pose[2]:.0f} deg, goal N 0 E 0, "
        f"current {args.current_mps:.2f} m/s toward north, simulator x{args.speedup:g}; "
        f"status on zenoh koopguide/{cfg.vehicle_id}/status (watch: koopguide monitor)",
        file=sys.stderr,
    )
    log = args.out / "demo.mcap"
    result = asyncio.run(
        fly(
            cfg,
            model,
            sim_cfg,
            args.timeout_s,
            settle_s=DEMO_SETTLE_S,
            zenoh_config=zenoh_config,
            progress=True,
            log_path=log,
        )
    )
    world = sim_cfg.world
    box = np.array([[world.north_m[0], world.east_m[0]], [world.north_m[1], world.east_m[1]]])
    flow = Flow(sim_cfg.flow, np.random.default_rng(0))
    png = args.out / "demo.png"
    verdict = (
        f"arrived in {result.arrival_time_s:.1f} s" if result.arrived else f"did not arrive within {args.timeout_s:g} s"
    )
    plot_mission(
        png,
        result.law.field_velocity_ned,
        box,
        result.track,
        pose[:2],
        cfg.frame.goal_ned,
        cfg.arrival.radius_m,
        lambda n, e: flow.velocity(n, e, 0.0),
        f"koopguide demo: Zshape, {verdict}",
    )
    gif = args.out / "demo.gif"
    frames = render_replay(read_mission(log), gif)
    after = result.max_distance_after_arrival_m
    if not result.paced(cfg):
        print(
            f"koopguide demo: WARNING the simulator fell {result.sim_behind_max_s:.2f} s behind its pace (a busy "
            f"machine): the service held for want of fresh positions then; try a lower --speedup",
            file=sys.stderr,
        )
    print(
        f"koopguide demo: {verdict}; largest setpoint {result.max_setpoint_mps:.3f} m/s"
        + (f"; within {after:.2f} m of the goal for {DEMO_SETTLE_S:.0f} s after arrival" if after is not None else "")
        + f"; wrote {png}, {log} and {gif} ({frames} frames)",
        file=sys.stderr,
    )
    return 0 if result.arrived else 1
