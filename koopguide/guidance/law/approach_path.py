"""A planned approach for a boat that needs way to turn: a Reeds-Shepp path onto the holding line, and a
tracker for it (pure math, no I/O).

Where the boat is far off the line it will hold, or faces far off it, feedback alone (law/line_approach.py)
makes slow progress in a tight space: a boat that turns on a circle of radius R ~ 1.5 m cannot make a U-turn
in a 3 m tank. A car's answer is a planned manoeuvre with reversals, and Reeds & Shepp (1990) give the
shortest one between two poses (law/reeds_shepp.py). Here:

* the path ends with ``FINAL_M`` straight (ahead or astern) on the holding line, the bow along it (either
  end of a current's line, or in still water any of ``CALM_HEADINGS``: a boat in still water holds in any
  heading), at the goal or ``SHORT_M`` short of it (where the hold, law/line_approach.py, takes the boat on:
  in a current it drifts down onto the goal; this is what fits where the goal lies near the area's
  downstream edge) and stays within the area the boat may use (the model's domain and the geofence,
  ``AREA_SLACK_M`` of slack); the cheapest is kept, length plus ``CUSP_COST_M`` per reversal plus
  ``SHORT_COST`` per metre short. In still water (which is also how a boat in sheared water plans, helm.py)
  a line with less than ``ROOM_M`` inside the area on either side of the goal costs ``ROOM_COST`` per metre
  short: the boat holds by going ahead and astern along its line, and a capture runs past the goal with way on
  (the campaign's goal lies 0.45 m from the area's east edge along the east-west line, 0.6-0.65 m along the
  others; in the double gyre 15 of the 18 rudder runs in 324 that did not arrive had made for that line, 11%
  of those that did against 1.6% of the rest; with the cost, 4 of 324 did not arrive).
  (The path may pass near the goal: a boat that needs way arrives only once it holds its line, helm.py.)
* it is planned in the water, not over ground: a turning circle is a circle through the water, and a 0.03 m/s
  current carries the boat 0.5-1 m while it drives a 20-30 s manoeuvre (a path planned over ground and
  tracked over ground, the boat set off it by the current, was abandoned and planned again, over and over).
  In a current ``c`` (the estimate when the plan is made, taken as uniform) the water moves on by ``c t``:
  the path runs from the boat's pose to where the goal's pose will be in the water when the boat gets there,
  ``goal - c T`` with ``T`` the time the tracker takes to drive it (a fixed point, ``ARRIVAL_ITERATIONS`` steps
  on the shortest path), and a sample reached at time ``t`` lies over ground ``c t`` further on
  (:attr:`ApproachPath.ground_ned`). That ground track is what must stay in the area (and also when set
  ``DRIFT_S`` of the current further downstream). The timing is the tracker's speed profile plus ``CUSP_S``
  per reversal; a path whose timing differs so much from the shortest one's that over ground it ends more than
  ``HOLD_ALONG_M`` from the goal (where the hold would not take it on) is passed over;
* it is planned on a circle a little wider than the boat's measured one (``RADIUS_MARGIN``; the boat's circle
  widens as it slows), and tracked per run (the part between two reversals) in the water: the boat's place
  in the water is its position less ``c`` times the time since the plan, and the tracker is line-of-sight
  guidance on that: the path's course ``LOOK_M`` ahead, less atan(offset / ``LOS_DELTA_M``) (astern the bow
  points opposite the course), at the speed through the water that stops the boat at the run's end
  (``STOP_GAIN`` per metre still to go, less for a boat slow to stop: ``stop_gain``, set from its stopping time
  by law/line_approach.py; at most ``cruise``, and at least ``WATER_MARGIN_MPS`` faster than the
  current, so that the speed over ground along the heading, which sets the autopilot's rudder, keeps the
  sign of the way through the water). Rover holds speed over ground along the heading, so the speed sent is
  that through the water plus the current's component along the heading;
* a boat that drifts off the path (``REPLAN_M``, in the water), faces far off it (``REPLAN_RAD``), has
  tracked one plan for ``REPLAN_S``, or is in water that moves otherwise than the plan's (the current estimate
  ``REPLAN_CURRENT_MPS`` from the plan's), gets a new one from where it is. In a flow that is not uniform (a
  vortex, a gyre) the plan's current is only the one at the boat when it was made; those replans are what
  corrects it (rudder boat, 12 starts each: 12/12 arrivals in the vortex and 10/12 in the double gyre with
  them, 10/12 and 9/12 without; tracking the sum of the changing estimate instead did worse, 10/12 and 7/12).

Conventions: positions local NED [m] (the samples: in the water, i.e. where the plan began, carried with the
water), headings [rad] from north, speeds over ground along the heading [m/s] (the tracker's profile: through
the water), vehicle seconds.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from koopguide.guidance.law import reeds_shepp
from koopguide.guidance.law.maneuver import Maneuver, capped, unit, water_current, wrap_pi

STEP_M = 0.05  # path sample spacing [m]
CHECK_STEP_M = 0.1  # ... when checking a candidate against the area and the goal [m]
MAX_CHECKED = 40  # candidates checked at most, cheapest first
RETRY_S = 2.0  # after a plan that found nothing, plan again only this much later [s]
FINAL_M = 0.4  # every path ends with this much straight along the final heading (the boat settles its heading) [m]
SHORT_M = (0.0, 0.4)  # a path ends at the goal or this far short of it on the line, where the hold takes over [m]
HOLD_ALONG_M = 0.6  # the hold (law/line_approach.py) takes a boat on the line this far from the goal [m]
SHORT_COST = 2.0  # ... each metre short costs as much as this much more path (the hold is slower) [m/m]
CUSP_COST_M = 0.5  # a reversal costs as much as this much more path [m]
AREA_SLACK_M = 0.1  # a path may leave the area by this much (or by what the boat is already outside) [m]
DOWNSTREAM_COST_M = 2.0  # a path that ends with the bow downstream costs as much as this much more path [m]
DRIFT_S = 4.0  # a path stays inside the area when set this long of the current downstream too [s]
RADIUS_MARGIN = 1.1  # plan on a circle this much wider than the boat's measured one
MIN_RADIUS_M, MAX_RADIUS_M = 1.0, 2.5  # [m]
CALM_HEADINGS = 8  # final headings tried in still water (every 360 / 8 deg)
ROOM_M = 0.8  # in still water, a line with less room than this inside the area on either side of the goal ...
ROOM_COST = 6.0  # ... costs as much as this much more path per metre short [m/m]
LOOK_M = 0.3  # the path's course is taken this far ahead along it [m]
LOS_DELTA_M = 0.5  # LOS look-ahead for the offset across the path [m]
STOP_GAIN = 0.6  # speed per metre still to go to the run's end [1/s]
MIN_SPEED_MPS = 0.04  # on a run, never slower than this [m/s]
RUN_END_M = 0.06  # a run counts as driven once its end is this close [m]
REPLAN_M = 0.3  # off the path by more than this: plan again [m]
REPLAN_RAD = math.radians(60.0)  # facing off the path by more than this: plan again
REPLAN_S = 20.0  # plan again after this long on one path [s]
REPLAN_CURRENT_MPS = 0.01  # ... or once the current estimate differs from the plan's by this much [m/s]
SEARCH = 40  # samples searched ahead for the boat's progress along the run
CUSP_S = 2.0  # a reversal: the boat stops and gets way on the other way in about this long [s]
ARRIVAL_ITERATIONS = 3  # the goal's place in the water when the boat gets there: this many fixed-point steps
WATER_MARGIN_MPS = 0.02  # through the water at least this much faster than the current (or the rudder misreads)


def room_along_m(goal_ned: np.ndarray, bow: np.ndarray, outside: Callable[[np.ndarray], np.ndarray]) -> float:
    """How far the line through ``goal_ned`` along the unit vector ``bow`` runs inside the area on its shorter side
    [m], up to ``ROOM_M`` (sampled every ``ROOM_M`` / 16). ``outside``: as for :meth:`ApproachPath.plan`."""
    d = np.linspace(0.0, ROOM_M, 17)[1:]
    room = ROOM_M
    for side in (1.0, -1.0):
        out = outside(np.asarray(goal_ned, dtype=float) + side * np.outer(d, bow)) > 0.0
        if out.any():
            room = min(room, float(d[int(np.argmax(out))]))
    return room


class ApproachPath:
    """Plan with :meth:`plan`, then call :meth:`command` each tick (None: no path, or its end reached)."""

    def __init__(self, cruise_mps: float, max_speed_mps: float) -> None:
        self.cruise = min(cruise_mps, max_speed_mps)  # through the water [m/s]
        self.max_speed = max_speed_mps  # over ground along the heading, what Rover holds [m/s]
        self.samples: list[tuple[float, float, float, float]] = []  # (N, E, heading, direction)
        self.i = 0  # progress along the samples
        self.t_planned: float | None = None
        self.final_heading: float | None = None  # the bow's direction at the path's end [rad]
        self.t_failed: float | None = None  # vehicle time of the last plan that found nothing [s]
        self.times = np.zeros(0)  # when the boat is to reach each sample [s after the plan]
        self.current = np.zeros(2)  # the current the plan was made in [m/s]
        self.stop_gain = STOP_GAIN  # speed per metre to a run's end: less for a boat slow to stop (LineApproach)
        self.astern = True  # the boat goes astern (LineApproach): if not, Dubins' paths ending bow upstream

    def reset(self) -> None:
        self.samples, self.i, self.t_planned, self.final_heading = [], 0, None, None
        self.times, self.current = np.zeros(0), np.zeros(2)

    @property
    def active(self) -> bool:
        return bool(self.samples)

    def plan(
        self,
        t: float,
        p_ned: np.ndarray,
        heading_rad: float,
        goal_ned: np.ndarray,
        final_headings: tuple[float, ...] | None,
        radius_m: float | None,
        outside: Callable[[np.ndarray], np.ndarray] | None,
        current_ned: np.ndarray | None = None,
    ) -> bool:
        """Plan from the boat's pose to the goal, the bow at the end along one of ``final_headings`` (None: any,
        still water); False (and no path) when none stays in the area. ``outside``: how far each of ``(K, 2)``
        NED points lies outside the area [m] (0 inside). ``current_ned`` [m/s]: the path must stay inside when set
        ``DRIFT_S`` of the current downstream too (a boat tracking it is carried off it downstream before its
        guidance corrects; a wall there would pin it)."""
        self.reset()
        r = min(MAX_RADIUS_M, max(MIN_RADIUS_M, RADIUS_MARGIN * (radius_m if radius_m is not None else 1.4)))
        calm = final_headings is None
        if calm:
            final_headings = tuple(2.0 * math.pi * k / CALM_HEADINGS for k in range(CALM_HEADINGS))
        start = (float(p_ned[0]), float(p_ned[1]), heading_rad)
        goal = np.asarray(goal_ned, dtype=float)
        here = 0.0 if outside is None else float(outside(np.asarray(p_ned, dtype=float)[None, :])[0])
        allowed = AREA_SLACK_M + here
        c = water_current(current_ned)
        moving, floor = bool(c.any()), self._floor(c)
        candidates = []
        for k, final in enumerate(final_headings):
            bow = unit(final)
            downstream = float(c @ bow) > 0.0
            if downstream and not self.astern:
                continue  # it would hold astern
            bow_cost = DOWNSTREAM_COST_M if downstream else 0.0  # it would hold astern, its rudder at its weakest
            if calm and outside is not None:  # room to hold on the line, ahead and astern
                bow_cost += ROOM_COST * (ROOM_M - room_along_m(goal, bow, outside))
            for way in (1.0, -1.0) if self.astern else (1.0,):  # the last FINAL_M ahead or astern, straight
                for short in SHORT_M:  # ending this far short of the goal (the hold brings it the rest of the way)
                    back = (short + FINAL_M) * way * bow  # from the final leg's start to the path's end
                    # planned in the water (which moves at c): the final leg must start where the goal's pose will
                    # be in the water when the boat gets there, T later (fixed point on the shortest path's T)
                    arrival_s, paths = 0.0, []
                    for _ in range(ARRIVAL_ITERATIONS):
                        n, e = goal - back - c * arrival_s
                        pre = (float(n), float(e), final)
                        plans = reeds_shepp.plan(start, pre, r, self.astern)
                        paths = [self._whole(start, pre, path, way, r) for path in plans]
                        if not paths or not moving:
                            break
                        arrival_s = float(self._times(paths[0].sample(CHECK_STEP_M), floor)[-1])
                    for whole in paths:
                        cost = whole.length_m + CUSP_COST_M * whole.cusps + SHORT_COST * short + bow_cost
                        candidates.append((cost, k, whole, final))
        self.t_failed = t
        # the cheapest that stays in the area over ground (the water's drift added), MAX_CHECKED at most; in still
        # water checked on a coarser sampling (in a current the timing of every sample matters)
        for _, _, path, final in sorted(candidates, key=lambda c: c[:2])[:MAX_CHECKED]:
            samples = path.sample(STEP_M if moving else CHECK_STEP_M)
            points = np.array([s[:2] for s in samples])
            if moving:
                times = self._times(samples, floor)
                points = points + np.outer(times, c)
                if float(np.hypot(*(points[-1] - goal))) > HOLD_ALONG_M:
                    continue  # its timing differs from the shortest path's: over ground it ends too far off the goal
                points = np.vstack([points, points + DRIFT_S * c])
            if outside is None or float(np.max(outside(points))) <= allowed:
                self.samples = samples if moving else path.sample(STEP_M)
                self.times = times if moving else self._times(self.samples, floor)
                self.t_planned, self.final_heading, self.current = t, final, c
                self.t_failed = None
                return True
        return False

    @staticmethod
    def _whole(
        start: tuple[float, float, float], pre: tuple[float, float, float], path: reeds_shepp.Path, way: float, r: float
    ) -> reeds_shepp.Path:
        """``path`` onto ``pre`` and then the final ``FINAL_M`` straight, ahead (``way`` +1) or astern."""
        return reeds_shepp.Path(start, r, (*path.segments, ("S", way * FINAL_M / r)))

    def _floor(self, c: np.ndarray) -> float:
        """The slowest the tracker drives a run through the water [m/s]: never so slow that the current turns
        the speed over ground along the heading (which sets the autopilot's rudder) the other way."""
        return min(self.cruise, max(MIN_SPEED_MPS, float(np.hypot(*c)) + WATER_MARGIN_MPS))

    def _times(self, samples: list[tuple[float, float, float, float]], floor: float) -> np.ndarray:
        """When the tracker reaches each of ``samples`` [s from the start]: its speed profile (``stop_gain`` per
        metre to each run's end, between ``floor`` and ``cruise``), plus ``CUSP_S`` per reversal."""
        P = np.array([s[:2] for s in samples])
        d = np.array([s[3] for s in samples])
        step = np.hypot(*np.diff(P, axis=0).T) if len(P) > 1 else np.zeros(0)
        remaining = np.zeros(len(P))  # to the end of each sample's run [m]
        for k in range(len(P) - 2, -1, -1):
            remaining[k] = remaining[k + 1] + step[k] if d[k + 1] == d[k] else 0.0
        speed = np.clip(self.stop_gain * remaining[1:], floor, self.cruise)
        driven = remaining[:-1] > RUN_END_M  # the last RUN_END_M of a run counts as driven at once
        dt = driven * step / speed + CUSP_S * (d[1:] != d[:-1])
        return np.concatenate([[0.0], np.cumsum(dt)])

    @property
    def ground_ned(self) -> np.ndarray:
        """Where the plan puts the boat over ground, sample by sample ``(K, 2)`` [m]: the samples (in the water)
        carried by the current the plan was made in until the boat reaches them."""
        if not self.samples:
            return np.zeros((0, 2))
        return np.array([s[:2] for s in self.samples]) + np.outer(self.times, self.current)

    def reach_m(self, goal_ned: np.ndarray) -> float:
        """How far from ``goal_ned`` [m] the plan takes the boat over ground, off it by ``REPLAN_M`` at most (0: no
        plan)."""
        ground = self.ground_ned
        return float(np.max(np.hypot(*(ground - goal_ned).T))) + REPLAN_M if len(ground) else 0.0

    def may_plan(self, t: float) -> bool:
        """Whether to try planning at ``t``: not within ``RETRY_S`` of a plan that found nothing (planning costs
        milliseconds of the control loop)."""
        return self.t_failed is None or not 0.0 <= t - self.t_failed < RETRY_S

    def run_end(self, i: int) -> int:
        """Index of the last sample of the run that sample ``i`` belongs to (up to the next reversal)."""
        d = self.samples[i][3]
        j = i
        while j + 1 < len(self.samples) and self.samples[j + 1][3] == d:
            j += 1
        return j

    def command(
        self, t: float, p_ned: np.ndarray, heading_rad: float, current_ned: np.ndarray | None = None
    ) -> Maneuver | None:
        """Heading and signed speed along the path; None when there is none, the boat has left it (plan again)
        or reached its end. The path lies in the water: the boat is tracked where it is in the water, its
        position less the plan's current times the time since the plan; ``current_ned`` [m/s], the estimate now,
        turns the speed through the water into the speed over ground Rover holds."""
        if not self.samples or self.t_planned is None:
            return None
        c = water_current(current_ned)
        # the boat's place in the water: the water has moved on as the plan assumed
        p = np.asarray(p_ned, dtype=float) - self.current * max(t - self.t_planned, 0.0)
        end = self.run_end(self.i)
        window = range(self.i, min(end, self.i + SEARCH) + 1)
        self.i = min(window, key=lambda k: math.hypot(self.samples[k][0] - p[0], self.samples[k][1] - p[1]))
        to_end = math.hypot(self.samples[end][0] - p[0], self.samples[end][1] - p[1])
        if to_end <= RUN_END_M or self.i == end:  # this run is driven: on to the next, or done
            if end + 1 >= len(self.samples):
                self.reset()
                return None
            self.i = end + 1
            end = self.run_end(self.i)
        n, e, path_heading, direction = self.samples[self.i]
        off = math.hypot(n - p[0], e - p[1])
        facing_off = abs(wrap_pi(path_heading - heading_rad)) > REPLAN_RAD
        other_water = float(np.hypot(*(c - self.current))) > REPLAN_CURRENT_MPS  # not the water it was planned in
        if off > REPLAN_M or facing_off or t - self.t_planned > REPLAN_S or other_water:
            self.reset()
            return None
        remaining = STEP_M * (end - self.i)  # along the path to the run's end [m]
        # LOS along the path (Fossen (2021) 12.4.2): the course of the path LOOK_M ahead within the run, less the
        # angle that steers out the offset across the path's own course here
        motion = path_heading if direction > 0 else wrap_pi(path_heading + math.pi)  # course over the path
        ahead_course = self.samples[min(end, self.i + max(1, round(LOOK_M / STEP_M)))][2]
        ahead_course = ahead_course if direction > 0 else wrap_pi(ahead_course + math.pi)
        across = -math.sin(motion) * (p[0] - n) + math.cos(motion) * (p[1] - e)  # to the right of the course [m]
        course = wrap_pi(ahead_course - math.atan2(across, LOS_DELTA_M))
        heading = course if direction > 0 else wrap_pi(course + math.pi)
        speed = min(self.cruise, max(self._floor(c), self.stop_gain * remaining))  # through the water
        over_ground = direction * speed + float(c @ unit(heading))  # Rover holds the speed over ground
        # ... never faster than max_speed (with the current from astern, cruise plus the current could be)
        return Maneuver(heading, capped(over_ground, self.max_speed), direction < 0)
