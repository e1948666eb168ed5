"""TurnAbility: how this boat turns, learned from its own telemetry while it is guided (pure, no I/O).

The service does not know the boat it steers: a skid-steer or vectored boat turns on the spot, a boat with a
single propeller and a rudder turns only with way through the water (its rudder force grows with the speed
through the water; docs/rover.md, docs/guidance.md "Any boat"). Both are read from what the boat does when
asked to turn, i.e. while the heading it was sent differs from its heading by more than ``ASKED_RAD``:

* moves sideways (set by the turn probe, guidance/turn_probe.py): asked a hard turn under way, it went where it
  was sent through the water, across its heading, and its heading did not move (or came round at once, a circle no
  rudder boat turns): a vehicle whose velocity follows the setpoint while its heading does not, or is merely the
  direction it moves in; its heading then tells nothing about how it moves;
* turns in place: it turned faster than ``PIVOT_RATE`` while slower than ``STILL_MPS`` through the water, for
  ``PIVOT_S`` in a row (not the moment a boat reversing from ahead to astern passes through zero speed), where its
  way through the water is known: with no current estimate yet, the speed is the ground's along the heading, and a
  rudder boat stemming an unknown current at its own speed through the water, turning, looks just like a pivot (a
  property test found one: 0.0625 m/s through the water against 0.0625 m/s, turning at 3 deg/s, stop 44);
* needs way: it stayed below ``STUCK_RATE`` while slower than ``SLOW_MPS`` for ``STUCK_S`` in a row
  (a rudder boat asked to turn at a crawl). Until either is seen, the boat is taken to turn in place (the
  Rover skid-steer default); evidence of the other kind replaces it;
* turn rate [rad/s]: the fastest turn seen while asked to turn, fading with ``FADE_S`` (a floor of
  ``RATE_FLOOR`` before any turn is seen), used to cap the speed near a point (see law/maneuver.py);
* turning radius [m]: speed through the water over turn rate, ``u / |r|``, the tightest seen (relaxing with
  ``RADIUS_RELAX_S``) in hard turns asked for ``RADIUS_SETTLE_S`` at least, at speed
  (``FAST_MPS`` to ``MANOEUVRE_MAX_MPS``: manoeuvring speeds, where a rudder boat's circle is widest), the
  radius the pursuit's look-ahead must exceed and the planned approach plans with.

Conventions: speeds through the water along the heading [m/s], turn rates [rad/s], vehicle seconds.
"""

from __future__ import annotations

import math

ASKED_RAD = math.radians(40.0)  # a heading error this large asks for a hard turn
STILL_MPS = 0.02  # slower than this through the water: "still" (a turn then is a turn in place) [m/s]
SLOW_MPS = 0.06  # slower than this through the water: "at a crawl" [m/s]
FAST_MPS = 0.08  # turns at this speed or faster measure the turning radius [m/s]
MANOEUVRE_MAX_MPS = 0.22  # ... and at most this fast: the circle at manoeuvring speed, where a rudder boat's is
# widest (its rudder force grows with the speed squared, the yaw damping it works against less), not the one of a
# turn at full speed along the field [m/s]
PIVOT_RATE = math.radians(3.0)  # a turn this fast at a crawl is a turn in place [rad/s]
STUCK_RATE = math.radians(2.0)  # slower than this at a crawl while asked to turn: no turn without way [rad/s]
STUCK_S = 2.0  # ... for this long in a row [s]
PIVOT_S = 1.0  # a turn in place is one that lasts this long [s]
RATE_FLOOR = math.radians(4.0)  # the turn rate assumed before any hard turn is seen [rad/s]
FADE_S = 60.0  # the fastest turn seen fades with this time constant [s]
RADIUS_SETTLE_S = 1.5  # a hard turn measures the radius only once it has been asked this long (the rudder over) [s]
RADIUS_RELAX_S = 60.0  # the tightest circle seen widens again with this time constant (a boat that changed) [s]
MAX_RADIUS_M = 20.0  # a larger u / |r| is not a turn (noise around straight running) [m]


class TurnAbility:
    """Fold in one sample per command with :meth:`update`; read :attr:`needs_way`, :attr:`turn_rate`,
    :attr:`radius_m`."""

    def __init__(self) -> None:
        self.needs_way = False  # the boat does not turn without way through the water (seen, not assumed)
        self.moves_sideways = False  # it goes where it is sent whatever its heading (seen by the helm's probe)
        self.pivot_seen = False
        self.turn_rate = RATE_FLOOR  # [rad/s]
        self.radius_m: float | None = None  # turning radius at speed [m]; None before a turn at speed
        self.radius_speed_mps: float | None = None  # ... the speed through the water it was measured at [m/s]
        self._stuck_since: float | None = None
        self._pivot_since: float | None = None
        self._asked_since: float | None = None  # vehicle time the hard turn under way was first asked [s]
        self._t: float | None = None

    def update(
        self,
        t: float,
        asked_error_rad: float | None,
        speed_water_mps: float,
        turn_rate_radps: float,
        way_known: bool = True,
    ) -> None:
        """One sample at vehicle time ``t``: the heading error the boat was sent (None: no heading asked),
        its speed through the water along its heading and its turn rate. ``way_known``: that speed is through the
        water (False: over ground, no current known; no turn in place is read from it)."""
        if not (math.isfinite(speed_water_mps) and math.isfinite(turn_rate_radps)):
            return
        dt = 0.0 if self._t is None or t <= self._t else t - self._t
        self._t = t if self._t is None else max(self._t, t)
        self.turn_rate = max(RATE_FLOOR, self.turn_rate * math.exp(-dt / FADE_S))
        asked = asked_error_rad is not None and abs(asked_error_rad) >= ASKED_RAD
        if not asked:
            self._stuck_since = self._pivot_since = self._asked_since = None
            return
        self._asked_since = t if self._asked_since is None else self._asked_since
        u, r = abs(speed_water_mps), abs(turn_rate_radps)
        self.turn_rate = max(self.turn_rate, r)
        pivoting = way_known and u < STILL_MPS and r >= PIVOT_RATE
        stuck = u < SLOW_MPS and r < STUCK_RATE
        self._pivot_since = (t if self._pivot_since is None else self._pivot_since) if pivoting else None
        self._stuck_since = (t if self._stuck_since is None else self._stuck_since) if stuck else None
        if self._pivot_since is not None and t - self._pivot_since >= PIVOT_S:
            self.pivot_seen, self.needs_way = True, False
        if self._stuck_since is not None and t - self._stuck_since >= STUCK_S:
            self.needs_way = True
        settled = t - self._asked_since >= RADIUS_SETTLE_S
        if settled and FAST_MPS <= u <= MANOEUVRE_MAX_MPS and r > 1e-6 and u / r <= MAX_RADIUS_M:
            radius = u / r
            # the tightest circle seen (transients, the rudder still going over, the turn rate still growing, all
            # read wider than the boat can turn), relaxing slowly
            relaxed = None if self.radius_m is None else self.radius_m * (1.0 + dt / RADIUS_RELAX_S)
            if relaxed is None or radius < relaxed:
                self.radius_m, self.radius_speed_mps = radius, u
            else:
                self.radius_m = relaxed
