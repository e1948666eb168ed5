"""TurnProbe: at the start of guiding, asks the boat to turn and to stop, to tell how it turns (pure, no I/O).

The service does not know the boat it steers (docs/guidance.md "Any boat"). For up to ``command.probe_turn_s`` it
sends speed 0 at a heading ``PROBE_RAD`` off the boat's (velocity + yaw; Rover turns a skid-steer boat on the spot,
a rudder boat not at all):

1. a boat whose heading moves ``PROBE_MOVED_RAD`` turns in place, unless, where its way through the water is known,
   it made way enough for a circle of ``PIVOT_RADIUS_M`` or more: an autopilot that holds the boat's ground at speed
   0 (no stop controller) keeps way on through a current along the heading, and a rudder boat turns on it (a
   kinematic rudder boat of a 0.6 m circle, held astern at 0.026 m/s through the water, turned 10 deg in the probe's
   4 s, was taken to turn in place and followed the field onto a tank's wall: Zshape start 3 toward E, stop 58). One
   whose heading does not move, or moves on a circle that wide, needs way;
2. the latter is asked a hard turn under way (``PROBE_WAY_RAD`` off, at ``command.turn_speed_mps``) for as long
   again, which measures its turning circle (estimation/turning.py), to the side whose circle stays more inside the
   area. The whole turn: the circle is the tightest seen in it, and the first reading (1.5 s in, the turn still
   tightening) was 2-9 m against the rudder boat's 1.1-1.5 m. A boat that meanwhile goes where it was sent, across
   its heading (``SIDEWAYS_RAD``, at ``SIDEWAYS_MPS`` or more), its heading still where the probe began, is no
   rudder boat: its velocity follows the setpoint and its heading does not (taken for a rudder boat, it was steered
   by its heading onto lines it never turned to: 0 of 12 Zshape missions arrived). What is read is the change of
   its velocity over ground since the turn began, the way it was sent (within ``SENT_RAD``), for ``SIDEWAYS_S`` in
   a row: the current's part cancels out, where the current estimate would not serve. A rudder boat at rest in
   sheared water, its current estimate 0.05 m/s off, read through it as going across its heading one tick into the
   turn, was guided as a follower, by velocities, and pinned bow-on to a wall by the double gyre, which it never
   turned off; and the estimate soaks up a slow follower's motion as slip (2 s lag: read at 0.068 m/s at most, then
   sinking), stop 42. So is one whose heading comes round to the turn asked within ``COURSE_S``, a circle no rudder
   boat turns: its heading is the direction it moves in (astern, it flipped end for end, and held as a rudder boat
   it shuttled 0.1-0.35 m about the goal). The probe ends there;
3. then, with the way that turn gave it, speed 0 at its heading for ``PROBE_STOP_S``: how far it runs on
   (estimation/speed_lag.py; a hull of twice the mass with a weak astern ran 0.2 m past the goal on ramps made for
   the simulator's, and nothing else tells the service before the boat is first stopped, at the goal).

Conventions: NED velocities ``(2,)`` [m/s], headings [rad] from north, vehicle seconds.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from koopguide.guidance.estimation.turning import TurnAbility
from koopguide.guidance.law.maneuver import unit, wrap_pi
from koopguide.guidance.settings import CommandSettings

PROBE_RAD = math.radians(60.0)  # the turn in place asked at the start (command.probe_turn_s)
PROBE_MOVED_RAD = math.radians(10.0)  # the heading moved this much in the probe: the boat turns in place ...
PIVOT_RADIUS_M = 0.3  # ... if the way it made through the water meanwhile, over the angle, is less than this: the
# tightest rudder boat flown turns on 0.6 m (tests/support/kinematic_rudder.py), the simulator's on 0.86-1.3 m; a
# skid-steer boat held at speed 0 against 0.03 m/s along its heading, pivoting at 6 deg/s, turns on 0.29 m [m]
PROBE_WAY_RAD = math.radians(90.0)  # ... and the turn under way asked of a boat that needs way, for its circle
PROBE_CIRCLE_M = 1.5  # ... to the side where a circle this wide stays more inside the area [m]
PROBE_STOP_S = 2.5  # ... and then a stop under way asked of it, for how far it runs on [s]
SIDEWAYS_MPS = 0.06  # in the turn under way, a boat this fast through the water ... [m/s]
SIDEWAYS_RAD = math.radians(45.0)  # ... this far across its heading (which has not moved) goes where it is sent
SENT_RAD = math.radians(45.0)  # ... when it goes within this of the direction sent ...
SIDEWAYS_S = 0.5  # ... for this long in a row [s]
COURSE_S = 2.0  # a boat whose heading is within PROBE_MOVED_RAD of the turn asked under way this soon turns with its
# course: 90 deg at turn_speed_mps (0.15 m/s) in 2 s is a circle under 0.2 m, half a hull's length, no rudder boat's [s]
PROBE_DOING = {
    False: "asking a turn in place to tell how the boat turns",
    True: "asking a hard turn under way to measure its turning circle",
}
PROBE_STOP_DOING = "asking a stop under way to measure how far it runs on"
Command = tuple[np.ndarray, float | None]  # (velocity NED [m/s], yaw [rad] or None for velocity only)


class TurnProbe:
    """Call :meth:`command` each tick until it returns None; it writes what it sees into the boat's ability."""

    def __init__(self, cfg: CommandSettings, outside: Callable[[np.ndarray], np.ndarray]) -> None:
        self.cfg = cfg
        self.outside = outside  # how far points (K, 2) lie outside the area the boat may use [m]
        self.until: float | None = None  # vehicle time the stage under way ends [s]
        self.heading: float | None = None  # the heading it asks [rad]
        self.began: float | None = None  # the boat's heading when it began [rad]
        self.with_way = False  # the second stage (a boat that needs way: a hard turn under way) ...
        self.way_began: float | None = None  # ... began at this vehicle time [s]
        self.stop_until: float | None = None  # ... the third, a stop under way: until this vehicle time [s]
        self.ground_began: np.ndarray | None = None  # ... its ground velocity as it began [m/s]
        self.sideways_since: float | None = None  # ... in which the boat has gone where it was sent since [s]
        self.way_m: float | None = 0.0  # the way made through the water in the first stage (None: not known) [m]
        self.t: float | None = None  # the last call's vehicle time [s]

    @property
    def doing(self) -> str:
        """What the stage under way asks (for the status's reason)."""
        return PROBE_STOP_DOING if self.stop_until is not None else PROBE_DOING[self.with_way]

    def command(
        self,
        t: float,
        heading_rad: float | None,
        p_ned: np.ndarray | None,
        ability: TurnAbility,
        ground_ned: np.ndarray | None,
        water_mps: float | None = None,
    ) -> Command | None:
        """The probe's setpoint at vehicle time ``t``, None once done (or off, or no heading known). ``p_ned``: the
        boat's position [m] (None: the turn under way goes to starboard); ``ground_ned``: its velocity over ground
        [m/s] (None: not known, or at the area's edge, where a wall sets any boat sideways); ``water_mps``: its way
        through the water along its heading [m/s] (None: not known, no current estimate yet)."""
        a = ability
        if heading_rad is None or a.pivot_seen or a.moves_sideways:
            return None
        dt, self.t = (0.0 if self.t is None else max(t - self.t, 0.0)), t
        if self.until is None:
            self.until, self.began = t + self.cfg.probe_turn_s, heading_rad
            self.heading = wrap_pi(heading_rad + PROBE_RAD)
        if not self.with_way:
            self.way_m = None if self.way_m is None or water_mps is None else self.way_m + abs(water_mps) * dt
            moved = abs(wrap_pi(heading_rad - self.began))
            if moved >= PROBE_MOVED_RAD and (self.way_m is None or self.way_m < PIVOT_RADIUS_M * moved):
                a.pivot_seen, a.needs_way = True, False  # it turned without way: it turns in place
                return None
            if t < self.until:
                return np.zeros(2), self.heading
            if self.cfg.probe_turn_s <= 0.0:
                return None
            a.needs_way, self.with_way, self.way_began = True, True, t  # it did not turn: it needs way
            self.until = t + self.cfg.probe_turn_s
            self.heading = wrap_pi(heading_rad + self._side(heading_rad, p_ned) * PROBE_WAY_RAD)
        # in the turn under way only (the stop after it runs on in whatever direction the turn left it)
        if self.stop_until is None and (
            self._sideways(t, heading_rad, ground_ned) or self._with_course(t, heading_rad)
        ):
            a.moves_sideways, a.needs_way = True, False
            return None
        if t >= self.until:
            if self.stop_until is None:
                self.stop_until, self.heading = t + PROBE_STOP_S, heading_rad
            if t >= self.stop_until:
                return None
            return np.zeros(2), self.heading  # Rover's stop controller, holding the heading
        return self.cfg.turn_speed_mps * unit(self.heading), None  # velocity only: Rover steers to it at its speed

    def _sideways(self, t: float, heading_rad: float, ground_ned: np.ndarray | None) -> bool:
        """The boat's velocity over ground has changed since the turn under way began by ``SIDEWAYS_MPS`` or more
        the way it was sent, across its heading (which has not moved from where the probe began), for
        ``SIDEWAYS_S`` in a row."""
        if self.ground_began is None and ground_ned is not None:
            self.ground_began = np.asarray(ground_ned, dtype=float)
        change = None if ground_ned is None or self.ground_began is None else ground_ned - self.ground_began
        going = change is not None and float(np.hypot(*change)) >= SIDEWAYS_MPS
        if going:
            direction = math.atan2(change[1], change[0])
            across = abs(wrap_pi(direction - heading_rad)) >= SIDEWAYS_RAD
            sent = abs(wrap_pi(direction - self.heading)) <= SENT_RAD
            going = across and sent and abs(wrap_pi(heading_rad - self.began)) < PROBE_MOVED_RAD
        self.sideways_since = (t if self.sideways_since is None else self.sideways_since) if going else None
        return self.sideways_since is not None and t - self.sideways_since >= SIDEWAYS_S

    def _with_course(self, t: float, heading_rad: float) -> bool:
        """Its heading came round to the turn asked under way within ``COURSE_S``: it turns with its course (a vehicle
        whose velocity follows the setpoint and whose heading is the direction it moves in, astern too)."""
        turned = abs(wrap_pi(heading_rad - self.heading)) < PROBE_MOVED_RAD
        return turned and self.way_began is not None and t - self.way_began <= COURSE_S

    def _side(self, heading_rad: float, p_ned: np.ndarray | None) -> float:
        """+1 (to starboard) or -1: the side of the hard turn whose quarter circle (of ``PROBE_CIRCLE_M``, the turning
        radius is not known yet) leaves the area by less (a tank's wall may lie just beyond it)."""
        if p_ned is None:
            return 1.0
        h = unit(heading_rad)
        right = np.array([-h[1], h[0]])
        theta = np.linspace(0.0, PROBE_WAY_RAD, 10)[:, None]
        along, aside = PROBE_CIRCLE_M * np.sin(theta) * h, PROBE_CIRCLE_M * (1.0 - np.cos(theta)) * right
        worst = [float(np.max(self.outside(p_ned + along + side * aside))) for side in (1.0, -1.0)]
        return -1.0 if worst[1] < worst[0] else 1.0
