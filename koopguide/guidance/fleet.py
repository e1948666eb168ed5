"""``koopguide fleet``: N vehicles guided from one process (one asyncio loop, one GuidanceDaemon per vehicle).

Each vehicle has its own MAVLink link (endpoint, target system id), estimators, law, supervisor and
status key ``koopguide/<id>/status``; they share the model and the frame. The shared goal is split into
rendezvous slots ``slot_separation_m`` apart, assigned from the vehicles' first fixes (crossing-free,
koopguide.guidance.law.separation); until every vehicle has a fix (or ``first_fix_timeout_s`` passed),
no vehicle is guided. The daemons keep their separation through each other's zenoh statuses, as separate
processes would (``fleet.*`` keys of the guidance config). Conventions: local NED [m], wall seconds.
"""

from __future__ import annotations

import asyncio
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np

from koopguide.base import config
from koopguide.base.config import ConfigError, Range, check
from koopguide.guidance.law.separation import slot_goals
from koopguide.guidance.settings import VEHICLE_ID, GuidanceConfig

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FleetVehicle:
    id: str  # vehicle id: the zenoh key segment koopguide/<id>/...
    endpoint: str  # its MAVLink endpoint (as mavlink.endpoint)
    target_system: Annotated[int, Range(1, 255)]  # its system id

    def __post_init__(self) -> None:
        check(bool(VEHICLE_ID.match(self.id)), "vehicles[].id", self.id, "1-64 characters of A-Z a-z 0-9 _ -")


@dataclass(frozen=True)
class FleetConfig:
    model: Path  # the shared model file (.pt)
    guidance: Path | None  # a guidance config file for every vehicle (null: the shipped defaults)
    goal_ned: tuple[Annotated[float, Range()], Annotated[float, Range()]]  # the shared goal [N_m, E_m]
    scale: Annotated[float, Range(0.0, 1e6, lo_open=True)]  # metres per model unit
    heading_deg: Annotated[float, Range(-360.0, 360.0)]  # compass heading of the model's +x axis
    slot_separation_m: Annotated[float, Range(0.0, 100.0, lo_open=True)]  # neighbouring slots this far apart [m]
    first_fix_timeout_s: Annotated[float, Range(0.0, 3600.0, lo_open=True)]  # wait this long for every fix [s]
    vehicles: tuple[FleetVehicle, ...]

    def __post_init__(self) -> None:
        check(len(self.vehicles) >= 1, "vehicles", list(self.vehicles), "at least one vehicle")
        ids = [v.id for v in self.vehicles]
        check(len(set(ids)) == len(ids), "vehicles[].id", ids, "distinct ids")
        links = [(v.endpoint, v.target_system) for v in self.vehicles]
        check(len(set(links)) == len(links), "vehicles[]", links, "distinct (endpoint, target_system) pairs")


def load_fleet(path: str | Path) -> FleetConfig:
    """The fleet file: unknown keys, missing keys and out-of-range numbers are ConfigErrors."""
    return config.build(FleetConfig, config.load_yaml(path))


def vehicle_configs(fleet: FleetConfig) -> list[GuidanceConfig]:
    """One guidance config per vehicle: the shared file, then the fleet's frame and the vehicle's link."""
    from koopguide.guidance import settings

    out = []
    for v in fleet.vehicles:
        out.append(
            settings.load(
                fleet.guidance,
                {
                    "vehicle_id": v.id,
                    "mavlink": {"endpoint": v.endpoint, "target_system": v.target_system},
                    "frame": {
                        "goal_ned": list(fleet.goal_ned),
                        "goal_latlon": None,
                        "scale": fleet.scale,
                        "heading_deg": fleet.heading_deg,
                    },
                    "fleet": {"slot_separation_m": fleet.slot_separation_m},
                },
            )
        )
    return out


async def wait_first_fixes(daemons: list[Any], timeout_s: float) -> np.ndarray:
    """(n, 2) each vehicle's first estimated position [m]; ConfigError naming the silent ones on timeout."""
    deadline = time.monotonic() + timeout_s
    while True:
        fixes = [d.estimate() for d in daemons]
        if all(f is not None for f in fixes):
            return np.array([f[0] for f in fixes])
        if time.monotonic() > deadline:
            silent = [d.cfg.vehicle_id for d, f in zip(daemons, fixes, strict=True) if f is None]
            raise ConfigError(
                f"fleet: no position fix from {', '.join(silent)} within {timeout_s:g} s "
                "(check their endpoints and target systems)"
            )
        await asyncio.sleep(0.05)


async def run_fleet(fleet: FleetConfig, zenoh_config: Any, stop: asyncio.Event) -> int:
    """Guide every vehicle until ``stop`` is set; then each shuts down (zero velocity, exit mode)."""
    from koopguide.guidance.daemon import GuidanceDaemon

    cfgs = vehicle_configs(fleet)
    daemons: list[GuidanceDaemon] = []
    runners: list[asyncio.Task[None]] = []
    try:
        for cfg in cfgs:
            daemons.append(await GuidanceDaemon.create(cfg, fleet.model, zenoh_config))
        for d in daemons:  # a fix may trigger a decision before run(): no goal until the slots are assigned
            d.supervisor.goal_placed = False
        starts = await wait_first_fixes(daemons, fleet.first_fix_timeout_s)
        slots = slot_goals(np.array(fleet.goal_ned), starts, fleet.slot_separation_m)
        for d, start, slot in zip(daemons, starts, slots, strict=True):
            d.law.place_goal((float(slot[0]), float(slot[1])))
            d.supervisor.goal_placed = True
            log.info("%s: first fix N %.2f E %.2f m -> slot N %.2f E %.2f m", d.cfg.vehicle_id, *start, *slot)
        runners = [asyncio.create_task(d.run()) for d in daemons]
        await stop.wait()
    finally:
        for d in daemons:
            d.stop()
        await asyncio.gather(*runners, return_exceptions=True)
        if not runners:  # never ran: close what was opened (run() closes its own)
            for d in daemons:
                await d.close()
    return 0
