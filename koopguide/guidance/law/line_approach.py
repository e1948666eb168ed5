"""Bringing a boat that cannot turn without way onto a point, and keeping it there (pure math).

A rudder boat turns only while it moves, on a circle of radius R (estimation/turning.py). It cannot turn on
the spot to face the goal, nor to face the current once there, so it must arrive already on the line it
will hold: the line through the goal along the current (bow upstream, where the current alone cannot set it
sideways), or, in still water, the line from where the approach began. On that line it moves ahead or astern
only; what is left across the line is steered out by line-of-sight guidance, aiming at the point
``Delta`` further along the line (Fossen (2021), "Handbook of Marine Craft Hydrodynamics and Motion Control",
2nd ed., section 12.4.2, LOS steering law ``chi_d = chi_p - atan(y_e / Delta)``). The look-ahead
``Delta >= R`` keeps the turns it asks for within the boat's circle.

Conventions: positions ``(2,)`` local NED [m], velocities NED [m/s], headings [rad] from north.
"""

from __future__ import annotations

import math

import numpy as np

from koopguide.guidance.law.maneuver import MIN_SPEED_MPS, Maneuver

MIN_DELTA_M = 0.3  # the smallest LOS look-ahead [m]
FLIP_M = 0.03  # ahead <-> astern changes only when the goal is this far past the boat along the line [m]


def unit(angle_rad: float) -> np.ndarray:
    return np.array([math.cos(angle_rad), math.sin(angle_rad)])


class LineApproach:
    """LOS guidance onto the line through the goal with bow direction ``axis_rad`` (set by :meth:`aim`)."""

    def __init__(self, max_speed_mps: float, gain_per_s: float, settle_m: float) -> None:
        self.max_speed = max_speed_mps
        self.settle_m = settle_m  # an offset across the line this small is left alone (no S-turns for it) [m]
        self.gain = gain_per_s
        self.axis_rad: float | None = None  # the bow's direction on the line [rad]
        self.in_current = False  # the line is the current's (bow upstream)
        self.astern = False

    def reset(self) -> None:
        self.axis_rad, self.astern, self.in_current = None, False, False

    def aim(self, p_ned: np.ndarray, goal_ned: np.ndarray, heading_rad: float, current_ned: np.ndarray | None) -> None:
        """Choose the line: bow upstream in a current; in still water, the line from the boat to the goal, bow
        along whichever way round the boat already faces (kept once chosen, until :meth:`reset`)."""
        self.in_current = current_ned is not None
        if current_ned is not None:
            self.axis_rad = math.atan2(-current_ned[1], -current_ned[0])
        elif self.axis_rad is None:
            to_goal = np.asarray(goal_ned, dtype=float) - np.asarray(p_ned, dtype=float)
            bearing = math.atan2(to_goal[1], to_goal[0]) if float(np.hypot(*to_goal)) > 1e-6 else heading_rad
            ahead = math.cos(bearing - heading_rad) >= 0.0
            self.axis_rad = bearing if ahead else bearing + math.pi

    def command(self, p_ned: np.ndarray, goal_ned: np.ndarray, radius_m: float | None) -> Maneuver:
        """Heading and signed speed toward the goal along the line, steering out the cross-track error."""
        if self.axis_rad is None:
            raise ValueError("LineApproach.command before aim()")
        a = unit(self.axis_rad)
        n = np.array([-a[1], a[0]])
        e = np.asarray(p_ned, dtype=float) - np.asarray(goal_ned, dtype=float)
        along, cross = float(e @ a), float(e @ n)  # [m] ahead of the goal (upstream), to the right of the line
        delta = max(MIN_DELTA_M, radius_m or 0.0)
        # ahead <-> astern once past the goal along the line; while off the line by more than settle_m, only once
        # far enough past to have steered out part of the offset (an S-turn of radius R across y needs about
        # 2 sqrt(R y) of travel)
        flip = FLIP_M if abs(cross) <= self.settle_m else max(FLIP_M, math.sqrt(delta * abs(cross)))
        if along > flip:
            self.astern = True  # past the goal toward the bow: back down onto it
        elif along < -flip:
            self.astern = False
        travel = -a if self.astern else a
        aim = delta * travel - cross * n  # toward the point delta along the line (LOS)
        heading = math.atan2(aim[1], aim[0]) + (math.pi if self.astern else 0.0)
        if self.in_current and self.astern and abs(cross) <= self.settle_m:
            # upstream of the goal on the line, bow upstream: let the current carry it back (speed exactly 0 is
            # Rover's stop controller, throttle off); backing down would reverse its steering (Rover reverses
            # the steering when the ground speed is negative) while the water still flows past the rudder ahead
            return Maneuver(heading, 0.0, True)
        speed = min(self.max_speed, self.gain * math.hypot(along, cross))
        speed = max(speed, MIN_SPEED_MPS)
        return Maneuver(heading, -speed if self.astern else speed, self.astern)
