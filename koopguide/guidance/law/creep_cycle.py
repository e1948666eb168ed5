"""Keeping a boat that needs way on a point in a current: a cycle of creeps upstream about it (pure math).

A rudder boat held on the current's line through the goal (law/line_approach.py) must keep the water passing
its rudder one way: into the current only, ahead with the bow upstream or astern with it downstream, never the
other way over ground (that would turn the water past the rudder round, and the autopilot sets the rudder by the
speed's sign, docs/rover.md). So it keeps station by a cycle about the goal: it creeps upstream (at least
``CREEP_MPS`` over ground, at most ``HOLD_MAX_MPS``) from ``CREEP_M`` / 2 downstream of the goal to ``CREEP_M``
/ 2 past it, then is sent speed 0 (Rover's stop controller: throttle off) while the current carries it back;
with the bow off the line it keeps way on (at least ``HOLD_WAY_MPS``) until the bow is back, but no further than
``CREEP_M`` past the goal (then it drifts back first). Drifting back no water passes the rudder and the bow stays
off, so the creep that rights it begins half its run downstream of the goal, centring the run on it.

Not every autopilot drifts at speed 0: one without Rover's stop controller holds the boat's ground at speed 0 (its
speed loop over ground keeps way on against the current), and a boat that began its hold upstream of the goal then
sat there, 0.2 m off, for good. Such a boat (``holds_at_rest``, learned by the caller: estimation/speed_lag.py
``RestHold``) is backed down instead of drifting: over ground downstream at the current's speed and
``BACK_MARGIN_MPS`` more, so the water passes its rudder from astern, the way the autopilot sets the rudder for a
negative speed.

Conventions: distances [m] along the current's line, positive upstream; speeds over ground [m/s], unsigned (the
caller signs them ahead or astern); heading errors [rad].
"""

from __future__ import annotations

import math

HOLD_WAY_MPS = 0.06  # righting the bow: at least this over ground into the current [m/s]
HOLD_MAX_MPS = 0.1  # ... and never more than this [m/s]
CREEP_M, CREEP_MPS = 0.12, 0.03  # creep this far upstream (about the goal), this fast at least
BACK_MARGIN_MPS = 0.5 * CREEP_MPS  # backing down: this much faster than the current over ground [m/s]


class CreepCycle:
    """Call :meth:`speed` each tick of the hold; :meth:`reset` when the hold ends. ``righting_rad``: a heading
    error this large is righted with way on (until back within half of it); ``gain_per_s``: the station
    keeper's proportional gain."""

    def __init__(self, righting_rad: float, gain_per_s: float) -> None:
        self.righting_rad, self.gain = righting_rad, gain_per_s
        self.righting = False  # the bow off the line: way on until it is back (hysteresis)
        self.creeping = False  # creeping upstream past the goal (else drifting back onto it)
        self.backing = False  # righting took the boat CREEP_M past the goal: drifting back onto it first
        self.holds_at_rest = False  # speed 0 holds the boat's ground: backed down instead (set by the caller)

    def reset(self) -> None:
        self.righting = self.creeping = self.backing = False

    def speed(
        self,
        to_go_m: float,
        cross_m: float,
        error_rad: float,
        bias_mps: float = 0.0,
        current_mps: float = 0.0,
        radius_m: float = 0.0,
        stop_s: float = 0.0,
    ) -> float:
        """The speed over ground into the current [m/s], 0 to drift, negative to back down (downstream):
        ``to_go_m`` how far the goal lies upstream, ``cross_m`` the offset across the line, ``error_rad`` how far
        the bow is off its LOS heading, ``bias_mps`` the station keeper's integral term along the way into the
        current; ``current_mps`` the current's speed."""
        # the bow off the line: way on until it is back within half the turn threshold (short bursts of way, the
        # boat drifting back between them, leave the bow where it was: the rudder's force grows with the
        # square of the water's speed past it)
        self.righting = error_rad > (0.5 * self.righting_rad if self.righting else self.righting_rad)
        # a cycle about the goal, each creep long enough for the rudder to act (bursts of way at the goal, the boat
        # drifting back between them, steer it hardly at all)
        if to_go_m >= self._creep_from_m(error_rad, radius_m, current_mps, stop_s):
            self.creeping = True
        elif to_go_m < -0.5 * CREEP_M:
            self.creeping = False
        # righting costs about R times the angle in way (0.3 m for 15 deg ahead; astern, where the rudder is weak,
        # the bow did not come back): it ran the boat 0.3 m upstream and beyond reacquire_radius_m (holds of p95
        # 0.30-0.32 m astern in uniform currents; ahead, a drift-off whose capture then ran 0.45 m past the goal).
        # CREEP_M past the goal the boat drifts back instead, and rights the bow further on the next creep
        self.backing = self.righting and (to_go_m < -CREEP_M or (self.backing and not self.creeping))
        if self.backing or not (self.creeping or self.righting):
            # drifting back: speed 0, the current carries the boat (not while the bow is off the line: drifting,
            # no water passes the rudder, and the bow would stay off)
            return -(current_mps + BACK_MARGIN_MPS) if self.holds_at_rest else 0.0
        s = self.gain * math.hypot(max(to_go_m, 0.0), cross_m) + bias_mps
        # slowing to the creep's end: coasting on from the offset's speed, boats ran 0.11-0.14 m past the goal
        s = min(s, CREEP_MPS + self.gain * max(to_go_m + 0.5 * CREEP_M, 0.0))
        s = max(s, HOLD_WAY_MPS if self.righting else CREEP_MPS)  # the current's flow past the rudder and more
        return min(HOLD_MAX_MPS, s)

    def _creep_from_m(self, error_rad: float, radius_m: float, current_mps: float, stop_s: float) -> float:
        """How far downstream of the goal the next creep begins [m]: CREEP_M / 2; with the bow off the line, half
        the run that righting it takes upstream over ground, so that the run is centred on the goal (at most
        CREEP_M, as far as righting may run past it). A boat drifting back at speed 0 has no water past its rudder
        and arrives with its bow as it left: a no-astern rudder boat held 35 deg off, righted from CREEP_M / 2
        downstream, ran 0.19 m upstream, to 0.13 m past the goal and 0.19 m from it (0.16 m turning, 0.06 m coasting
        on at the end)."""
        if not self.righting:
            return 0.5 * CREEP_M
        # a turn at the radius through the error down to the end of righting, through the water at HOLD_WAY_MPS
        # over ground and the current's speed (the current's share of that run is taken off over ground), then
        # the way dying over ``stop_s``
        turn = radius_m * max(error_rad - 0.5 * self.righting_rad, 0.0) / (HOLD_WAY_MPS + current_mps)  # [s]
        run = HOLD_WAY_MPS * (turn + stop_s)
        return min(CREEP_M, max(0.5 * CREEP_M, 0.5 * run))
