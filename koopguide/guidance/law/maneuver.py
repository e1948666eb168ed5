"""Heading-and-speed commands for any boat: ahead or astern, slowed to turn or kept with way (pure math).

ArduPilot Rover in GUIDED takes a velocity + yaw setpoint (type mask 2535) as "hold heading ``yaw`` at speed
over ground ``s`` along it", with ``s < 0`` astern (docs/rover.md). That is the one command that works on
every kind of boat near a point, where a velocity-only setpoint (heading = its direction, speed >= 0) makes a
boat turn toward wherever it should go, however far round that is:

* the heading: along the velocity the boat needs through the water, ``w = v_ground - c`` (with the estimated
  current ``c``; its component across the heading is not corrected by Rover and carries the boat sideways,
  so the ground velocity is exactly ``v_ground``: see law.command.crab), ahead; or the reverse heading,
  astern, when ahead would need a turn of more than ``ASTERN_RAD`` and astern one of less (hysteresis: the
  other way round to come back ahead). In a current the boat thus faces upstream when it holds station;
* the speed: the ground velocity's component along the heading (signed; it is negative ahead, or positive
  astern, when the boat is to be carried back by a current faster than it is to move);
* a boat that turns in place is slowed to turn: by cos(heading error), and near a point to no more than the
  speed whose turning circle still reaches it, ``|s| <= omega d / (2 |sin e|)`` (the circle tangent to the
  heading through a point at distance d and bearing e off it has radius d / (2 |sin e|)), with omega the
  boat's turn rate (estimation/turning.py);
* a boat that needs way through the water to turn (a rudder boat) is never slowed below ``way_mps`` while it
  turns, and it may go astern anywhere (not only near a point), so a field's hairpin is taken by backing
  down its next leg instead of a turning circle the boat does not have;
* keeping station in a current (``holding``), the hull stays on the current's line, bow up- or downstream,
  whichever end is nearer the heading (hysteresis ``HOLDING_ASTERN_RAD``), turned off it by no more than the
  ferry-glide angle ``ferry_rad``: atan(cross / (|c| + up)), for the wanted ground speed ``cross`` across the line
  and ``up`` (>= 0) up it (the crab angle of w; going downstream, that of the ferry glide: the current's component
  across a hull turned by delta off the line sets it that way at |c| sin delta), with no turning circle to
  make (slowed by cos^2 of the heading error while it turns). The exact
  heading along w swings round the compass when the wanted ground velocity is near the current's own (w -> 0:
  the goal just downstream), and every turn sets a boat that turns at 7 deg/s off by the current: at the goal
  across the current, boats turned up to 160 deg, and the current set them 0.24-0.38 m off while they did.
  So does a boat that turns in place making for a point (``distance_m``) whose wanted ground velocity is nearly the
  current's (``|w| < DRIFT_ENTER |c|``, until ``DRIFT_LEAVE``): drifting onto a goal just downstream. There w is small
  and turns with every tick (the approach cap, law/command.py, puts it at the edge of the sector the hull may face),
  and a boat that came in bow downstream pivoted after it for 25 s (the simulator's) to 35 s (a hull of twice its
  mass) 0.3 m short of the goal; on the line it drifts in as it lies, stern to the current, in a few seconds. The
  ground velocity made good then differs from the one wanted by w's part across the hull, under ``DRIFT_LEAVE |c|``.

Conventions: NED velocities ``(2,)`` [m/s], headings [rad] from north, turn rates [rad/s], distances [m].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from koopguide.guidance.estimation.turning import TurnAbility
from koopguide.guidance.law.command import CRAB_MIN_SPEED_MPS, CURRENT_MIN_MPS
from koopguide.mavlink.rover import float32_toward_zero

ASTERN_RAD = math.radians(120.0)  # switch ahead <-> astern when the current direction needs a larger turn
HOLDING_ASTERN_RAD = math.radians(100.0)  # ... keeping station in a current: the nearer end of its line, past 90 deg
TURNING_RAD = math.radians(15.0)  # a heading error this large is a turn (for the way floor)
# |w| / |c| below which a boat making for a point drifts on the current's line (and above which it stops). At the edge
# of the approach cap's sector (law/command.py), |w| = |c| sin(alpha) / sin(theta + alpha) for a goal alpha off
# straight downstream: 0.5 drifts onto a goal 16 deg off from 0.45 m in and one 20 deg off from 0.4 m in (theta
# narrows as the boat closes; tests/guidance/test_current_compensation.py); at 0.3 (stop 43) a goal 16 deg off drifted
# only from 0.35 to 0.21 m, and a heavier boat at 0.37-0.40 m (|w| 0.36-0.41 |c|) pivoted 0.3 m short of it for 30 s
# instead, in 3 of 23 flights beside two busy processes (arrived after 71.4 s)
DRIFT_ENTER, DRIFT_LEAVE = 0.5, 0.7
CIRCLE_MARGIN = 0.7  # fraction of the geometric speed cap used (the turn rate is an estimate)
# a boat that turns in place chasing a heading that turns as fast: once it has turned CHASE_TURNED_RAD in CHASE_S
# without closing on the heading by CHASE_CLOSE_RAD, it takes the other end (ahead <-> astern) for CHASE_S, turning
# the other way to meet the heading
CHASE_S = 8.0  # [s]
CHASE_ERROR_RAD = math.radians(60.0)  # ... while it pivots this far off it (Rover's WP_PIVOT_ANGLE; under, it drives)
CHASE_TURNED_RAD = math.radians(30.0)
CHASE_CLOSE_RAD = math.radians(15.0)
CHASE_GAP_S = 1.0  # a turn not watched for this long (no command with a heading, a hold) is watched afresh [s]
# the smallest speed sent while steering (exactly 0 would be Rover's stop controller), and the current estimate
# below which there is no current: the law's own (law/command.py), one value each for both
MIN_SPEED_MPS = CRAB_MIN_SPEED_MPS


Angle = TypeVar("Angle", float, np.ndarray)


def wrap_pi(angle: Angle) -> Angle:
    """``angle`` [rad] wrapped into [-pi, pi) (a float, or an array element-wise)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def unit(angle_rad: float) -> np.ndarray:
    """The NED unit vector of heading ``angle_rad`` [rad from north]."""
    return np.array([math.cos(angle_rad), math.sin(angle_rad)])


def capped(speed_mps: float, max_speed_mps: float) -> float:
    """A signed speed (negative: astern) [m/s] with its size capped at ``max_speed_mps``."""
    return min(max_speed_mps, max(-max_speed_mps, speed_mps))


def within_speed(v_ned: tuple[float, float] | np.ndarray, max_speed_mps: float) -> tuple[float, float]:
    """The setpoint ``v_ned`` (2,) [m/s] shortened, where need be, so that its norm is at most ``max_speed_mps`` as
    computed and as sent (MAVLink's float32): a heading's cos and sin times the top speed come out one ulp over in
    167 of 3600 headings (0.3 m/s: 0.30000000000000004), and 0.3 as a float32 is 0.3000000119."""
    vn, ve = float(v_ned[0]), float(v_ned[1])
    norm = math.hypot(vn, ve)
    if norm > max_speed_mps:
        vn, ve = vn * (max_speed_mps / norm), ve * (max_speed_mps / norm)
    wire = math.hypot(float(np.float32(vn)), float(np.float32(ve)))  # as sent (rounded to nearest)
    if math.hypot(vn, ve) <= max_speed_mps and wire <= max_speed_mps:
        return vn, ve
    vn, ve = float32_toward_zero(vn), float32_toward_zero(ve)  # float32 values: sent as they are
    while math.hypot(vn, ve) > max_speed_mps:  # (a component float32 already)
        vn, ve = float32_toward_zero(vn * (1.0 - 2.0**-23)), float32_toward_zero(ve * (1.0 - 2.0**-23))
    return vn, ve


def water_current(current_ned: np.ndarray | None) -> np.ndarray:
    """The current the water moves at [m/s]: the estimate, or none (zeros) when absent or below
    ``CURRENT_MIN_MPS``."""
    c = np.zeros(2) if current_ned is None else np.asarray(current_ned, dtype=float)
    return c if float(np.hypot(*c)) >= CURRENT_MIN_MPS else np.zeros(2)


@dataclass(frozen=True)
class Maneuver:
    """A heading-and-speed command: ``speed_mps`` over ground along ``heading_rad`` (negative: backward over
    ground); ``astern``: the boat moves stern first through the water."""

    heading_rad: float
    speed_mps: float
    astern: bool

    @property
    def velocity_ned(self) -> np.ndarray:
        """The commanded ground velocity along the heading [m/s] (points backward when astern)."""
        return self.speed_mps * np.array([math.cos(self.heading_rad), math.sin(self.heading_rad)])


class ManeuverPlanner:
    """Chooses ahead or astern, and whether to drift onto a point on the current's line, each with hysteresis (its
    only state), and shapes the speed for the boat's turning."""

    def __init__(self, max_speed_mps: float, way_mps: float, ferry_rad: float) -> None:
        self.max_speed = max_speed_mps
        self.way = min(way_mps, max_speed_mps)
        self.ferry = ferry_rad
        self.astern = False
        self.drifting = False  # making for a point at nearly the current's own velocity: on its line
        self._turn: tuple[float, float, float, bool] | None = None  # (t, heading, |error|, astern) as a turn began
        self._end_until: float | None = None  # vehicle time until which the end a chase chose is kept [s]
        self._watched_t: float | None = None  # the last vehicle time the chase was watched [s]

    def reset(self) -> None:
        self.astern = self.drifting = False
        self._turn = self._end_until = self._watched_t = None

    def plan(
        self,
        v_ground: np.ndarray,
        heading_rad: float,
        current_ned: np.ndarray | None,
        ability: TurnAbility,
        distance_m: float | None = None,
        allow_astern: bool = True,
        slow_to_turn: bool = True,
        holding: bool = False,
        t: float | None = None,
    ) -> Maneuver:
        """The command that moves the boat over ground at ``v_ground`` [m/s] from ``heading_rad``.

        ``distance_m`` (to the point it makes for, when near one) caps the speed of a boat that turns in place
        so that its turning circle reaches the point (``slow_to_turn`` False: no slowing at all); a boat that
        needs way keeps ``way_mps`` while it turns. ``holding``: keeping station (in a current: on its line); a boat
        that turns in place making for a point at nearly the current's velocity drifts onto it on that line too.
        ``t`` (vehicle time [s]; None: not watched) watches a boat that turns in place making for a point (not holding
        station, nor on the current's line) for a chase (:meth:`_chasing`).
        """
        v = np.asarray(v_ground, dtype=float)
        c = water_current(current_ned)
        w = v - c  # through the water
        c_norm, w_norm = float(np.hypot(*c)), float(np.hypot(*w))
        ferry = None
        near = distance_m is not None and not ability.needs_way  # (no current, c_norm 0: never drifting)
        self.drifting = near and w_norm < (DRIFT_LEAVE if self.drifting else DRIFT_ENTER) * c_norm
        if (holding or self.drifting) and c_norm > 0.0:  # on the current's line: its nearer end, then the ferry
            ahead, flip = math.atan2(-c[1], -c[0]), HOLDING_ASTERN_RAD  # upstream
            cross = float(v @ unit(ahead + 0.5 * math.pi))  # the wanted ground speed across the line
            # the crab angle of the water velocity w (exact), or the ferry glide's when going downstream
            ferry = min(self.ferry, max(-self.ferry, math.atan2(cross, c_norm + max(float(v @ unit(ahead)), 0.0))))
            distance_m = None  # the hull keeps to the line: no turning circle to make the goal by
        elif w_norm <= 1e-9:  # drifting with the current is wanted (or nothing at all): speed 0
            return Maneuver(heading_rad, 0.0, self.astern)  # is Rover's stop controller, throttle off: it drifts
        else:
            ahead, flip = math.atan2(w[1], w[0]), ASTERN_RAD
        error_ahead = wrap_pi(ahead - heading_rad)
        # a boat that turns in place making for a point (not holding station, nor on the current's line) is watched
        now = t if t is not None and ferry is None and not holding and not ability.needs_way and allow_astern else None
        if now is None:
            self._turn = self._end_until = None
        end_error = abs(wrap_pi(error_ahead + math.pi)) if self.astern else abs(error_ahead)
        kept = now is not None and self._end_until is not None and 0.0 <= self._end_until - now <= CHASE_S
        if not allow_astern:
            self.astern = False
        elif kept and end_error <= ASTERN_RAD:
            pass  # the end a chase chose (below), kept for CHASE_S though the other is nearer (not past ASTERN_RAD)
        elif self.astern:
            self.astern = abs(wrap_pi(error_ahead + math.pi)) <= flip
        else:
            self.astern = abs(error_ahead) > flip
        ahead = ahead if ferry is None else ahead + ferry  # the hull's line turned off the current's, either end
        h = wrap_pi(ahead + math.pi) if self.astern else wrap_pi(ahead)
        error = wrap_pi(h - heading_rad)
        if now is not None and self._chasing(now, heading_rad, abs(error)):
            self.astern = not self.astern  # the other end of the heading's line: turning the other way, to meet it
            self._end_until = now + CHASE_S
            h = wrap_pi(h + math.pi)
            error = wrap_pi(h - heading_rad)
        s = float(v @ np.array([math.cos(h), math.sin(h)]))  # ground speed along the heading (signed)
        # the sign of s is that of the ground motion along the heading: it can differ from ahead/astern (through
        # the water) when the boat is to drift back slower than the current carries it
        sign = math.copysign(1.0, s) if abs(s) >= MIN_SPEED_MPS else (-1.0 if self.astern else 1.0)
        size = max(abs(s), MIN_SPEED_MPS)
        if ability.needs_way:
            if abs(error) >= TURNING_RAD:
                size = max(size, self.way)  # a rudder turns the boat only with way on
        elif slow_to_turn:
            # slowed by cos e while it turns; holding, by cos^2 e: the motion across the heading asked (sin e times the
            # speed) is what sets the boat off its station (at cos e, 0.04 m/s at 67 deg off carried a boat 0.25 m off)
            size *= max(math.cos(error), 0.0) ** (2 if ferry is not None else 1)
            if distance_m is not None and abs(math.sin(error)) > 1e-6:
                size = min(size, CIRCLE_MARGIN * ability.turn_rate * distance_m / (2.0 * abs(math.sin(error))))
            size = max(size, MIN_SPEED_MPS)
        return Maneuver(h, sign * min(size, self.max_speed), self.astern)

    def _chasing(self, t: float, heading_rad: float, error_rad: float) -> bool:
        """Whether a boat that turns in place, ``error_rad`` [rad] off the heading it is sent, has been chasing it: in
        the last ``CHASE_S`` it turned by ``CHASE_TURNED_RAD`` or more and closed on it by less than
        ``CHASE_CLOSE_RAD``. Making for the goal while a current carries it round it (the double gyre by the campaign's
        goal: 0.05 m/s across at 0.45 m, 6 deg/s of bearing), the heading it is sent turns as fast as the boat pivots,
        which never catches it and is carried round for a minute and more (diff_thrust, the default campaign's double
        gyre start 2: 2 of 10 flights did not arrive within 120 s, 4 of 10 took 103 s; stop 56); the other end of the
        line, turning the other way, meets it. A turn is watched while the boat pivots (``CHASE_ERROR_RAD`` or more off
        the heading) on the same end: driving past its goal under that, its bearing turns as the boat comes round to it
        (a flip there sent the diff_thrust boat of the default campaign's double gyre start 3 on a 160 deg pivot), and
        afresh after ``CHASE_GAP_S`` unwatched. A heading that turns faster than the boat pivots is chased either way:
        the boat then flips every ``CHASE_S`` or so, and stays within a few degrees of it."""
        last, self._watched_t = self._watched_t, t
        if last is None or not 0.0 <= t - last <= CHASE_GAP_S:
            self._turn = None
        turn = self._turn
        if error_rad < CHASE_ERROR_RAD:
            self._turn = None
            return False
        if turn is None or turn[3] != self.astern:
            self._turn = (t, heading_rad, error_rad, self.astern)
            return False
        if t - turn[0] < CHASE_S:
            return False
        turned = abs(wrap_pi(heading_rad - turn[1]))
        chased = turned >= CHASE_TURNED_RAD and turn[2] - error_rad < CHASE_CLOSE_RAD
        self._turn = None if chased else (t, heading_rad, error_rad, self.astern)  # the next window from here
        return chased
