"""Two-boat encounters for the separation guarantee (issue 13), and ``koopguide bench separation``.

Each encounter flies two simulated boats, each with its own guidance service and zenoh session (the fleet
harness, koopguide.harness.fleet_demo), on the LASA ``Line`` field placed so that boat k comes in on compass
course ``courses_deg[k]`` to its slot around the shared goal NED (0, 0): head-on (courses 180 deg apart),
crossing at an angle, or overtaking (one course, the boat ahead slower). The slots are given so that each
boat has to get past the other: its slot lies beyond the other boat's. Figures from the simulator's
ground-truth record: the smallest distance between the boats and each boat's final distance to its slot.
Conventions: local NED metres, compass degrees, simulated seconds.
"""

from __future__ import annotations

import argparse
import asyncio
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from koopguide.harness import fleet_demo

SHAPE = "Line"  # a straight demonstration: the courses are the frames' placement alone
SPEEDUP = 4.0  # simulated seconds per wall second (fleet_demo.FLEET_MAX_SPEEDUP)
CURRENT_MPS = 0.03  # the current of the "current" runs [m/s], toward the north (across east-west courses)
SLOT_RADIUS_M = 0.15  # arrival: each boat within this of its slot at the end [m]


@dataclass(frozen=True)
class Encounter:
    name: str
    courses_deg: tuple[float, float]  # each boat's compass course into the goal [deg]
    slot_east: tuple[bool, bool]  # whether boat k's slot is the east one (the slots lie east-west of the goal)
    ahead: float = 0.0  # boat 2 starts this fraction of the way along the demonstration (overtaking) [-]
    speeds_mps: tuple[float, float] = (0.3, 0.3)  # each boat's max_speed_mps [m/s]


ENCOUNTERS = {
    e.name: e
    for e in (
        Encounter("head_on", (90.0, 270.0), (True, False)),
        Encounter("crossing_60", (150.0, 210.0), (True, False)),
        Encounter("crossing_90", (135.0, 225.0), (True, False)),
        Encounter("crossing_120", (120.0, 240.0), (True, False)),
        Encounter("overtaking", (90.0, 90.0), (True, False), ahead=0.35, speeds_mps=(0.3, 0.1)),
    )
}


@dataclass(frozen=True)
class EncounterResult:
    encounter: str
    vehicle: str
    current_mps: float
    min_separation_m: float  # ground truth [m]
    slot_errors_m: tuple[float, ...]  # each boat's final true distance to its slot [m]
    arrival_s: tuple[float | None, ...]  # simulated time to arrival [s]; None: never arrived
    filter_seen: bool  # some status said separation_active
    wall_s: float  # of the attempt counted
    speedup: float  # the simulator's speed-up in the attempt counted [-]
    behind_max_s: float  # how far that attempt fell behind its pace (fleet_demo.FleetResult) [simulated s]

    @property
    def arrived(self) -> bool:
        return all(t is not None for t in self.arrival_s) and max(self.slot_errors_m) <= SLOT_RADIUS_M


def free_tcp_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def course_heading_deg(field_: Any, start_model: np.ndarray, course_deg: float) -> float:
    """The frame heading (compass of model +x) that makes the straight way from ``start_model`` to the field's
    goal run on compass ``course_deg`` (model angle phi maps to compass heading - phi, frames.py)."""
    way = np.asarray(field_.goal, dtype=float) - np.asarray(start_model, dtype=float)
    return (course_deg + math.degrees(math.atan2(way[1], way[0]))) % 360.0


def setup(
    encounter: Encounter,
    model: Path,
    vehicle: str,
    current_mps: float,
    speedup: float = SPEEDUP,
    guidance: dict[str, Any] | None = None,
) -> tuple:
    """(configs, simulator config) of ``encounter`` with ``vehicle`` boats in a current toward the north;
    ``guidance``: overrides of both boats' guidance config (as the file's keys)."""
    from koopguide.base import config, data
    from koopguide.guidance import settings
    from koopguide.model.field import load_field

    demo = data.load_lasa(SHAPE).trajectories[0]
    field_ = load_field(model)
    starts = [demo[0], demo[int(encounter.ahead * (len(demo) - 1))]]
    headings = [course_heading_deg(field_, s, c) for s, c in zip(starts, encounter.courses_deg, strict=True)]
    half = 0.5 * settings.load().fleet.slot_separation_m
    slots = np.array([[0.0, half if east else -half] for east in encounter.slot_east])
    flow = {"kinds": ["uniform"], "uniform": {"speed_mps": current_mps, "direction_deg": 0.0, "drift_std_mps": 0.0}}
    sim_extra = {"vehicle": vehicle, "flow": flow if current_mps > 0 else {"kinds": ["none"]}}
    per_boat = [config.merge({"command": {"max_speed_mps": s}}, guidance or {}) for s in encounter.speeds_mps]
    cfgs, sim_cfg, _ = fleet_demo.fleet_setup(
        model, starts, speedup, headings, sim_extra=sim_extra, per_boat=per_boat, slots_ned=slots
    )
    return cfgs, sim_cfg


def fly(
    encounter: Encounter,
    model: Path,
    vehicle: str = "diff_thrust",
    current_mps: float = 0.0,
    zenoh_config: Any = None,
    timeout_s: float = 120.0,
    settle_s: float = 8.0,
    speedup: float = SPEEDUP,
    attempts: int = 3,
    guidance: dict[str, Any] | None = None,
) -> EncounterResult:
    """Fly one encounter (one zenoh config for both services: peers on loopback; default a fresh port per
    attempt; ``guidance``: as :func:`setup`). As the mission campaign's ``fly_paced``: a run that fell behind
    its pace by more than ``mission.pace_limit_s`` (a busy machine: the services held for want of positions, or
    answered late) says nothing about the separation, so it is flown again at half the speed-up; PaceError after
    ``attempts``."""
    from koopguide.bus.zenoh_config import default_zenoh_config
    from koopguide.harness.mission import pace_limit_s, slower_until_paced

    async def at(x: float) -> tuple[fleet_demo.FleetResult, float, float, float]:
        """(the result, its wall time [s], its speed-up, its pace limit [simulated s])."""
        cfgs, sim_cfg = setup(encounter, model, vehicle, current_mps, x, guidance)
        zc = default_zenoh_config(free_tcp_port()) if zenoh_config is None else zenoh_config
        start = time.monotonic()
        result = await fleet_demo.fly_fleet(cfgs, model, sim_cfg, timeout_s, [zc] * 2, settle_s=settle_s)
        return result, time.monotonic() - start, x, pace_limit_s(cfgs[0])

    what = f"encounter {encounter.name}"
    result, wall_s, x, _ = asyncio.run(
        slower_until_paced(at, lambda r: (r[0].behind_max_s, r[3]), speedup, attempts, what)
    )
    return EncounterResult(
        encounter.name,
        vehicle,
        current_mps,
        result.min_separation_m,
        tuple(b.slot_error_m for b in result.boats),
        tuple(b.arrival_time_s for b in result.boats),
        any(b.separation_seen for b in result.boats),
        wall_s,
        x,
        result.behind_max_s,
    )


def main(argv: list[str] | None = None) -> int:
    """``koopguide bench separation``: every encounter x vehicle x (calm, current); prints one row each."""
    parser = argparse.ArgumentParser(prog="koopguide bench separation", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--encounters", default=",".join(ENCOUNTERS), help="comma-separated, of " + ", ".join(ENCOUNTERS)
    )
    parser.add_argument("--vehicles", default="diff_thrust,rudder,vectored", help="simulator vehicle kinds")
    parser.add_argument("--currents", default=f"0,{CURRENT_MPS}", help="current speeds toward the north [m/s]")
    parser.add_argument("--model", type=Path, default=Path("out/line.pt"), help="Line model (trained if missing)")
    parser.add_argument("--speedup", type=float, default=SPEEDUP, help="simulated s per wall s")
    args = parser.parse_args(argv)
    names = [n for n in args.encounters.split(",") if n]
    unknown = sorted(set(names) - set(ENCOUNTERS))
    if unknown:
        raise ValueError(f"--encounters: unknown {unknown}; known: {sorted(ENCOUNTERS)}")
    if not args.model.is_file():
        from koopguide.base import data
        from koopguide.model.learn.export import train_to_file

        args.model.parent.mkdir(parents=True, exist_ok=True)
        print(f"training {SHAPE} into {args.model}", file=sys.stderr)
        train_to_file(data.load_lasa(SHAPE), args.model, seed=0)
    from koopguide.guidance import settings

    d_min = settings.load().fleet.min_separation_m
    print(
        f"min_separation_m {d_min:g}, arrival within {SLOT_RADIUS_M:g} m; simulator x{args.speedup:g} (shared machine)"
    )
    print(
        f"{'encounter':13s} {'vehicle':11s} {'current':>7s} {'min sep [m]':>11s} {'slot errors [m]':>16s} "
        f"{'arrival [s]':>14s} {'filter':>6s} {'ok':>3s}"
    )
    failures = 0
    for vehicle in [v for v in args.vehicles.split(",") if v]:
        for current in [float(c) for c in args.currents.split(",") if c]:
            for name in names:
                r = fly(ENCOUNTERS[name], args.model, vehicle, current, speedup=args.speedup)
                ok = r.min_separation_m >= d_min and r.arrived
                failures += not ok
                errors = " ".join(f"{e:.3f}" for e in r.slot_errors_m)
                times = " ".join("-" if t is None else f"{t:.0f}" for t in r.arrival_s)
                print(
                    f"{name:13s} {vehicle:11s} {current:7.2f} {r.min_separation_m:11.3f} {errors:>16s} "
                    f"{times:>14s} {'yes' if r.filter_seen else 'no':>6s} {'ok' if ok else 'NO':>3s}",
                    flush=True,
                )
    print(f"{failures} encounter(s) broke the separation or did not arrive")
    return 0
