"""StoppingTime: how far this boat runs on when told to stop, learned from its own telemetry (pure, no I/O).

Told speed 0 (Rover's stop controller: it brakes down to ATC_STOP_SPEED, then the throttle goes off and the hull's
drag alone slows it, docs/simulator.md), a boat's way through the water dies away roughly as a first-order lag,
``du/dt = -u / tau``, so from speed ``u`` it runs on about ``u tau`` before it stops. ``tau`` depends on the hull
(its mass against its drag) and on how hard the autopilot can brake (the thrust astern). Stopped from 0.2 m/s in
open water (0.03 m/s currents from five sides) the simulator's rudder boat gives 0.8-1.2 s, one of twice the mass
with 45% less thrust astern 1.7-2.3 s; in missions they learn about 1.2-1.3 s and 2.2 s. (The coast after the
braking is slower, the hull's own m11 / |X_u|: 1.5 and 2.8 s; this fit is dominated by the braking, where the way
is.) Speed ramps that end a run at a point (law/approach_path.py, law/line_approach.py) ask no more speed than
``distance / tau``: on ramps made for the simulator's boats, one of twice the mass with a weak astern ran 0.2 m past
the goal.

``tau`` is fitted by least squares over windows of at least ``WINDOW_S`` while the boat is told to stop and moves
(``|u| >= MOVING_MPS``): the speed lost in a window against the way run in it, ``u0 - u1 = integral(u dt) / tau``
(over a window, not tick by tick: the tick-to-tick noise of a filtered speed would otherwise bias the fit). The
sums fade with ``RELAX_S`` (a boat that changed), and start from a prior of ``PRIOR_S`` worth ``PRIOR_WEIGHT`` (of
m^2), so a boat never seen to stop is taken to stop as the simulator's boats do.

Conventions: speeds through the water along the heading [m/s] (negative astern), vehicle seconds.
"""

from __future__ import annotations

import math

from koopguide.guidance.law.approach_path import STOP_GAIN

PRIOR_S = 1.0 / STOP_GAIN  # the stopping time assumed before any stop is seen: that the ramps are made for [s]
PRIOR_WEIGHT = 0.002  # ... worth this much evidence, a fifth of a window at 0.1 m/s [m^2]
WINDOW_S = 1.0  # a fit window lasts at least this long [s]
MAX_GAP_S = 0.5  # samples further apart than this break the window [s]
MOVING_MPS = 0.04  # a window starts only this fast through the water [m/s]
RELAX_S = 120.0  # the evidence fades with this time constant [s]
MIN_S, MAX_S = 0.5, 8.0  # the stopping time is kept within these [s]


class StoppingTime:
    """Fold in one sample per command with :meth:`update`; read :attr:`tau_s`."""

    def __init__(self) -> None:
        self._sxx = 0.0  # sum over windows of x^2, x = integral(u dt) the way run in the window [m^2]
        self._sxy = 0.0  # sum over windows of x (u0 - u1), the speed lost in it [m^2/s]
        self._window: tuple[float, float] | None = None  # (t0, u0) of the window under way
        self._run_m = 0.0  # the way run in it so far (trapezoids) [m]
        self._t: float | None = None  # vehicle time of the last sample [s]
        self._u = 0.0  # the last sample's speed [m/s]

    def update(self, t: float, stopping: bool, speed_water_mps: float) -> None:
        """One sample at vehicle time ``t``: ``stopping``, the boat has been told speed 0 (since at least its
        last sample); ``speed_water_mps``, its speed through the water along its heading."""
        if self._t is not None and t > self._t:
            fade = math.exp(-(t - self._t) / RELAX_S)
            self._sxx, self._sxy = self._sxx * fade, self._sxy * fade
        u, t_last, u_last = speed_water_mps, self._t, self._u
        broken = t_last is None or not 0.0 < t - t_last <= MAX_GAP_S
        self._t, self._u = t, u
        if not stopping or broken or self._window is None:
            self._window, self._run_m = ((t, u) if stopping and abs(u) >= MOVING_MPS else None), 0.0
            return
        self._run_m += 0.5 * (u_last + u) * (t - t_last)
        t0, u0 = self._window
        if t - t0 < WINDOW_S:
            return
        x = self._run_m  # the way run on in the window [m]
        self._sxx += x * x
        self._sxy += x * (u0 - u)
        self._window, self._run_m = ((t, u) if abs(u) >= MOVING_MPS else None), 0.0

    @property
    def tau_s(self) -> float:
        """The boat's stopping time [s]: from speed u it runs on about ``u * tau_s`` when told to stop."""
        rate = (PRIOR_WEIGHT / PRIOR_S + self._sxy) / (PRIOR_WEIGHT + self._sxx)
        return MAX_S if rate <= 1.0 / MAX_S else max(MIN_S, 1.0 / rate)
