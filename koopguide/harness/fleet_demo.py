"""A simulated fleet: N boats in the bundled simulator, one guidance service (GuidanceDaemon) per boat.

Used by ``koopguide demo --fleet N`` and the fleet tests. One simulator (its own thread) with ``count = N``
boats; boat k (system id k + 1) sends to its own service's UDP port (``port_stride``, sitl/runner.py); each
service runs on the caller's event loop with its own MAVLink link and its own zenoh session, and hears
the others only through their zenoh statuses, exactly as separate processes would. Each boat's goal is
its rendezvous slot around the shared goal (koopguide.guidance.law.separation). Ground truth comes from
the simulator's recorder. Conventions: local NED metres, simulated (vehicle) seconds.
"""

from __future__ import annotations

import asyncio
import itertools
import math
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from koopguide.guidance.law.command import GuidanceState
from koopguide.guidance.law.frames import ModelFrame
from koopguide.guidance.law.separation import slot_goals
from koopguide.guidance.settings import GuidanceConfig
from koopguide.harness.mission import demo_start_pose, free_udp_port, tank_around

FLEET_SETTLE_S = 15.0  # simulated seconds watched after the last boat arrived
SLOT_ROOM_M = 0.5  # the tank reaches at least this far beyond each slot, plus tank_around's margin [m]
FLEET_MAX_SPEEDUP = 4.0  # the demo runs the simulator at most this fast: two services share the machine
LOOP_SLEEP_S = 0.02  # the watcher's sleep between looks at the services [wall s]


@dataclass
class BoatResult:
    vehicle_id: str
    slot_ned: tuple[float, float]  # [m]
    arrival_time_s: float | None  # simulated time from the first setpoint to arrival [s]
    slot_error_m: float  # true final distance to the slot [m]
    track: np.ndarray  # (T, 3): t, N, E of the true boat [s, m, m]
    separation_seen: bool  # its status said separation_active at least once


@dataclass
class FleetResult:
    boats: list[BoatResult]
    min_separation_m: float  # smallest true distance between any two boats at any record [m]
    # the furthest the run fell behind its pace after the first setpoint [simulated s]: the simulator's own lag,
    # or a stall of the services' event loop (wall seconds beyond its sleep, times the speed-up), whichever is
    # larger; past mission.pace_limit_s the services held for want of positions because the machine was busy
    behind_max_s: float = 0.0

    def all_within(self, radius_m: float) -> bool:
        return all(b.arrival_time_s is not None and b.slot_error_m <= radius_m for b in self.boats)


def ports_with_stride(n: int) -> tuple[int, int]:
    """A first port and a stride such that port + k * stride (k < n) are all free UDP ports on loopback."""
    for _ in range(50):
        ports = sorted({free_udp_port() for _ in range(n)})
        if len(ports) < n:
            continue
        if n == 1:
            return ports[0], 0
        stride = ports[1] - ports[0]
        if stride > 0 and all(p == ports[0] + k * stride for k, p in enumerate(ports)):
            return ports[0], stride
        if n == 2 or all(_udp_free(ports[0] + k * stride) for k in range(n)):
            return ports[0], stride
    raise OSError(f"no {n} free UDP ports with a common stride on 127.0.0.1")


def _udp_free(port: int) -> bool:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def fleet_setup(
    model: Path,
    starts_model: list[np.ndarray],
    speedup: float,
    headings_deg: list[float] | None = None,
    guidance_extra: dict[str, Any] | None = None,
    sim_extra: dict[str, Any] | None = None,
    crossing: bool = False,
    per_boat: list[dict[str, Any]] | None = None,
    slots_ned: np.ndarray | None = None,
) -> tuple[list[GuidanceConfig], Any, list[tuple[float, float, float]]]:
    """N services and one N-boat simulator: boat k starts at ``starts_model[k]`` (its frame's model
    coordinates, the frame's +x along ``headings_deg[k]``, default 90) heading along the field; the shared goal
    is NED (0, 0), split into slots ``fleet.slot_separation_m`` apart, assigned from the start positions
    (``crossing``: in reverse order instead, so that the boats' courses cross, for tests). ``per_boat[k]``:
    guidance overrides of boat k alone (e.g. its max speed); ``slots_ned`` (n, 2): each boat's goal instead of
    its assigned slot [m]."""
    from koopguide.base import config
    from koopguide.guidance import settings
    from koopguide.model.field import load_field
    from sitl import config as sitl_config

    n = len(starts_model)
    headings = headings_deg or [90.0] * n
    base = config.merge(
        {
            "arm": True,
            "frame": {"goal_ned": [0.0, 0.0], "scale": 0.04},
            "command": {"max_speed_mps": 0.3},
            "status": {"rate_hz": 20.0},
        },
        guidance_extra or {},
    )
    field_ = load_field(model)
    poses, corners = [], []
    for start, heading in zip(starts_model, headings, strict=True):
        cfg0 = settings.load(overrides=config.merge(base, {"frame": {"heading_deg": heading}}))
        frame = ModelFrame.place(field_.goal, cfg0.frame)
        poses.append(demo_start_pose(field_, frame, np.asarray(start, dtype=float)))
        lo, hi = field_.bounds
        corners.append(frame.to_ned(np.array([lo, hi, [lo[0], hi[1]], [hi[0], lo[1]]])))
    separation = settings.load(overrides=base).fleet.slot_separation_m
    goals = slot_goals(np.zeros(2), np.array([p[:2] for p in poses]), separation)
    goals = goals[::-1] if crossing else goals
    goals = goals if slots_ned is None else np.asarray(slots_ned, dtype=float).reshape(n, 2)
    port, stride = ports_with_stride(n)
    cfgs = [
        settings.load(
            overrides=config.merge(
                config.merge(base, (per_boat or [{}] * n)[k]),
                {
                    "vehicle_id": f"boat{k + 1}",
                    "mavlink": {"endpoint": f"udp:127.0.0.1:{port + k * stride}", "target_system": k + 1},
                    "frame": {"goal_ned": [float(goals[k][0]), float(goals[k][1])], "heading_deg": headings[k]},
                },
            )
        )
        for k in range(n)
    ]
    around_slots = goals[:, None, :] + SLOT_ROOM_M * np.array([[1, 1], [1, -1], [-1, 1], [-1, -1]])  # room to turn
    world = tank_around(np.vstack([*corners, [p[:2] for p in poses], *around_slots]))
    sim = config.merge(
        {
            "seed": 0,
            "count": n,
            "speedup": speedup,
            "start_poses": [list(p) for p in poses],
            "world": {"walls": True, **world},
            "flow": {"kinds": ["none"]},
            "recorder": {"rate_hz": 20.0},
            "mavlink": {"endpoints": [f"udpout:127.0.0.1:{port}"], "port_stride": stride},
        },
        sim_extra or {},
    )
    return cfgs, sitl_config.load(overrides=sim), poses


async def fly_fleet(
    cfgs: list[GuidanceConfig],
    model: Path,
    sim_cfg: Any,
    timeout_s: float,
    zenoh_configs: list[Any],
    settle_s: float = FLEET_SETTLE_S,
    progress: bool = False,
) -> FleetResult:
    """Run the fleet until every boat has been arrived at once for ``settle_s`` simulated seconds, or
    ``timeout_s`` after the start."""
    from koopguide.guidance.daemon import GuidanceDaemon
    from sitl.runner import SimulationThread

    records: list[dict[str, Any]] = []
    daemons: list[GuidanceDaemon] = []
    runners: list[asyncio.Task[None]] = []
    arrived: dict[str, float] = {}
    seen_active: set[str] = set()
    t_start = all_in = None
    loop_behind_s = behind_s = 0.0
    try:
        for cfg, zc in zip(cfgs, zenoh_configs, strict=True):
            daemons.append(await GuidanceDaemon.create(cfg, model, zc))
            runners.append(asyncio.create_task(daemons[-1].run()))
        with SimulationThread(sim_cfg, records) as sim:
            last_print = -math.inf
            wall_guard = time.monotonic() + 15.0 + 3.0 * (timeout_s + settle_s) / max(sim_cfg.speedup, 0.5)
            woke = time.monotonic()
            while time.monotonic() < wall_guard and not any(r.done() for r in runners):
                await asyncio.sleep(LOOP_SLEEP_S)
                t = daemons[0].clock.now()
                if t_start is not None:  # the services share this loop: a late wake-up is a stall of theirs too
                    stall_s = max(0.0, time.monotonic() - woke - LOOP_SLEEP_S) * sim_cfg.speedup
                    loop_behind_s = max(loop_behind_s, stall_s)
                woke = time.monotonic()
                if t_start is None and all(d.setpoints_sent > 0 for d in daemons):
                    t_start = t
                    sim.call(lambda s: s.reset_pace())  # the pace counts from the first setpoints
                for d in daemons:
                    if d.arrived and d.cfg.vehicle_id not in arrived:
                        arrived[d.cfg.vehicle_id] = d.clock.now()
                    if d.supervisor.separation_active:
                        seen_active.add(d.cfg.vehicle_id)
                if progress and t - last_print >= 5.0 and daemons[0].clock.started:
                    last_print = t
                    print_fleet_progress([d.status() for d in daemons])
                if t_start is not None and t - t_start > timeout_s:
                    break
                together = all(d.state is GuidanceState.ARRIVED for d in daemons)  # all at their slots now
                all_in = (all_in if all_in is not None else t) if together else None
                if all_in is not None and t - all_in >= settle_s:
                    break
            behind_s = max(loop_behind_s, sim.behind_max_s)
    finally:
        for d in daemons:
            d.stop()
        await asyncio.gather(*runners, return_exceptions=True)
    return replace(summarize_fleet(daemons, records, t_start, arrived, seen_active), behind_max_s=behind_s)


def summarize_fleet(
    daemons: list[Any],
    records: list[dict[str, Any]],
    t_start: float | None,
    arrived: dict[str, float],
    seen_active: set[str],
) -> FleetResult:
    tracks = ground_truth_tracks(records, len(daemons))
    boats = []
    for k, d in enumerate(daemons):
        track, goal = tracks[k], d.law.goal_ned
        error = float(np.hypot(track[-1, 1] - goal[0], track[-1, 2] - goal[1])) if len(track) else math.inf
        t_arr = arrived.get(d.cfg.vehicle_id)
        boats.append(
            BoatResult(
                d.cfg.vehicle_id,
                (float(goal[0]), float(goal[1])),
                None if t_arr is None or t_start is None else t_arr - t_start,
                error,
                track,
                d.cfg.vehicle_id in seen_active,
            )
        )
    return FleetResult(boats, min_separation(tracks))


def ground_truth_tracks(records: list[dict[str, Any]], n: int) -> list[np.ndarray]:
    """Per boat (system id k + 1): (T, 3) t, N, E from the recorder's state records."""
    out = []
    for k in range(n):
        rows = [[r["t"], r["n"], r["e"]] for r in records if r.get("kind") == "state" and r["sysid"] == k + 1]
        out.append(np.array(rows) if rows else np.zeros((0, 3)))
    return out


def min_separation(tracks: list[np.ndarray]) -> float:
    """The smallest distance between any two boats [m], each pair compared at the first's record times
    (the other's track interpolated)."""
    best = math.inf
    for a, b in itertools.combinations(tracks, 2):
        if len(a) < 2 or len(b) < 2:
            continue
        lo, hi = max(a[0, 0], b[0, 0]), min(a[-1, 0], b[-1, 0])
        mask = (a[:, 0] >= lo) & (a[:, 0] <= hi)
        t = a[mask, 0]
        bn, be = np.interp(t, b[:, 0], b[:, 1]), np.interp(t, b[:, 0], b[:, 2])
        if len(t):
            best = min(best, float(np.min(np.hypot(a[mask, 1] - bn, a[mask, 2] - be))))
    return best


def print_fleet_progress(statuses: list[dict[str, Any]]) -> None:
    parts = []
    for s in statuses:
        pos, dist = s["position_ned"], s["distance_to_goal_m"]
        where = f"N {pos[0]:+.2f} E {pos[1]:+.2f}" if pos else "no fix"
        sep = " SEP" if s.get("separation_active") else ""
        parts.append(
            f"{s['vehicle_id']} {s['state']:8s} {where} to slot {dist if dist is not None else float('nan'):.2f} m{sep}"
        )
    print(f"  t {statuses[0]['vehicle_time_s']:6.1f} s  " + " | ".join(parts), file=sys.stderr)


def run_fleet_demo(args: Any) -> int:
    """``koopguide demo --fleet 2``: Multi_Models_4 from both demonstration starts, two boats, two services."""
    import logging

    from koopguide.base import data
    from koopguide.bus.zenoh_config import load_zenoh_config
    from koopguide.harness.fleet_plot import animate_fleet, plot_fleet
    from koopguide.model.learn.export import train_to_file

    if args.fleet != 2:
        raise ValueError(f"--fleet: Multi_Models_4 has two demonstration starts, so 2 boats; got {args.fleet}")
    if args.speedup <= 0:
        raise ValueError(f"--speedup must be > 0, got {args.speedup}")
    speedup = min(args.speedup, FLEET_MAX_SPEEDUP)
    zenoh_config = load_zenoh_config(args.zenoh_config)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    args.out.mkdir(parents=True, exist_ok=True)
    model = args.out / "multi_models_4.pt"
    demos = data.load_lasa("Multi_Models_4")
    if not model.is_file():
        print(f"koopguide demo: no cached model; training Multi_Models_4 into {model}", file=sys.stderr)
        train_to_file(demos, model, seed=0)
    starts = [demos.trajectories[0][0], demos.trajectories[4][0]]  # one from each side
    cfgs, sim_cfg, poses = fleet_setup(model, starts, speedup)
    for cfg, pose in zip(cfgs, poses, strict=True):
        print(
            f"koopguide demo: {cfg.vehicle_id} at N {pose[0]:.2f} E {pose[1]:.2f} m -> slot "
            f"N {cfg.frame.goal_ned[0]:.2f} E {cfg.frame.goal_ned[1]:.2f} m",
            file=sys.stderr,
        )
    print(
        f"koopguide demo: simulator x{speedup:g}; min separation {cfgs[0].fleet.min_separation_m:g} m; "
        "statuses on zenoh koopguide/boat1|boat2/status",
        file=sys.stderr,
    )
    result = asyncio.run(fly_fleet(cfgs, model, sim_cfg, args.timeout_s, [zenoh_config] * len(cfgs), progress=True))
    from koopguide.guidance.law.command import GuidanceLaw
    from koopguide.model.field import load_field

    shared = GuidanceLaw.from_config(load_field(model), cfgs[0])
    shared.place_goal((0.0, 0.0))
    world = sim_cfg.world
    box = np.array([[world.north_m[0], world.east_m[0]], [world.north_m[1], world.east_m[1]]])
    tracks = [b.track for b in result.boats]
    slots = np.array([b.slot_ned for b in result.boats])
    d_min, radius = cfgs[0].fleet.min_separation_m, cfgs[0].arrival.radius_m
    title = f"koopguide demo --fleet 2: Multi_Models_4, min separation {result.min_separation_m:.2f} m"
    png, gif = args.out / "fleet.png", args.out / "fleet.gif"
    plot_fleet(png, shared.field_velocity_ned, box, tracks, slots, radius, title)
    animate_fleet(gif, shared.field_velocity_ned, box, tracks, slots, radius, d_min, title)
    for b in result.boats:
        arrival = f"arrived in {b.arrival_time_s:.1f} s" if b.arrival_time_s is not None else "did not arrive"
        print(
            f"koopguide demo: {b.vehicle_id} {arrival}, {b.slot_error_m:.3f} m from its slot at the end",
            file=sys.stderr,
        )
    ok_sep = result.min_separation_m >= d_min
    print(
        f"koopguide demo: boats never closer than {result.min_separation_m:.3f} m (ground truth; "
        f"min_separation_m {d_min:g}: {'kept' if ok_sep else 'BROKEN'}); wrote {png} and {gif}",
        file=sys.stderr,
    )
    return 0 if result.all_within(0.15) and ok_sep else 1
