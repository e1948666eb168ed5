"""The other boats a service has heard of lately, and the separation filter of its setpoint (pure, no I/O).

The service feeds :class:`~koopguide.guidance.events.NeighbourStatus` events (other vehicles' zenoh
statuses); :meth:`Neighbours.keep_separation` forgets those older than ``fleet.neighbour_timeout_s``,
moves each on at its last velocity to now, and filters the setpoint with the barrier-function filter of
:mod:`koopguide.guidance.law.separation`. Conventions: local NED [m], [m/s]; the timeout is in wall
seconds (how long ago it was heard), the move-on in this vehicle's time [s] (so a simulator at speed-up X
moves the others on at X times the wall clock, as it moves the boats).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from koopguide.guidance import events as ev
from koopguide.guidance.law import separation
from koopguide.guidance.settings import FleetSettings

MARGIN_M = 0.15  # the barrier keeps up to this much beyond min_separation_m: a boat does not turn or stop at once [m]
LAG_S = 4.0  # ... namely the closing speed times this (a boat's turn-and-slow lag), so boats at rest need none [s]
TURN_SPEED_MPS = 0.02  # while turning toward the filtered direction the speed floor (keeps the direction) [m/s]


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

    def current(self, t_s: float, wall_s: float) -> list[separation.Neighbour]:
        """The boats heard within the timeout (wall ``wall_s``), each moved on at its last velocity to vehicle
        time ``t_s``."""

        def age(n: ev.NeighbourStatus) -> float:
            return max(0.0, t_s - n.t_s)

        timeout = self.fleet.neighbour_timeout_s
        self.latest = {k: n for k, n in self.latest.items() if n.age_s + wall_s - n.wall_s <= timeout}
        return [
            separation.Neighbour(
                n.vehicle_id,
                (n.position_ned[0] + n.velocity_ned[0] * age(n), n.position_ned[1] + n.velocity_ned[1] * age(n)),
                n.velocity_ned,
            )
            for n in self.latest.values()
        ]

    @staticmethod
    def margins(position_ned: np.ndarray, velocity_ned: np.ndarray, others: list[separation.Neighbour]) -> np.ndarray:
        """Per neighbour: min(MARGIN_M, LAG_S x the speed at which the gap closes now) [m]."""
        out = []
        for nb in others:
            gap = np.asarray(position_ned, dtype=float) - np.asarray(nb.position_ned)
            unit = gap / max(float(np.hypot(*gap)), 1e-9)
            closing = -float(unit @ (velocity_ned - np.asarray(nb.velocity_ned)))
            out.append(min(MARGIN_M, LAG_S * max(closing, 0.0)))
        return np.array(out)

    def keep_separation(
        self,
        position_ned: np.ndarray,
        v: tuple[float, float],
        t_s: float,
        wall_s: float,
        heading_rad: float | None,
        velocity_ned: np.ndarray | None = None,
    ) -> Filtered:
        """Filter ``v`` [m/s]; while the filter is active and the bow points more than 90 deg off the filtered
        velocity, slow down to turn first (a boat drives on along its heading while it turns toward a new
        direction: at full speed that is toward the boat it must avoid)."""
        others = self.current(t_s, wall_s)
        own_v = np.zeros(2) if velocity_ned is None else np.asarray(velocity_ned, dtype=float)
        if not others:
            return Filtered(v, False, "", None)
        fleet = self.fleet
        out = separation.separation_filter(
            self.own_id,
            position_ned,
            np.array(v),
            others,
            fleet.min_separation_m + self.margins(position_ned, own_v, others),
            fleet.barrier_gain_per_s,
            self.max_speed_mps,
        )
        if not out.active:
            return Filtered(v, False, "", out.closest_m)
        who = f", yielding to {', '.join(out.yielding_to)}" if out.yielding_to else ""
        note = f"separation active: nearest boat {out.closest_m:.2f} m (min {fleet.min_separation_m:g}){who}"
        filtered = out.velocity_ned
        speed = float(np.hypot(*filtered))
        if heading_rad is not None and speed > TURN_SPEED_MPS:  # turn first: cos(heading error), floored
            facing = float(np.dot(filtered / speed, [np.cos(heading_rad), np.sin(heading_rad)]))
            filtered = filtered * max(facing, TURN_SPEED_MPS / speed)
        return Filtered((float(filtered[0]), float(filtered[1])), True, note, out.closest_m)


def neighbour_event(
    other: dict, unix_now: float, wall_now: float, vehicle_now: float, clock_rate: float, timeout_s: float
) -> ev.NeighbourStatus | None:
    """Another vehicle's decoded status as an event for the supervisor, or None when it has no position or
    is older than ``timeout_s`` (publication to now, unix clocks [s]). Its time on this vehicle's clock is
    ``vehicle_now`` minus its age scaled by the clock's rate (simulators run faster than the wall)."""
    age = max(0.0, unix_now - other["t"])
    if other["position_ned"] is None or other["velocity_ned"] is None or age > timeout_s:
        return None
    return ev.NeighbourStatus(
        wall_now,
        vehicle_now - age * clock_rate,
        other["vehicle_id"],
        tuple(other["position_ned"]),
        tuple(other["velocity_ned"]),
        age,
    )
