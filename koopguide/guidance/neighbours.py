"""The other boats a service has heard of lately, and the separation filter of its setpoint (pure, no I/O).

The service feeds :class:`~koopguide.guidance.events.NeighbourStatus` events (other vehicles' zenoh
statuses); :meth:`Neighbours.keep_separation` forgets those older than ``fleet.neighbour_timeout_s``,
moves each on at its last velocity to now, and filters the setpoint with the barrier-function filter of
:mod:`koopguide.guidance.law.separation`. Conventions: local NED [m], [m/s]; the timeout is in wall
seconds (how long ago it was heard), the move-on in this vehicle's time [s] (so a simulator at speed-up X
moves the others on at X times the wall clock, as it moves the boats).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from koopguide.guidance import events as ev
from koopguide.guidance.law import separation
from koopguide.guidance.law.maneuver import wrap_pi
from koopguide.guidance.settings import FleetSettings

# The barrier's distance is min_separation_m plus an allowance for what the boat does before it follows a new
# setpoint (each constant measured on the bundled simulator's 0.4 m boats, docs/fleet.md "Separation"):
REACTION_S = 0.3  # a fix's age when its setpoint acts: 0.1 s setpoint period, fix latency, the autopilot's lag [s]
BRAKE_MPS2 = 0.3  # deceleration a boat manages (the simulated ones: 0.3 m/s to rest in 0.12 m, mean 0.37) [m/s^2]
TURN_CREEP_M = 0.1  # how far a boat may creep along its heading while it turns away (skid-steer: 0.11 m per 90 deg) [m]
ESTIMATE_M = 0.02  # both boats' position errors: own estimate and the neighbour's moved-on status (<= 0.015) [m]
CREEP_SEEN_MPS = 0.003  # a neighbour moving faster than this may creep on along its course while it turns [m/s]
TURN_SPEED_MPS = 0.02  # while turning toward the filtered direction, the speed floor (keeps the direction) [m/s]
DRIFT_SEEN_MPS = 0.01  # drift across the heading faster than this is the water's, not the estimate's noise [m/s]
HEADING_SPEED_MPS = 0.001  # the least setpoint speed: it carries the direction to turn to (zero would turn north) [m/s]


@dataclass(frozen=True)
class Filtered:
    velocity_ned: tuple[float, float]  # the setpoint to send [m/s]
    active: bool  # changed to keep the separation
    note: str  # for the reason when active ("" otherwise)
    closest_m: float | None  # the nearest boat heard of [m]; None: none
    yaw_rad: float | None = None  # the yaw to send with it (astern), None: velocity only


class Neighbours:
    def __init__(self, own_id: str, fleet: FleetSettings, max_speed_mps: float) -> None:
        self.own_id, self.fleet, self.max_speed_mps = own_id, fleet, max_speed_mps
        self.latest: dict[str, ev.NeighbourStatus] = {}  # by vehicle id
        self.detour_sides: dict[str, int] = {}  # the side this boat goes round each parked neighbour (filter)

    def hear(self, status: ev.NeighbourStatus) -> None:
        if status.vehicle_id != self.own_id:
            self.latest[status.vehicle_id] = status

    def current(self, t_s: float, wall_s: float) -> list[separation.Neighbour]:
        """The boats heard within the timeout (wall ``wall_s``), each moved on at its last velocity to vehicle
        time ``t_s``."""
        return [nb for nb, _ in self.current_with_ages(t_s, wall_s)]

    def current_with_ages(self, t_s: float, wall_s: float) -> list[tuple[separation.Neighbour, float]]:
        """:meth:`current`, each with how far it was moved on [s, vehicle time]."""
        timeout = self.fleet.neighbour_timeout_s
        self.latest = {k: n for k, n in self.latest.items() if n.age_s + wall_s - n.wall_s <= timeout}
        out = []
        for n in self.latest.values():
            age = max(0.0, t_s - n.t_s)
            moved = (n.position_ned[0] + n.velocity_ned[0] * age, n.position_ned[1] + n.velocity_ned[1] * age)
            out.append((separation.Neighbour(n.vehicle_id, moved, n.velocity_ned), age))
        return out

    @staticmethod
    def margins(
        position_ned: np.ndarray,
        velocity_ned: np.ndarray,
        others: list[separation.Neighbour],
        ages_s: list[float] | None = None,
        heading_rad: float | None = None,
        turn_to_rad: float | None = None,
    ) -> np.ndarray:
        """Per neighbour, the allowance [m] beyond min_separation_m, for what the barrier condition on the
        setpoint does not see (each boat keeps its own allowance; both boats run this filter):
        - ESTIMATE_M, the position estimates' error;
        - BRAKE_MPS2 x age^2 / 2: how far the neighbour may have left the course it was moved on along since
          its status (``ages_s``, vehicle time) - the reachable set of a boat of bounded acceleration;
        - closing speed x REACTION_S: the gap closed before this boat's setpoint acts (the neighbour is already
          moved on to now at its last velocity);
        - own closing speed^2 / (2 BRAKE_MPS2): its braking distance;
        - TURN_CREEP_M x (how far this bow points at the neighbour now or on its turn to ``turn_to_rad``,
          :func:`sweep_facing`, + how far the neighbour's course points at this boat): a boat turning on the
          spot creeps on along its bow, and a boat cannot stop that by its setpoint.
        Boats at rest side by side need only the first."""
        p, v = np.asarray(position_ned, dtype=float), np.asarray(velocity_ned, dtype=float)
        out = []
        for k, nb in enumerate(others):
            gap = np.asarray(nb.position_ned) - p
            toward = gap / max(float(np.hypot(*gap)), 1e-9)  # unit vector to the neighbour
            own = max(float(toward @ v), 0.0)
            closing = max(float(toward @ (v - np.asarray(nb.velocity_ned))), 0.0)
            age = ages_s[k] if ages_s is not None else 0.0
            bearing = math.atan2(toward[1], toward[0])
            facing = 0.0 if heading_rad is None else sweep_facing(heading_rad, turn_to_rad, bearing)
            vj = np.asarray(nb.velocity_ned, dtype=float)
            speed_j = float(np.hypot(*vj))
            if speed_j > CREEP_SEEN_MPS:  # the neighbour's bow (its velocity's direction) toward this boat
                facing += max(-float(toward @ vj) / speed_j, 0.0)
            unheard = 0.5 * BRAKE_MPS2 * age**2  # how far it may have left its course since it was heard
            braking = own**2 / (2.0 * BRAKE_MPS2)
            out.append(ESTIMATE_M + unheard + closing * REACTION_S + braking + TURN_CREEP_M * facing)
        return np.array(out)

    def keep_separation(
        self,
        position_ned: np.ndarray,
        v: tuple[float, float],
        t_s: float,
        wall_s: float,
        heading_rad: float | None,
        velocity_ned: np.ndarray | None = None,
        yaw_rad: float | None = None,
    ) -> Filtered:
        """Filter ``v`` [m/s] with the barrier conditions at min_separation_m plus :meth:`margins` (the turn toward
        ``v``, then once more toward the filtered velocity); then, with the heading known, (1) while the bow points more
        than 90 deg off the filtered velocity, slow down to turn first, and (2) cap the speed so that the conditions
        hold for the velocity the boat has *until* it has turned, along its heading plus its measured drift
        (separation.heading_speed_cap); or, (3) where with that drift the speed along its heading closes on a neighbour,
        send the boat along its heading at the nearest speed, either way, that keeps the gap
        (separation.heading_escape_speed; astern as velocity + yaw at its heading): a skid-steer boat held across a
        0.03 m/s current drifted 0.3 m onto a boat held beside it, its setpoint 0.001 m/s, to 0.15 m apart (two-boat
        encounter, both in direct pursuit; stop 46).
        The helm's ``yaw_rad`` pointing away from ``v`` means astern: the boat drives along its stern, and the filter
        reasons about that way (the heading turned by pi). A velocity the filter changes goes velocity-only (the boat
        turns to it, as the filter expects) unless the boat can go on astern along it."""
        astern = yaw_rad is not None and _astern(v, yaw_rad)
        if heading_rad is not None and astern:
            heading_rad += math.pi
        heard = self.current_with_ages(t_s, wall_s)
        if not heard:
            return Filtered(v, False, "", None, yaw_rad)
        others, ages = [nb for nb, _ in heard], [age for _, age in heard]
        own_v = np.zeros(2) if velocity_ned is None else np.asarray(velocity_ned, dtype=float)
        p, fleet, wanted = np.asarray(position_ned, dtype=float), self.fleet, np.array(v, dtype=float)
        hold = fleet.min_separation_m + ESTIMATE_M  # within the allowance only hold the gap; part within this

        def passes(toward: np.ndarray) -> tuple[np.ndarray, separation.SeparationResult]:
            turn_to = math.atan2(toward[1], toward[0]) if np.hypot(*toward) > 1e-12 else None
            d = fleet.min_separation_m + self.margins(p, own_v, others, ages, heading_rad, turn_to)
            return d, separation.separation_filter(
                self.own_id,
                p,
                wanted,
                others,
                d,
                fleet.barrier_gain_per_s,
                self.max_speed_mps,
                recover_within_m=hold,
                detour_sides=self.detour_sides,
            )

        distance, out = passes(wanted)
        if out.active:  # the boat turns toward the filtered velocity instead: its own sweep
            distance, out = passes(out.velocity_ned)
        filtered, active = out.velocity_ned, out.active
        self.detour_sides = out.detours
        speed = float(np.hypot(*filtered))
        escape = None
        if heading_rad is not None:
            bow = np.array([np.cos(heading_rad), np.sin(heading_rad)])
            a, b = separation.barrier_rows(p, others, distance, fleet.barrier_gain_per_s, hold)
            drift = own_v - float(own_v @ bow) * bow  # across the heading [m/s]
            if float(np.hypot(*drift)) > DRIFT_SEEN_MPS:  # (noise read as drift walked a boat off its slot)
                # Rover drives it at the setpoint's speed along its heading until it has turned (as for the cap)
                escape = separation.heading_escape_speed(a, b, bow, drift, self.max_speed_mps, speed)
            if escape is not None:  # drifting toward a neighbour: along the heading, whichever way keeps the gap
                filtered, active = escape * bow, True
            elif speed > 1e-12:
                if active and speed > TURN_SPEED_MPS:  # turn first: cos(heading error), floored
                    filtered = filtered * max(float(filtered @ bow) / speed, TURN_SPEED_MPS / speed)
                    speed = float(np.hypot(*filtered))
                cap = max(separation.heading_speed_cap(a, b, bow, drift), HEADING_SPEED_MPS)
                if speed > cap:
                    filtered, active = filtered * (cap / speed), True
        if not active:
            return Filtered(v, False, "", out.closest_m, yaw_rad)
        who = f", yielding to {', '.join(out.yielding_to)}" if out.yielding_to else ""
        note = f"separation active: nearest boat {out.closest_m:.2f} m (min {fleet.min_separation_m:g}){who}"
        f = (float(filtered[0]), float(filtered[1]))
        if escape is not None:  # the bow held: astern (velocity + yaw) where the escape runs against it
            bow_rad = heading_rad - math.pi if astern else heading_rad
            return Filtered(f, True, note, out.closest_m, bow_rad if _astern(f, bow_rad) else None)
        return Filtered(f, True, note, out.closest_m, yaw_rad if astern and _astern(f, yaw_rad) else None)


def _astern(v: tuple[float, float] | np.ndarray, yaw_rad: float) -> bool:
    """Whether velocity ``v`` [m/s] held at heading ``yaw_rad`` [rad] is astern (against the bow)."""
    return float(v[0]) * math.cos(yaw_rad) + float(v[1]) * math.sin(yaw_rad) < 0.0


def sweep_facing(heading_rad: float, turn_to_rad: float | None, bearing_rad: float) -> float:
    """The largest cos(bow - bearing), clipped at 0, over the bow's turn from ``heading_rad`` the short way to
    ``turn_to_rad`` (as Rover turns to a new heading): 1 when the bow sweeps past the neighbour's bearing.
    A turn on the spot creeps along the bow, so this is how much of the creep is toward the neighbour."""
    off = wrap_pi(bearing_rad - heading_rad)
    if turn_to_rad is None:
        return max(math.cos(off), 0.0)
    turn = wrap_pi(turn_to_rad - heading_rad)
    if (0.0 <= off <= turn) or (turn <= off <= 0.0):
        return 1.0
    return max(math.cos(off), math.cos(off - turn), 0.0)


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
