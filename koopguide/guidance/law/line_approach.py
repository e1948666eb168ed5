"""Bringing a boat that cannot turn without way onto a point, and keeping it there (pure math).

A rudder boat turns only while it moves, on a circle of radius R (estimation/turning.py): at the arrival
radius's scale (0.15 m) against R ~ 1.5 m it can neither turn on the spot to face the goal nor make a U-turn
in the room a tank leaves. What it can do is what a driver does in a narrow street: go ahead and astern in
turn (the autopilot reverses the rudder astern, docs/rover.md). Four modes, one line:

* far from the line or facing off it, once the boat's turning circle is known: a planned approach, the
  shortest Reeds-Shepp path onto an end of the line (law/approach_path.py), planned again when the boat
  leaves it;
* within ``CAPTURE_M`` of the goal and not yet holding: a receding-horizon search over ahead/astern
  manoeuvres with the rudder over (law/capture.py), the last decimetres onto the line (a path tracked in the
  water on a current that is not the goal's ended off the line there, and LOS feedback shuttled along it);
* on the line near the goal (taken on within the capture search's ``ENTRY_*`` bounds however the boat got
  there, left beyond ``LEAVE_*``): feedback; in a current into the current only (law/creep_cycle.py), in still
  water ahead or astern along the line. A planned path is driven to its end before the hold takes over: its last
  leg lines the bow up with the line (taken over mid-path, a hold began up to 25 deg off, and turning the bow
  back with way on carried the boat 0.3-0.5 m past the goal);
* otherwise (no circle measured yet, or no path fits): line-of-sight guidance onto the line with K-turns,
  reversing before the area's edge, as below.

* the line it holds: through the goal along the current (in a current the boat holds only bow or stern
  upstream: across it the current sets the boat sideways faster than the rudder, with the little way a
  0.03 m/s current gives it, can turn it back), ahead into the current or astern into it, whichever end of
  the line it faces when the approach begins (the ends swap only when it faces the other end by more than
  90 deg + ``SWAP_RAD``); in still water the line from where the approach began to the goal;
* the way along the line to the goal (``travel``, kept apart from ahead/astern): toward the goal, reversed
  once the boat is past it by ``FLIP_M`` on the line, or off the line by as much as it still has to go
  across (where along the line it meets the line matters less than getting there); level with the goal,
  the way whose course stays inside the area the boat may use, then the one that needs the smaller turn;
* the heading: line-of-sight guidance onto that line, aiming at the point ``Delta`` further along it in the
  way of travel (Fossen (2021), "Handbook of Marine Craft Hydrodynamics and Motion Control", 2nd ed.,
  section 12.4.2, LOS steering law ``chi_d = chi_p - atan(y_e / Delta)``), ``R <= Delta <= MAX_DELTA_M``;
  astern the bow points opposite the course;
* ahead or astern: as the way of travel, except in a K-turn (heading error beyond ``K_TURN_RAD``), when the
  boat goes ahead and astern in turn, each leg ``LEASH_M`` past where the K-turn began, all toward the same
  heading; and it reverses before it leaves the area it may use (law/edge_reversal.py). After a reversal the
  heading is held until the water passes the rudder the new way (before that the rudder turns the boat the wrong
  way);
* a boat seen not to go astern (estimation/speed_lag.py ``SternwayTrial``): ahead only. It holds bow upstream, turns
  round (no K-turn, no reversal at the edge) where the goal lies behind it in still water, and its planned approach
  and capture search keep ahead (Dubins' paths, no manoeuvre astern);
* the speed over ground along the heading: at least the way the rudder needs (``way_mps``) while turning, else
  ``gain`` (at most 1 / the boat's stopping time ``stop_s``, estimation/speed_lag.py, as on the planned approach's
  runs) times the distance to the goal plus the station keeper's integral term along it (PI with anti-windup,
  law/station.py); in a current, a speed over ground one way with the water past the rudder the other (the
  autopilot sets the rudder by the speed's sign) is sent as 0: Rover's stop controller lets the current carry
  the boat (one that holds its ground at 0 is backed down in the hold instead, law/creep_cycle.py).

Conventions: positions ``(2,)`` local NED [m], velocities NED [m/s], headings [rad] from north.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from types import EllipsisType

import numpy as np

from koopguide.guidance.law.approach_path import HOLD_ALONG_M, STOP_GAIN, ApproachPath
from koopguide.guidance.law.capture import (
    CAPTURE_LEAVE_M,
    CAPTURE_M,
    ENTRY_CROSS_M,
    CaptureSearch,
    bow_downstream,
    entry_rad,
)
from koopguide.guidance.law.creep_cycle import CreepCycle
from koopguide.guidance.law.edge_reversal import EdgeReversal
from koopguide.guidance.law.line_of_sight import los_course, los_heading
from koopguide.guidance.law.maneuver import MIN_SPEED_MPS, Maneuver, capped, unit, wrap_pi

MIN_DELTA_M = 0.3  # the smallest LOS look-ahead [m]
MAX_DELTA_M = 1.0  # the largest: a longer one only delays the turn onto the line (K-turns make up the rest) [m]
STILL_MPS = 0.02  # slower than this through the water the boat is not yet moving either way [m/s]
DEFAULT_RADIUS_M = 1.0  # the turning radius assumed before one is measured [m]
FLIP_M = 0.03  # on the line: ahead <-> astern once the goal is this far behind the boat along its heading [m]
LEASH_M = 0.3  # while turning (a K-turn): the boat goes on this far past the goal before it reverses [m]
TURNING_RAD = math.radians(20.0)  # a heading error this large is a turn: keep way on
K_TURN_RAD = math.radians(45.0)  # ... and this large a K-turn about the goal
LEAVE_CROSS_M, LEAVE_RAD, LEAVE_ALONG_M = 0.4, math.radians(60.0), 0.8  # ... until beyond these: a planned approach
ENTRY_AWAY_RAD, ENTRY_SIDE_M = math.radians(4.0), 0.02  # a boat this far off its line: creeping this little away
UNARRIVED_LEAVE_CROSS_M = 0.15  # ... or, not yet arrived, beyond this across: the capture search (law/capture.py)
UNARRIVED_LEAVE_RAD = math.radians(15.0)  # ... or facing off a current's line by this much (it turned under the bow)
FERRY_RAD = math.radians(30.0)  # a boat that goes ahead only is held in a current from this far off its line
REPLAN_OFF_LINE_RAD = math.radians(20.0)  # a path whose end is this far off the current's line is planned again
SWAP_RAD = math.radians(30.0)  # hysteresis of the bow's end of the line (past 90 deg + this, the ends swap)
# arrived and holding on a current's line, the line turns toward the estimate's direction with this time constant:
# in steady water the estimate's wander (sway read as current, 15 deg either way) left a bow that cannot turn while
# drifting 20 deg off the line; righting it ran a rudder boat 0.2-0.45 m off (4 of 10 flights in bounds, 8/8 now) [s]
AXIS_TAU_S = 20.0
EDGE_COURSE_M = 0.5  # a course along the line "leads out" when the point this far along it is farther out [m]


class LineApproach:
    """LOS guidance onto the line through the goal with bow direction ``axis_rad`` (:meth:`aim`), ahead/astern."""

    def __init__(
        self, max_speed_mps: float, gain_per_s: float, settle_m: float, way_mps: float, approach_mps: float
    ) -> None:
        self.max_speed = max_speed_mps
        self.settle_m = settle_m  # an offset across the line this small is "on the line" [m]
        self.gain = gain_per_s
        self.way = min(way_mps, max_speed_mps)
        self.axis_rad: float | None = None  # the bow's direction on the line [rad]
        self.in_current = False  # the line is the current's
        self.travel: float | None = None  # toward the goal along the line: +1 along the axis, -1 against it
        self.astern = False  # the boat is to move stern first (on the line: travel -1; in a K-turn: by legs)
        self.pivot: np.ndarray | None = None  # where the K-turn under way began [m]
        self.edge = EdgeReversal()  # reversing before the area's edge (law/edge_reversal.py)
        self.path = ApproachPath(approach_mps, max_speed_mps)  # a planned approach onto the line, while far from it
        self.capture = CaptureSearch(max_speed_mps)  # manoeuvres onto the line within CAPTURE_M of the goal
        self.holding = False  # on the line near the goal: feedback only (hysteresis on HOLD_* / LEAVE_*)
        self.cycle = CreepCycle(TURNING_RAD, gain_per_s)  # holding in a current: creeps upstream about the goal
        self.drift: np.ndarray | None = None  # the current the capture search's model boat drifts on [m/s]
        self.aim_t: float | None = None  # vehicle time of the last aim [s]
        self.stop_s = 1.0 / STOP_GAIN  # the boat's stopping time, set by the caller (estimation/speed_lag.py) [s]
        self.astern_able = True  # the boat goes astern, set by the caller (speed_lag.SternwayTrial): if not, ahead only

    def reset(self) -> None:
        self.axis_rad, self.astern, self.in_current, self.travel, self.pivot = None, False, False, None, None
        self.edge.reset()
        self.path.reset()
        self.capture.reset()
        self.holding = False
        self.cycle.reset()

    def aim(
        self,
        p_ned: np.ndarray,
        goal_ned: np.ndarray,
        heading_rad: float,
        current_ned: np.ndarray | None,
        drift_ned: np.ndarray | EllipsisType | None = ...,
        t: float | None = None,
    ) -> None:
        """Choose the line: along the current (the end nearest the one held, so that the line turns with the current
        in a vortex); in still water the line from the boat to the goal (kept once chosen, until :meth:`reset`).
        The bow's end of the line is the one the boat faces: past 90 deg + ``SWAP_RAD`` off it, the ends swap (the
        way to the goal is kept: ahead and astern swap with them). ``drift_ned``: the current the capture search's
        model boat drifts on where the line does not follow it (sheared water); None: none; default: current_ned.
        ``t``: vehicle time [s], once arrived (None before): holding on the current's line, it turns with AXIS_TAU_S."""
        self.drift = current_ned if drift_ned is ... else drift_ned
        if current_ned is not None:
            upstream = math.atan2(-current_ned[1], -current_ned[0])
            ref = heading_rad if self.axis_rad is None else self.axis_rad
            end = min((upstream, wrap_pi(upstream + math.pi)), key=lambda end: abs(wrap_pi(end - ref)))
            end = end if self.astern_able else upstream  # ahead only: it holds bow upstream
            held = self.axis_rad if self.holding and self.in_current else None  # holding on the current's line
            if held is not None and t is not None and self.aim_t is not None:
                step = min(1.0, max(t - self.aim_t, 0.0) / AXIS_TAU_S)  # it turns with AXIS_TAU_S
                end = wrap_pi(held + step * wrap_pi(end - held))
            self.axis_rad = end
        elif self.axis_rad is None:
            to_goal = np.asarray(goal_ned, dtype=float) - np.asarray(p_ned, dtype=float)
            self.axis_rad = math.atan2(to_goal[1], to_goal[0]) if float(np.hypot(*to_goal)) > 1e-6 else heading_rad
        self.in_current, self.aim_t = current_ned is not None, t
        if abs(wrap_pi(heading_rad - self.axis_rad)) > math.pi / 2 + SWAP_RAD and self.astern_able:
            self.axis_rad = wrap_pi(self.axis_rad + math.pi)
            self.travel = None if self.travel is None else -self.travel

    def command(
        self,
        p_ned: np.ndarray,
        goal_ned: np.ndarray,
        heading_rad: float,
        radius_m: float | None,
        current_ned: np.ndarray | None = None,
        speed_mps: float = 0.0,
        water_mps: float = 0.0,
        bias_ned: np.ndarray | None = None,
        outside: Callable[[np.ndarray], float] | None = None,
        t: float | None = None,
        arrived: bool = True,
    ) -> Maneuver:
        """Heading and signed speed toward the goal along the line, steering out the cross-track error.

        ``speed_mps``: the boat's ground speed (how far ahead to look for the area's edge); ``water_mps``: its
        speed through the water along its heading (negative: astern); ``bias_ned``: the station keeper's
        integral term [m/s] (law/station.py), added along the heading; ``outside``: how far points ``(K, 2)``
        lie outside the area the boat may use [m] (0 inside; None: no limit); ``t``: vehicle time [s] (None: no
        planned approach, feedback only); ``arrived``: the service has declared arrival (until then a hold that
        sits more than ``UNARRIVED_LEAVE_CROSS_M`` off the line is given up for the capture search)."""
        if self.axis_rad is None:
            raise ValueError("LineApproach.command before aim()")
        p = np.asarray(p_ned, dtype=float)
        e = p - np.asarray(goal_ned, dtype=float)
        _, _, along, cross = self._line_frame(e)
        self.path.stop_gain = min(STOP_GAIN, 1.0 / self.stop_s)  # no ramp runs on past its end
        if self.path.astern and not self.astern_able:  # shown not to go astern: plan again, ahead only
            self.path.reset()
            self.capture.reset()
        self.path.astern = self.capture.astern = self.astern_able
        planned = (
            None
            if t is None
            else self._planned(
                t, p, goal_ned, heading_rad, radius_m, along, cross, outside, current_ned, water_mps, arrived
            )
        )
        if planned is not None:
            return self._finish(planned, heading_rad, current_ned, water_mps)
        a, n, along, cross = self._line_frame(e)  # the plan may have chosen the other end of the line
        radius = radius_m if radius_m is not None else DEFAULT_RADIUS_M
        delta = min(MAX_DELTA_M, max(MIN_DELTA_M, radius))
        h = unit(heading_rad)
        # which way along the line to the goal (the bow lies along +a, so +1 is ahead): past the goal by the leash
        # (FLIP_M once on the line), the other way
        on_line = abs(cross) <= self.settle_m

        def inward(travel: float) -> bool:  # its LOS course does not lead out of the area
            return outside is None or outside(p + EDGE_COURSE_M * los_course(travel, delta, a, n, cross)) <= outside(p)

        def effort(travel: float) -> tuple[bool, float]:  # out of the area first, then the larger turn
            return (not inward(travel), abs(wrap_pi(los_heading(travel, delta, a, n, cross) - heading_rad)))

        if self.holding and self.in_current and current_ned is not None:
            return self._finish(
                self._hold_in_current(p, goal_ned, heading_rad, delta, a, n, cross, current_ned, bias_ned, radius),
                heading_rad,
                current_ned,
                water_mps,
            )
        if self.travel is None:  # toward the goal along the line; level with it, the smaller turn that stays inside
            far = abs(along) > (FLIP_M if self.holding else max(LEASH_M, abs(cross)))
            self.travel = (-1.0 if along > 0.0 else 1.0) if far else min((1.0, -1.0), key=effort)
        target = los_heading(self.travel, delta, a, n, cross)
        # off the line, where along the line the boat meets it matters less than getting there: past the goal by as
        # much as it still has to go across
        aligned = on_line and abs(wrap_pi(target - heading_rad)) <= TURNING_RAD
        leash = FLIP_M if self.holding or aligned else max(LEASH_M, abs(cross))
        if self.travel > 0 and along > leash:
            self.travel = -1.0
        elif self.travel < 0 and along < -leash:
            self.travel = 1.0
        elif abs(along) <= leash and not inward(self.travel) and inward(-self.travel):
            self.travel = -self.travel  # not yet past the goal either way: the way that stays in the area
        if self.travel < 0 and not (self.astern_able or self.in_current):  # ahead only: turn round to the goal
            self.axis_rad, self.travel = wrap_pi(self.axis_rad + math.pi), 1.0
            a, n, along, cross = self._line_frame(e)
        heading = los_heading(self.travel, delta, a, n, cross)
        error = abs(wrap_pi(heading - heading_rad))
        if error > K_TURN_RAD and self.astern_able:
            # a K-turn: ahead and astern in turn about where it began, every leg turning the bow toward the heading,
            # each leg until the boat has gone the leash past that point along its motion
            if self.pivot is None:
                self.pivot = p.copy()
            sign = -1.0 if self.astern else 1.0
            if float((self.pivot - p) @ (sign * h)) < -LEASH_M:
                self.astern = not self.astern
        else:
            self.pivot = None
            self.astern = self.travel < 0
        if outside is not None and self.astern_able:  # reverse before the area's edge, or back into it
            self.astern = self.edge.way(p, h, speed_mps, self.astern, outside)
        sign = -1.0 if self.astern else 1.0
        turning = error > TURNING_RAD
        s = sign * min(self.max_speed, min(self.gain, 1.0 / self.stop_s) * math.hypot(along, cross))
        if bias_ned is not None:
            s += float(np.asarray(bias_ned, dtype=float) @ unit(heading))  # the PI's integral along the heading
        if turning:
            s = sign * max(self.way, sign * s)  # a rudder turns the boat only with way on
        s = capped(s, self.max_speed)
        if s * sign < MIN_SPEED_MPS:  # toward the goal the other way than the boat is going: let it lie
            s = 0.0
        return self._finish(Maneuver(heading, s, self.astern), heading_rad, current_ned, water_mps)

    def _hold_in_current(
        self,
        p: np.ndarray,
        goal_ned: np.ndarray,
        heading_rad: float,
        delta: float,
        a: np.ndarray,
        n: np.ndarray,
        cross: float,
        current_ned: np.ndarray,
        bias_ned: np.ndarray | None,
        radius_m: float,
    ) -> Maneuver:
        """On the current's line near the goal: into the current only, ahead (bow upstream) or astern (bow
        downstream), by the creep cycle about the goal (law/creep_cycle.py), steering by LOS onto the line."""
        c = np.asarray(current_ned, dtype=float)
        up = -c / float(np.hypot(*c))
        self.travel = -1.0 if bow_downstream(self.axis_rad, c) else 1.0
        self.astern = self.travel < 0
        heading = los_heading(self.travel, delta, a, n, cross)
        to_go = float((np.asarray(goal_ned, dtype=float) - p) @ up)  # how far the goal lies upstream [m]
        bias = 0.0 if bias_ned is None else self.travel * float(np.asarray(bias_ned, dtype=float) @ unit(heading))
        error = abs(wrap_pi(heading - heading_rad))
        s = self.cycle.speed(to_go, cross, error, bias, float(np.hypot(*c)), radius_m, self.stop_s)
        # backed down (s < 0): stern first through the water, whichever end faces upstream
        speed = self.travel * (s if s < 0.0 else max(s, MIN_SPEED_MPS) if s > 0.0 else 0.0)
        return Maneuver(heading, speed, self.travel > 0 if s < 0.0 else self.astern)

    def _planned(
        self,
        t: float,
        p: np.ndarray,
        goal_ned: np.ndarray,
        heading_rad: float,
        radius_m: float | None,
        along: float,
        cross: float,
        outside: Callable[[np.ndarray], float] | None,
        current_ned: np.ndarray | None = None,
        water_mps: float = 0.0,
        arrived: bool = True,
    ) -> Maneuver | None:
        """Far from the line or facing off it: the planned approach's command (law/approach_path.py), planned
        anew when there is none; within ``CAPTURE_M`` of the goal, the capture search's manoeuvre (law/capture.py);
        None on the line near the goal (feedback holds the boat there), or before the boat's turning circle has
        been measured."""
        facing = abs(wrap_pi(heading_rad - self.axis_rad))
        ferry = self.in_current and not self.astern_able  # ahead only: the hold ferries it onto the line
        if self.holding and ferry:
            self.holding = math.hypot(along, cross) <= CAPTURE_LEAVE_M and facing <= LEAVE_RAD
        elif ferry:
            self.holding = math.hypot(along, cross) <= CAPTURE_M and facing <= FERRY_RAD
        elif self.holding:  # in still water the boat barely moves while it holds: off by more than it could be at
            # the goal (twice settle_m, the arrival radius), it would stay off
            leave_cross = LEAVE_CROSS_M if self.in_current else 2.0 * self.settle_m
            if not arrived:  # a hold beside the line, short of arriving, sat there for a minute and more (astern, or
                # in a gyre's sheared current its cross-track steering does not bring the bow round): capture again
                leave_cross = min(leave_cross, UNARRIVED_LEAVE_CROSS_M)
            # nor is a bow a current's line has turned away from since the hold took it on (the estimate turns the
            # line): 2 of 2 holds that arrived 15-17 deg off held 0.46-0.82 m p95, 22 at 10-15 deg at most 0.19 m
            leave_rad = UNARRIVED_LEAVE_RAD if self.in_current and not arrived else LEAVE_RAD
            self.holding = abs(cross) <= leave_cross and facing <= leave_rad and abs(along) <= LEAVE_ALONG_M
        else:
            # the hold takes on only a bow lined up as well as the capture search hands over: taken on 20-25 deg off,
            # its righting set boats beyond the reacquire radius (0.3-0.7 m p95 in one uniform run in 25); astern,
            # tighter still (capture.entry_rad)
            entry = entry_rad(self.axis_rad, current_ned if self.in_current else None)
            near = abs(cross) <= ENTRY_CROSS_M and facing <= entry and abs(along) <= HOLD_ALONG_M
            if near and self.in_current and current_ned is not None and abs(cross) > ENTRY_SIDE_M:
                # nor a boat that would creep away from the line: the hold turns the bow only as it creeps upstream
                # (ahead, or astern with the bow downstream), which first carried the boat farther off (4 of 4
                # takes-on traced at the default campaign's rudder start 5 toward S: 9-10 deg away; 0.08-0.19 m p95)
                creep = -1.0 if bow_downstream(self.axis_rad, current_ned) else 1.0
                near = creep * wrap_pi(heading_rad - self.axis_rad) * math.copysign(1.0, cross) <= ENTRY_AWAY_RAD
            if near and self.path.active:  # a planned path is driven to its end first (its last leg lines the bow up)
                m = self.path.command(t, p, heading_rad, current_ned)
                if m is not None:
                    return m
            self.holding = near
        if self.holding or radius_m is None:  # holding; or its turning circle not yet seen: nothing to plan with
            self.path.reset()
            self.capture.reset()
            return None
        zone = CAPTURE_LEAVE_M if self.capture.active else CAPTURE_M  # hysteresis: no chatter with the planner
        if math.hypot(along, cross) <= zone:  # the last decimetres onto the line: a search over manoeuvres
            self.path.reset()
            # within CAPTURE_M the current at the boat is near the goal's, even where the line does not follow it
            # (self.drift, Helm._on_line): a model boat in still water there, the vortex's 0.025 m/s across a still-
            # water line set the real one off it on every capture (rudder, vortex seeds 37-43: 236/252; 241/252 on it)
            goal, c = np.asarray(goal_ned, dtype=float), self.drift
            return self.capture.command(t, p, goal, heading_rad, water_mps, self.axis_rad, c, radius_m, outside)
        self.capture.reset()
        if self.path.active and self.in_current and self.path.final_heading is not None:
            off = abs(wrap_pi(self.path.final_heading - self.axis_rad))
            if min(off, math.pi - off) > REPLAN_OFF_LINE_RAD:  # planned before the current was known: not its line
                self.path.reset()
        m = self.path.command(t, p, heading_rad, current_ned) if self.path.active else None
        if m is None and self.path.may_plan(t):
            ends = (self.axis_rad, wrap_pi(self.axis_rad + math.pi)) if self.in_current else None  # either end
            goal = np.asarray(goal_ned, dtype=float)
            if not self.path.plan(t, p, heading_rad, goal, ends, radius_m, outside, current_ned):
                return None
            final = self.path.final_heading  # the bow's end of the line: the path's
            if self.in_current:
                final = min((self.axis_rad, wrap_pi(self.axis_rad + math.pi)), key=lambda a: abs(wrap_pi(a - final)))
            self.axis_rad, self.travel = final, None
            m = self.path.command(t, p, heading_rad, current_ned)
        return m

    @staticmethod
    def _finish(m: Maneuver, heading_rad: float, current_ned: np.ndarray | None, water_mps: float) -> Maneuver:
        """The rules every command obeys: drift where the rudder would misread the speed, and hold the heading
        while a reversal stops the boat."""
        heading, s = m.heading_rad, m.speed_mps
        if s != 0.0 and current_ned is not None:
            water = s - float(np.asarray(current_ned, dtype=float) @ unit(heading))  # through the water along it
            if water * s < 0.0:  # over ground one way, the water past the rudder the other: drift instead
                s = 0.0
        if s * water_mps < 0.0 and abs(water_mps) > STILL_MPS:
            # still moving the old way after a reversal: hold the heading while it stops (until the water passes
            # the rudder the new way the rudder turns it the wrong way, whichever way the autopilot sets it)
            heading = heading_rad
        return Maneuver(heading, s, m.astern)

    def _line_frame(self, e: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
        """The line's unit axis ``a`` (the bow's end), its right normal ``n``, and the offset ``e`` = boat - goal
        [m] along and across it (ahead of the goal along the axis, to its right)."""
        a = unit(self.axis_rad)
        n = np.array([-a[1], a[0]])
        return a, n, float(e @ a), float(e @ n)
