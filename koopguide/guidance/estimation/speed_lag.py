"""SpeedLag: how quickly this boat's way through the water follows what it is asked, learned from its own
telemetry (pure, no I/O).

Asked a speed through the water ``target`` (a heading and a speed over ground along it, less the current's component
along the heading: Rover holds the speed over ground), a boat's way approaches it roughly as a first-order lag,
``du/dt = (target - u) / T``. One ``SpeedLag`` is fitted per kind of request:

- **stopping** (``target`` 0: Rover's stop controller brakes down to ATC_STOP_SPEED, then the throttle goes off and
  the hull's drag alone slows it, docs/simulator.md): from speed ``u`` a boat runs on about ``u T`` before it stops.
  ``T`` depends on the hull (its mass against its drag) and on how hard the autopilot can brake (the thrust astern).
  Stopped from 0.2 m/s in open water (0.03 m/s currents from five sides) the simulator's rudder boat gives 0.8-1.2 s,
  one of twice the mass with 45% less thrust astern 1.7-2.3 s; in missions they learn about 1.2-1.3 s and 2.2 s.
  (The coast after the braking is slower, the hull's own m11 / |X_u|: 1.5 and 2.8 s; this fit is dominated by the
  braking, where the way is.) Speed ramps that end a run at a point (law/approach_path.py, law/line_approach.py)
  ask no more speed than ``distance / T``: on ramps made for the simulator's boats, one of twice the mass with a
  weak astern ran 0.2 m past the goal.
- **astern** and **ahead** (the capture search's manoeuvres and its model boat, law/capture.py): a hull whose thrust
  astern barely overcomes its drag at the speed asked gathers sternway several times slower than the simulator's
  (one of twice the mass with 45% less thrust astern: 0.066 m/s of 0.12 asked after 2 s); the search's model, which
  took every boat to follow within 1 s, then chose astern manoeuvres that did not happen, and the boat drifted
  beside its line for 40 s. Learned (2-3 s astern for that hull, at most 1.3 s for the simulator's), its Zshape demo
  missions met issue 10's bounds 57 of 84 times against 35 of 56 without: within the flights' spread (stop 41).

Whether the boat goes astern at all is learned apart (:class:`SternwayTrial`): a single thruster on a motor that
does not reverse (Rover clips the negative throttle to nothing) never gathers sternway, and every manoeuvre planned
with a leg astern then stalls where that leg begins (a kinematic rudder boat without sternway, Zshape demo starts in
cross currents: its planned approach asked 0.28 m/s astern for 50 s while the current carried it 1 m off, and it met
issue 10's bounds 12 of 28 times, stop 48).

``T`` is fitted by least squares over windows of at least ``WINDOW_S`` while the same kind of request stands and the
boat is ``MOVING_MPS`` or more from its target: the speed gained in a window against the shortfall integrated over
it, ``u1 - u0 = integral((target - u) dt) / T`` (over a window, not tick by tick: the tick-to-tick noise of a
filtered speed would otherwise bias the fit). The sums fade with ``RELAX_S`` (a boat that changed), and start from
a prior worth ``PRIOR_WEIGHT`` (of (m/s s)^2), so a boat never seen is taken to respond as the simulator's boats do.

Nor does every autopilot let the boat drift at speed 0 (:class:`RestHold`): Rover's stop controller puts the throttle
off once the boat is slower than ATC_STOP_SPEED, and the current carries it; an autopilot whose speed loop over ground
keeps running at 0 holds the boat's ground along its heading instead (the kinematic rudder boat of
tests/support/kinematic_rudder.py). A search that took every boat to drift at 0 sent one that held its ground speed 0
for 20 s, its model drifting the boat down onto its line while the boat crept across the goal 49 deg off it and
missed its hold (stop 49).

Conventions: speeds through the water along the heading [m/s] (negative astern), vehicle seconds.
"""

from __future__ import annotations

import math

PRIOR_WEIGHT = 0.002  # the prior is worth this much evidence, a fifth of a window 0.1 m/s short [m^2]
WINDOW_S = 1.0  # a fit window lasts at least this long [s]
MAX_GAP_S = 0.5  # samples further apart than this break the window [s]
MOVING_MPS = 0.04  # a window starts only this far from the target speed [m/s]
RELAX_S = 120.0  # the evidence fades with this time constant [s]
MIN_S, MAX_S = 0.5, 8.0  # the lag is kept within these [s]
WAY_TARGET_MAX_MPS = 0.16  # the lags ahead and astern are learned from requests up to this fast through the water,
# the capture search's (near a hull's top speed the way gathers ever slower: the heavy hull, asked 0.25 m/s astern by
# a planned approach, fitted 5-8 s where at the search's 0.12 m/s it takes 2-3 s) [m/s]
TRIAL_MPS = 0.05  # an astern request this fast through the water or faster is a trial of the boat's sternway [m/s]
TRIAL_STILL_MPS = 0.01  # ... counted from when the way ahead is gone (a heavy hull with a weak astern, asked
# astern at 0.19 m/s ahead, still had way ahead 2.5 s later, and was taken for one that goes ahead only) [m/s]
TRIAL_SETTLE_S = 1.0  # ... from this long after that (the sternway takes that long to gather) [s]
TRIAL_S = 2.0  # ... and judged once this much of it has been seen [s]
TRIAL_HEADING_RAD = math.radians(30.0)  # ... asked within this of the boat's heading (below a pivot's)
STERNWAY_MPS = 0.025  # the boat goes astern when its mean sternway over the trial is at least this [m/s] (the
# simulator's hull of twice the mass with 45% less thrust astern: 0.066 m/s 2 s into a 0.12 m/s request) ...
STERNWAY_FRACTION = 0.25  # ... or this fraction of the mean sternway asked, if less: that hull gathers about half of
# what it is asked over a trial (0.026 m/s asked 0.05, 0.062 m/s asked 0.12), and asked about 0.055 m/s astern by the
# station keeper the skid-steer one was once taken for a boat that goes ahead only (stop 49's CI)
REST_SETTLE_LAGS = 3.0  # a speed-0 request is watched from this many stopping lags after it began (the way it had
# is gone by then: 5% of it) ...
REST_CURRENT_MPS = 0.015  # ... while the current along the heading is at least this, against the bow or from astern
# (holding the ground needs way against it, astern when it comes from astern: a kinematic rudder boat held bow
# downstream 0.35 m upstream of the goal at speed 0 sat there for 20 s, the hold waiting on a drift, stop 58) [m/s]
REST_S = 3.0  # ... and judged each time this much of it has been seen [s]
REST_CARRY_FRACTION = 0.25  # carried back along its heading by less than this fraction of the current's component
# along it, the boat holds its ground at rest (Rover's stop controller, stopped from 0.06-0.25 m/s in 0.03 m/s
# against the bow or 30 deg off it: the simulator's rudder boat carried 0.63-1.0 of it in the first verdict, the
# heavy hull with a weak astern 0.49-0.88, then 0.83-1.0; a boat that holds its ground, about 0)
WAY_ERROR_MPS = 0.05  # the way a boat had when speed 0 was sent is known within this (in sheared water the current
# along its heading, which the way is reckoned against, was 0.06-0.13 m/s off in the double gyre, stop 54) [m/s]


def follows(t_last: float | None, t: float) -> bool:
    """Whether a sample at ``t`` [s] continues the one at ``t_last`` (None: none yet): later, by ``MAX_GAP_S`` at
    most."""
    return t_last is not None and 0.0 < t - t_last <= MAX_GAP_S


class SpeedLag:
    """Fold in one sample per command with :meth:`update`; read :attr:`lag_s`."""

    def __init__(self, prior_s: float) -> None:
        self.prior_s = prior_s  # the lag taken before any evidence [s]
        self._sxx = 0.0  # sum over windows of x^2, x = integral((target - u) dt) the shortfall [m^2]
        self._sxy = 0.0  # sum over windows of x (u1 - u0), the speed gained [m^2/s]
        self._window: tuple[float, float] | None = None  # (t0, u0) of the window under way
        self._short_m = 0.0  # the shortfall integrated in it so far (trapezoids) [m]
        self._t: float | None = None  # vehicle time of the last sample [s]
        self._gap = 0.0  # the last sample's shortfall, target - u [m/s]

    def update(self, t: float, target_mps: float | None, speed_water_mps: float) -> None:
        """One sample at vehicle time ``t``: ``target_mps``, the speed through the water the boat has been asked
        (since at least its last sample; None: a request of another kind, no evidence); ``speed_water_mps``, its
        speed through the water along its heading."""
        if self._t is not None and t > self._t:
            fade = math.exp(-(t - self._t) / RELAX_S)
            self._sxx, self._sxy = self._sxx * fade, self._sxy * fade
        u, t_last, gap_last = speed_water_mps, self._t, self._gap
        broken = not follows(t_last, t)
        gap = 0.0 if target_mps is None else target_mps - u
        self._t, self._gap = t, gap
        starts = target_mps is not None and abs(gap) >= MOVING_MPS
        if target_mps is None or broken or self._window is None:
            self._window, self._short_m = ((t, u) if starts else None), 0.0
            return
        self._short_m += 0.5 * (gap_last + gap) * (t - t_last)
        t0, u0 = self._window
        if t - t0 < WINDOW_S:
            return
        x = self._short_m
        self._sxx += x * x
        self._sxy += x * (u - u0)
        self._window, self._short_m = ((t, u) if starts else None), 0.0

    @property
    def lag_s(self) -> float:
        """The boat's time constant [s] for this kind of request (stopping: from speed u it runs on ``u * lag_s``)."""
        rate = (PRIOR_WEIGHT / self.prior_s + self._sxy) / (PRIOR_WEIGHT + self._sxx)
        return MAX_S if rate <= 1.0 / MAX_S else max(MIN_S, 1.0 / rate)


class SternwayTrial:
    """Whether the boat goes astern: taken to until a trial shows otherwise. A trial is ``TRIAL_S`` of astern
    requests (``TRIAL_MPS`` or faster through the water), each counted from ``TRIAL_SETTLE_S`` after its way ahead
    was gone (``TRIAL_STILL_MPS``); the boat goes astern if its mean sternway over them reached ``STERNWAY_MPS``, or
    ``STERNWAY_FRACTION`` of the mean sternway asked if that is less.
    Judged once (per :class:`BoatLags`)."""

    def __init__(self) -> None:
        self.goes_astern: bool | None = None  # the verdict (None: not yet judged; the boat is taken to)
        self._since: float | None = None  # vehicle time the request astern under way found the way ahead gone [s]
        self._t: float | None = None  # the last sample's time [s]
        self._seen_s = 0.0  # trial time seen [s]
        self._sternway_m = 0.0  # sternway integrated over it [m]
        self._asked_m = 0.0  # sternway asked, integrated over it [m]

    @property
    def able(self) -> bool:
        """The boat goes astern, or has not been shown not to."""
        return self.goes_astern is not False

    def update(self, t: float, target_mps: float | None, speed_water_mps: float) -> None:
        """One sample at vehicle time ``t``: the speed through the water asked (None: no evidence) and the way."""
        if self.goes_astern is not None:  # judged once
            return
        t_last, self._t = self._t, t
        trying = target_mps is not None and target_mps <= -TRIAL_MPS
        if not trying or not follows(t_last, t):
            self._since = None
            return
        if self._since is None:
            if speed_water_mps > TRIAL_STILL_MPS:
                return  # still carrying way ahead: the trial begins once that has gone
            self._since = t
        if t - self._since < TRIAL_SETTLE_S:
            return
        self._seen_s += t - t_last
        self._sternway_m += -speed_water_mps * (t - t_last)
        self._asked_m += -target_mps * (t - t_last)
        if self._seen_s >= TRIAL_S:
            self.goes_astern = bool(
                self._sternway_m >= min(STERNWAY_MPS * self._seen_s, STERNWAY_FRACTION * self._asked_m)
            )


class RestHold:
    """Whether speed 0 holds the boat's ground along its heading (:attr:`holds`) instead of letting the current carry
    it: taken not to until shown. Speed-0 requests are watched from ``REST_SETTLE_LAGS`` stopping lags after each
    began, while the current along the heading is at least ``REST_CURRENT_MPS`` either way; each ``REST_S`` of that is
    a verdict: the boat holds its ground if it was carried downstream along its heading by less than
    ``REST_CARRY_FRACTION`` of the current's component along it (then kept for good; else watched again). A boat that
    goes ahead only is carried by a current from astern, and is never taken to hold its ground by it. Not watched in
    sheared water, where the estimate is no guide to the current at the boat (:meth:`BoatLags.update`)."""

    def __init__(self) -> None:
        self.holds = False
        self._since: float | None = None  # vehicle time the speed-0 request under way began [s]
        self._t: float | None = None  # the last sample's time [s]
        self._seen_s = 0.0  # watched time [s]
        self._carried_m = 0.0  # ground lost along the heading over it (downstream) [m]
        self._current_m = 0.0  # the current along the heading, either way, integrated over it [m]

    def update(self, t: float, stop: bool, current_along_mps: float, ground_along_mps: float, settle_s: float) -> None:
        """One sample at vehicle time ``t``: whether speed 0 stands (``stop``), the current's component along the
        heading and the ground velocity's [m/s], and how long after the request began the way it had is gone."""
        if self.holds:
            return
        t_last, self._t = self._t, t
        if not stop or not follows(t_last, t):
            self._since = None
            return
        if self._since is None:
            self._since = t
        if t - self._since < settle_s or abs(current_along_mps) < REST_CURRENT_MPS:
            return
        dt = t - t_last
        downstream = math.copysign(1.0, current_along_mps)  # along the heading: -1 against the bow, +1 from astern
        self._seen_s += dt
        self._carried_m += downstream * ground_along_mps * dt
        self._current_m += abs(current_along_mps) * dt
        if self._seen_s >= REST_S:
            self.holds = self._carried_m < REST_CARRY_FRACTION * self._current_m
            self._seen_s = self._carried_m = self._current_m = 0.0


class BoatLags:
    """One boat's three lags: :attr:`stopping` (speed 0 sent), :attr:`ahead` and :attr:`astern`; whether it goes
    astern at all (:attr:`sternway`); and whether speed 0 holds its ground (:attr:`rest`)."""

    def __init__(self, stop_prior_s: float, way_prior_s: float) -> None:
        self.stopping = SpeedLag(stop_prior_s)
        self.ahead, self.astern = SpeedLag(way_prior_s), SpeedLag(way_prior_s)
        self.sternway = SternwayTrial()
        self.rest = RestHold()
        self._stop_since: float | None = None  # vehicle time speed 0 began to stand, unbroken (None: it does not) [s]
        self._stop_way = 0.0  # the way through the water the boat had then [m/s]
        self._t: float | None = None  # the last sample's time [s]

    @property
    def way_left_mps(self) -> float | None:
        """While speed 0 stands and is not known to hold the boat's ground (:class:`RestHold`: Rover's stop controller
        puts the throttle off and the boat drifts with the water): a bound on the way it has left [m/s], the way it
        had when speed 0 was sent (known within ``WAY_ERROR_MPS``) dying away over the stopping lag; None otherwise."""
        if self._stop_since is None or self._t is None or self.rest.holds:
            return None
        return (abs(self._stop_way) + WAY_ERROR_MPS) * math.exp(-(self._t - self._stop_since) / self.stopping.lag_s)

    def update(
        self,
        t: float,
        asked_mps: float | None,
        current_along_mps: float,
        speed_water_mps: float,
        heading_error_rad: float | None = None,
        current_trusted: bool = True,
    ) -> None:
        """One sample at vehicle time ``t`` of the way ``speed_water_mps`` [m/s] under the request that stands:
        ``asked_mps``, the speed over ground along the heading last sent (negative: astern; exactly 0: Rover's stop
        controller, throttle off, toward 0 through the water; None: no evidence, such as at a wall, which stops a
        boat too), less ``current_along_mps``, the current's component along the heading, through the water;
        ``heading_error_rad``: how far the heading asked lies off the boat's, beyond ``TRIAL_HEADING_RAD`` no
        sternway trial (a skid-steer boat pivots first, Rover's WP_PIVOT_ANGLE; None: a boat that does not pivot,
        such as a rudder boat, which goes astern, or not, whatever its heading); ``current_trusted``: the current
        estimate is a guide to the water at the boat (not in sheared water, where the boat at rest may be carried by
        less than the estimate says: then no evidence of speed 0 holding its ground, :class:`RestHold`)."""
        stop = asked_mps is not None and abs(asked_mps) <= 1e-9
        if not (stop and self._stop_since is not None and follows(self._t, t)):  # speed 0 begins (or none stands)
            self._stop_since, self._stop_way = (t if stop else None), speed_water_mps
        self._t = t
        target = None if asked_mps is None or stop else asked_mps - current_along_mps
        steady = heading_error_rad is None or abs(heading_error_rad) <= TRIAL_HEADING_RAD
        self.sternway.update(t, target if steady else None, speed_water_mps)  # astern, however fast
        target = None if target is None or abs(target) > WAY_TARGET_MAX_MPS else target
        self.stopping.update(t, 0.0 if stop else None, speed_water_mps)
        settle = REST_SETTLE_LAGS * self.stopping.lag_s
        self.rest.update(t, stop and current_trusted, current_along_mps, speed_water_mps + current_along_mps, settle)
        self.ahead.update(t, target if target is not None and target > 0.0 else None, speed_water_mps)
        self.astern.update(t, target if target is not None and target < 0.0 else None, speed_water_mps)
