"""The other boats a service has heard of lately, and the separation filter of its setpoint (pure, no I/O).

The service feeds :class:`~koopguide.guidance.events.NeighbourStatus` events (other vehicles' zenoh
statuses); :meth:`Neighbours.keep_separation` forgets those older than ``fleet.neighbour_timeout_s``,
moves each on at its last velocity to now, and filters the setpoint with the barrier-function filter of
:mod:`koopguide.guidance.law.separation`. Conventions: local NED [m], [m/s]; ``wall_s`` the service's
monotonic clock [s].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from koopguide.guidance import events as ev
from koopguide.guidance.law import separation
from koopguide.guidance.settings import FleetSettings


@dataclass(frozen=True)
class Filtered:
    velocity_ned: tuple[float, float]  # the setpoint to send [m/s]
    active: bool  # changed to keep the separation
    note: str  # for the reason when active ("" otherwise)
    closest_m: float | None  # the nearest boat heard of [m]; None: none


class Neighbours:
    def __init__(self, own_id: str, fleet: FleetSettings, max_speed_mps: float) -> None:
        self.own_id, self.fleet, self.max_speed_mps = own_id, fleet, max_speed_mps
        self.latest: dict[str, ev.NeighbourStatus] = {}  # by vehicle id

    def hear(self, status: ev.NeighbourStatus) -> None:
        if status.vehicle_id != self.own_id:
            self.latest[status.vehicle_id] = status

    def current(self, wall_s: float) -> list[separation.Neighbour]:
        """The boats heard within the timeout, each moved on at its last velocity to ``wall_s``."""

        def age(n: ev.NeighbourStatus) -> float:
            return n.age_s + wall_s - n.wall_s

        self.latest = {k: n for k, n in self.latest.items() if age(n) <= self.fleet.neighbour_timeout_s}
        return [
            separation.Neighbour(
                n.vehicle_id,
                (n.position_ned[0] + n.velocity_ned[0] * age(n), n.position_ned[1] + n.velocity_ned[1] * age(n)),
                n.velocity_ned,
            )
            for n in self.latest.values()
        ]

    def keep_separation(self, position_ned: np.ndarray, v: tuple[float, float], wall_s: float) -> Filtered:
        others = self.current(wall_s)
        if not others:
            return Filtered(v, False, "", None)
        fleet = self.fleet
        out = separation.separation_filter(
            self.own_id,
            position_ned,
            np.array(v),
            others,
            fleet.min_separation_m,
            fleet.barrier_gain_per_s,
            self.max_speed_mps,
        )
        if not out.active:
            return Filtered(v, False, "", out.closest_m)
        who = f", yielding to {', '.join(out.yielding_to)}" if out.yielding_to else ""
        note = f"separation active: nearest boat {out.closest_m:.2f} m (min {fleet.min_separation_m:g}){who}"
        return Filtered((float(out.velocity_ned[0]), float(out.velocity_ned[1])), True, note, out.closest_m)
