"""Capturing the holding line near the goal: a receding-horizon search over short manoeuvres (pure math).

A boat that needs way to turn (a rudder boat, estimation/turning.py) holds the goal only on its line (through
the goal along the current, law/line_approach.py): within ``ENTRY_CROSS_M`` of it across, facing along it within
``ENTRY_RAD``. Close to the goal, the last few decimetres onto that pose are a parking problem: a turning circle
of R ~ 1.3 m turns the bow by only 0.1 rad per 0.13 m of way, and a boat 0.25 m beside the line, facing along
it, needs ahead-and-astern legs with the rudder over to get onto it (as a car parks), while the current sets it
off meanwhile. Line-of-sight feedback there steers toward the line by a few degrees and shuttles along it
without closing the offset; a shortest Reeds-Shepp path (law/approach_path.py) is tracked in the water on a
current that is not the one at the goal, and ends off the line.

So within ``CAPTURE_M`` of the goal the boat's next ``HORIZON`` manoeuvres are chosen by search (a receding
horizon, as in model-predictive control with motion primitives: Frazzoli, Dahleh & Feron (2005), "Maneuver-based
motion planning for nonlinear systems with symmetries"): each manoeuvre lasts ``STEP_S``, ahead or astern at
``speed`` through the water with the rudder hard over either way or amidships, or drifting (speed 0, Rover's
stop controller; a boat whose autopilot holds its ground at 0, ``holds_at_rest``, keeps its ground along its heading
instead, as far as it goes astern); every sequence is simulated on a kinematic model of the boat (a circle of radius
R through the water, first-order speed lags ahead and astern, ``lags_s``) carried by the current estimate, and scored
where it ends each manoeuvre by how far it is from holding (off the line, off the goal, the bow off the line, way
left on) plus how far it strays out of the area the boat may use. The first manoeuvre of the best sequence is driven
for its whole ``STEP_S`` (the boat needs that long to get way on; a search every tick dithers ahead-astern), then
the search is made again from where the boat is. A boat already out of the area (pressed onto a tank's wall by the
current) scores every sequence by how far out it ends up, so it comes back in first.

In sheared water (``point_only``, set by the helm) there is no line to capture: the still-water line the boat makes
for there is not the current's at the goal, which turns it off that line, and such a boat arrives off its line once
its way would stop it within the arrival radius (Helm.stops_within). There the search scores a pose by its distance
from the goal and the way left on, as that arrival does, and once arrived keeps it so.

The model's circle is the one the boat was seen to turn on in the search's own manoeuvres ahead with the rudder
over (way made through the water over the heading turned, ``SEEN_WEIGHT`` of the way to each new one; not at the
area's edge, where a wall turns a boat); until one is seen, the one measured in a hard turn at speed (``radius_m``,
at ``circle_speed_mps``) widened to the manoeuvre's speed in inverse proportion, as a rudder boat's is at low speed
(its rudder force grows with the speed squared, the linear yaw damping it works against does not). From the way it
had, for ``STEP_S``, its rudder and yaw also take time to come round. The simulator's rudder boat, 0.86 m at
0.17 m/s, turned 5.6-8.0 deg in a manoeuvre's first 2 s at 0.12 m/s and 9-10 deg in the next, where a 1.0 m model
said 8-16 and 14; in the double gyre's current at the goal it went on past the goal, each search expecting a turn
it did not make (docs/guidance-notes.md, "Stop 51").

Rover's command for a manoeuvre: heading ``TURN_RAD`` off the heading it began with (the rudder stays hard over
for its whole length: the boat turns by at most speed x ``STEP_S`` / R, far less) or that heading itself, at
the speed over ground along the heading that gives ``speed`` through the water (Rover holds the speed over
ground), astern as a negative speed.

Conventions: positions ``(2,)`` local NED [m], headings [rad] from north, speeds [m/s], vehicle seconds.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

import numpy as np

from koopguide.guidance.law.area import at_edge
from koopguide.guidance.law.maneuver import Maneuver, capped, unit, wrap_pi

CAPTURE_M = 0.5  # within this distance of the goal, a boat not yet holding its line is steered by this search [m]
CAPTURE_LEAVE_M = 0.7  # ... until beyond this (hysteresis: at one radius it went search, planner, search) [m]
STEP_S = 2.0  # one manoeuvre [s]
HORIZON = 4  # manoeuvres searched ahead
SIM_DT_S = 0.1  # the model's time step [s]
SPEED_LAG_S = 1.0  # the speed through the water follows its command with this time constant [s], or slower ahead or
# astern as the boat is seen to be (``CaptureSearch.lags_s``, estimation/speed_lag.py)
TURN_RAD = math.radians(45.0)  # a turning manoeuvre asks for this much off its starting heading (rudder hard over)
SPEED_MPS = 0.12  # through the water on a manoeuvre (at least WATER_MARGIN_MPS faster than the current) [m/s]
WATER_MARGIN_MPS = 0.04
MIN_RADIUS_M, MAX_RADIUS_M = 1.0, 2.5  # the turning radius the model uses, clamped [m]
SEEN_MIN_WAY_M = 0.1  # a manoeuvre ahead with the rudder over measures the circle once it made this much way [m]
SEEN_WEIGHT = 0.5  # ... and moves the model's circle this fraction of the way to the one it measured
ENTRY_CROSS_M = 0.1  # the hold takes a boat on this close to the line (across), from the search or not [m]
ENTRY_RAD = math.radians(10.0)  # ... facing along it this well: from 20 deg off the hold keeps way on to right the
# bow, which carried a boat handed over 20 deg off 0.5 m from the goal (uniform current)
ENTRY_ASTERN_RAD = math.radians(5.0)  # ... and this well with the bow downstream (astern into a current): held astern
# from 9-16 deg off, 4 of 4 uniform runs held 0.17-0.82 m p95 (the rudder rights a bow astern too slowly), from
# 0.3-3.3 deg off 6 of 6 held within 0.09 m (rudder, seed 1, stop 31)
CROSS_SCALE_M = ENTRY_CROSS_M  # the scales of the score
ALONG_SCALE_M = 0.15  # the arrival radius [m]
HEADING_SCALE_RAD = ENTRY_RAD
WAY_SCALE_MPS = 0.2  # ground speed left at the end of a manoeuvre
ASTERN_END_COST = 2.0  # holding with the bow downstream (astern into the current) is the rudder's weakest
CONTINUE_S = 3.0  # the straight run ahead or astern that scores each sequence's end beyond the horizon [s]
LATER_COST = 0.3  # a pose reached one manoeuvre later scores this much worse
AREA_COST_PER_M = 200.0  # each metre out of the area the boat may use
# (direction through the water: +1 ahead, -1 astern, 0 drift; rudder: -1 to port, 0 amidships, +1 to starboard)
MANEUVERS: tuple[tuple[int, int], ...] = (*itertools.product((1, -1), (-1, 0, 1)), (0, 0))


def bow_downstream(axis_rad: float, current_ned: np.ndarray | None) -> bool:
    """Whether a boat facing ``axis_rad`` [rad] has its bow downstream in the current ``current_ned`` [m/s, NED]
    (None: still water, never): it then holds astern, creeping upstream stern first."""
    return current_ned is not None and float(unit(axis_rad) @ np.asarray(current_ned, dtype=float)) > 0.0


def entry_rad(axis_rad: float, current_ned: np.ndarray | None) -> float:
    """How well a boat must face along its line (bow direction ``axis_rad``) for the hold to take it on:
    ``ENTRY_ASTERN_RAD`` with the bow downstream in the current ``current_ned`` (None: still water), else
    ``ENTRY_RAD``."""
    return ENTRY_ASTERN_RAD if bow_downstream(axis_rad, current_ned) else ENTRY_RAD


def straight_run(
    pos: np.ndarray,
    psi: np.ndarray,
    u: np.ndarray,
    target: np.ndarray,
    lag_s: np.ndarray,
    c: np.ndarray,
    seconds: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The search's model boats ``(S,)`` (at ``pos`` ``(S, 2)`` [m], headings ``psi`` [rad], way ``u`` [m/s]) driven
    for ``seconds`` with the rudder amidships toward the way ``target`` [m/s] through the water, lag ``lag_s`` [s], in
    the current ``c`` ``(2,)`` [m/s]: the search's Euler steps of ``SIM_DT_S`` summed in closed form. The heading
    stays; the way after k steps is u_k = target + (u - target) r^k with r = 1 - SIM_DT_S / lag, and each step moves
    the boat by u_k SIM_DT_S along it. Returns (pos, psi, u) after the run."""
    steps = round(seconds / SIM_DT_S)
    r = 1.0 - SIM_DT_S / lag_s
    rk = r**steps
    way = SIM_DT_S * (steps * target + (u - target) * r * (1.0 - rk) / (1.0 - r))  # [m]
    moved = way[:, None] * np.stack([np.cos(psi), np.sin(psi)], axis=1) + (steps * SIM_DT_S) * c
    return pos + moved, psi, target + (u - target) * rk


class CaptureSearch:
    """Call :meth:`command` each tick while capturing; :meth:`reset` when the boat holds or leaves the zone."""

    def __init__(self, max_speed_mps: float) -> None:
        self.max_speed = max_speed_mps
        self.chosen: tuple[int, int] | None = None  # the manoeuvre under way
        self.heading0 = 0.0  # the heading it began with [rad]
        self.until: float | None = None  # vehicle time it ends [s]
        # the boat's learned lags (ahead, astern) [s], set by the caller (estimation/speed_lag.py); the model takes
        # the slower of each and SPEED_LAG_S, the lag the search was made with (what else delays the way, such as
        # the autopilot's speed loop, is not in the fit)
        self.lags_s = (SPEED_LAG_S, SPEED_LAG_S)
        self.point_only = False  # no line to capture (sheared water): at rest at the goal, whatever the heading
        self.astern = True  # the boat goes astern (estimation/speed_lag.py SternwayTrial): if not, no manoeuvre astern
        self.holds_at_rest = False  # speed 0 holds the boat's ground along its heading (speed_lag.py RestHold)
        self.radius_seen_m: float | None = None  # the circle seen in its manoeuvres (kept by reset: the boat's) [m]
        self.circle_speed_mps: float | None = None  # the speed the circle it is given was measured at (the caller's)
        self._way_m = 0.0  # way made through the water in the manoeuvre under way [m]
        self._t: float | None = None  # the last command's vehicle time [s]

    def reset(self) -> None:
        self.chosen, self.until, self._t = None, None, None

    def forget(self) -> None:
        """A restarted vehicle (maybe another boat): forget the circle seen."""
        self.reset()
        self.radius_seen_m = None

    @property
    def active(self) -> bool:
        """A manoeuvre has been chosen since the last :meth:`reset`."""
        return self.chosen is not None

    def command(
        self,
        t: float,
        p_ned: np.ndarray,
        goal_ned: np.ndarray,
        heading_rad: float,
        water_mps: float,
        axis_rad: float,
        current_ned: np.ndarray | None,
        radius_m: float,
        outside: Callable[[np.ndarray], np.ndarray] | None,
    ) -> Maneuver:
        """The manoeuvre under way, or (when it has run its ``STEP_S``) the first of the best sequence from here.

        ``water_mps``: the boat's speed through the water along its heading (negative: astern); ``axis_rad``: the
        line's bow direction (upstream in a current); ``current_ned``: the estimate, or None in still water;
        ``outside``: how far points ``(K, 2)`` lie outside the area the boat may use [m] (None: no limit)."""
        c = np.zeros(2) if current_ned is None else np.asarray(current_ned, dtype=float)
        if self._t is not None:
            self._way_m += abs(water_mps) * max(t - self._t, 0.0)
        self._t = t
        if self.until is None or t >= self.until or self.chosen is None:
            if self.until is not None and self.chosen is not None:  # the manoeuvre has run its STEP_S
                self._see(p_ned, heading_rad, outside)
            self.chosen = MANEUVERS[self.best(p_ned, goal_ned, heading_rad, water_mps, axis_rad, c, radius_m, outside)]
            self.heading0, self.until, self._way_m = heading_rad, t + STEP_S, 0.0
        direction, rudder = self.chosen
        heading = wrap_pi(self.heading0 + rudder * TURN_RAD)
        if direction == 0:
            return Maneuver(self.heading0, 0.0, False)
        speed = self.speed(c)
        over_ground = direction * speed + float(c @ unit(heading))  # Rover holds the speed over ground
        return Maneuver(heading, capped(over_ground, self.max_speed), direction < 0)

    def _see(self, p_ned: np.ndarray, heading_rad: float, outside: Callable[[np.ndarray], np.ndarray] | None) -> None:
        """The circle the manoeuvre that has just run turned the boat on, when it went ahead with the rudder over
        and made ``SEEN_MIN_WAY_M`` of way, clear of the area's edge (``radius_seen_m``)."""
        assert self.chosen is not None
        direction, rudder = self.chosen
        if direction <= 0 or rudder == 0 or self._way_m < SEEN_MIN_WAY_M:
            return
        if outside is not None and at_edge(outside, p_ned):
            return
        turned = rudder * wrap_pi(heading_rad - self.heading0)  # toward the rudder [rad]
        radius = self._way_m / turned if turned > self._way_m / MAX_RADIUS_M else MAX_RADIUS_M
        radius = min(MAX_RADIUS_M, max(MIN_RADIUS_M, radius))
        seen = self.radius_seen_m
        self.radius_seen_m = radius if seen is None else seen + SEEN_WEIGHT * (radius - seen)

    def model_radius_m(self, radius_m: float, speed_mps: float) -> float:
        """The model's circle [m] at a manoeuvre's ``speed_mps`` [m/s]: the one seen, else ``radius_m`` (measured at
        ``circle_speed_mps``) widened in inverse proportion to the speed as a rudder boat's is, within the clamps."""
        if self.radius_seen_m is not None:
            return self.radius_seen_m
        given = radius_m * max(1.0, (self.circle_speed_mps or speed_mps) / speed_mps)
        return min(MAX_RADIUS_M, max(MIN_RADIUS_M, given))

    @staticmethod
    def speed(c: np.ndarray) -> float:
        """The speed through the water of a manoeuvre: enough over the current for the rudder to read the way."""
        return max(SPEED_MPS, float(np.hypot(*c)) + WATER_MARGIN_MPS)

    def best(
        self,
        p_ned: np.ndarray,
        goal_ned: np.ndarray,
        heading_rad: float,
        water_mps: float,
        axis_rad: float,
        c: np.ndarray,
        radius_m: float,
        outside: Callable[[np.ndarray], np.ndarray] | None,
    ) -> int:
        """Index into ``MANEUVERS`` of the first manoeuvre of the best-scoring sequence (``c``: the current, zeros
        in still water). The sequences are searched as a tree: the boat is driven through each manoeuvre once per
        distinct beginning (7 + 49 + 343 + 2401 manoeuvres, not 4 x 2401), and the straight runs that score each
        end beyond the horizon are summed in closed form (they keep their heading). Ties go to the first sequence in
        ``itertools.product`` order."""
        moves = [i for i, (d, _) in enumerate(MANEUVERS) if self.astern or d >= 0]  # ahead only: none astern
        table = np.array([MANEUVERS[i] for i in moves], dtype=float)
        n_moves = len(moves)
        speed = self.speed(c)
        radius = self.model_radius_m(radius_m, speed)
        a = unit(axis_rad)
        normal = np.array([-a[1], a[0]])
        upstream = math.atan2(-c[1], -c[0]) if float(np.hypot(*c)) > 0.0 else None
        ahead, astern = (max(SPEED_LAG_S, lag) for lag in self.lags_s)

        def ground(psi, u):  # the velocity over ground (S, 2) of way u along headings psi, carried by the current
            return u[:, None] * np.stack([np.cos(psi), np.sin(psi)], axis=1) + c

        def at_rest(psi):  # the way (S,) speed 0 asks through the water: none, or holding the ground along psi
            if not self.holds_at_rest:
                return np.zeros(len(psi))
            hold = -(c[0] * np.cos(psi) + c[1] * np.sin(psi))
            return hold if self.astern else np.maximum(hold, 0.0)

        def lag_of(target):
            return np.where(target > 0.0, ahead, np.where(target < 0.0, astern, SPEED_LAG_S))

        def drive(pos, psi, u, target, rudder, seconds):  # the model over ``seconds``: Euler steps of SIM_DT_S
            lag = lag_of(target)
            for _ in range(round(seconds / SIM_DT_S)):
                u = u + (target - u) * (SIM_DT_S / lag)
                psi = psi + rudder * np.abs(u) / radius * SIM_DT_S  # Rover turns toward the asked heading
                pos = pos + ground(psi, u) * SIM_DT_S
            return pos, psi, u

        def either(off):  # off the line at either end (a boat that goes ahead only: bow upstream in a current)
            return off if upstream is not None and not self.astern else np.minimum(off, math.pi - off)

        def pose_cost(pos, psi, u, k):  # how far from holding, a pose reached after k + 1 manoeuvres
            way = ground(psi, u)
            cost = (np.hypot(way[:, 0], way[:, 1]) / WAY_SCALE_MPS) ** 2 + LATER_COST * k  # at rest, soon
            if self.point_only:  # at rest within the arrival radius, whatever the heading
                return cost + (np.hypot(pos[:, 0], pos[:, 1]) / ALONG_SCALE_M) ** 2
            off_axis = np.abs(wrap_pi(psi - axis_rad))
            downstream = (
                np.zeros(len(psi), dtype=bool) if upstream is None else np.abs(wrap_pi(psi - upstream)) > math.pi / 2
            )
            heading_scale = np.where(downstream, ENTRY_ASTERN_RAD, HEADING_SCALE_RAD)  # the hold's entry, either end
            return (
                cost
                + (pos @ normal / CROSS_SCALE_M) ** 2
                + (pos @ a / ALONG_SCALE_M) ** 2
                + (either(off_axis) / heading_scale) ** 2  # either end of the line (ahead only: its bow end)
                + ASTERN_END_COST * downstream
            )

        # level k holds one state per distinct beginning of k + 1 manoeuvres, in product order (parent-major)
        pos = (np.asarray(p_ned, dtype=float) - np.asarray(goal_ned, dtype=float))[None, :]  # from the goal [m]
        psi, u = np.array([heading_rad]), np.array([water_mps])
        score, strayed = np.full(1, np.inf), np.zeros(1)  # per beginning: best pose so far, farthest out of the area
        for k in range(HORIZON):
            pos, psi, u = (np.repeat(x, n_moves, axis=0) for x in (pos, psi, u))
            score, strayed = np.repeat(score, n_moves), np.repeat(strayed, n_moves)
            ways, rudders = np.tile(table[:, 0], len(psi) // n_moves), np.tile(table[:, 1], len(psi) // n_moves)
            target = np.where(ways == 0.0, at_rest(psi), ways * speed)  # (a drift keeps its heading)
            pos, psi, u = drive(pos, psi, u, target, rudders, STEP_S)
            if outside is not None:
                strayed = np.maximum(strayed, np.asarray(outside(pos + goal_ned), dtype=float))
            score = np.minimum(score, pose_cost(pos, psi, u, k))  # the best pose along the sequence
        # beyond the horizon: each sequence's end carried on straight ahead or astern for CONTINUE_S, then stopped,
        # credits a pose aimed at the line (a boat 0.2 m beside its line otherwise found no sequence of four that
        # got there, and drifted beside it for a minute: every turn toward the line scored worse than none)
        for direction in (1.0, -1.0) if self.astern else (1.0,):
            target = np.full(len(psi), direction * speed)
            on = straight_run(pos, psi, u, target, lag_of(target), c, CONTINUE_S)
            target = at_rest(on[1])
            on = straight_run(*on, target, lag_of(target), c, STEP_S)
            score = np.minimum(score, pose_cost(*on, HORIZON + 1))
        total = score + AREA_COST_PER_M * strayed  # out of the area already: back in first
        return moves[int(np.argmin(total)) // n_moves ** (HORIZON - 1)]
