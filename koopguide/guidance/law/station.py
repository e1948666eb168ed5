"""Station keeping and direct pursuit: proportional-integral position feedback with anti-windup (pure math).

The wanted ground velocity toward the goal is

    v = kp e + ki integral(e_x dt),   e = goal - p,   e_x = e (1 - d0 / |e|)+   (NED [m]; v [m/s])

(a PI controller on a vehicle that is, to first order, an integrator of its velocity setpoint:
s^2 + kp s + ki = 0, damping kp / (2 sqrt(ki)); Astrom & Murray (2021), "Feedback Systems",
2nd ed., ch. 11 "PID Control").
The integral term is what holds a boat whose response differs from the model the feed-forward current
compensation assumes (a boat whose speed through the water, not over ground, follows the setpoint, drifts
by the current under P alone; the integral grows until it cancels the drift). Anti-windup (same
chapter, "integrator windup"): the integral term is clamped to ``integral_limit_mps``, and it does not integrate
while the output saturates at ``max_speed_mps`` in the direction of the error (conditional integration).
Only the error beyond the dead band ``d0`` (the arrival radius) is integrated, and the integral is kept
across drift-offs (a bias of the boat or the current); inside the dead band it leaks away slowly
(``LEAK_S``), so that a transient (a gust, a stale position) leaves no lasting push: where the model-based
feed-forward already holds the boat inside the arrival radius, the integral stays out of its way.

Conventions: positions ``(2,)`` local NED [m], velocities ``(2,)`` NED [m/s], times in vehicle seconds.
"""

from __future__ import annotations

import math

import numpy as np

from koopguide.guidance.settings import GuidanceConfig

MAX_STEP_S = 0.5  # a longer gap between updates integrates only this long (a stale or restarted estimate)
LEAK_S = 30.0  # inside the dead band the integral decays with this time constant [s]


class StationKeeper:
    """PI feedback toward a goal; :meth:`update` gives the wanted ground velocity [m/s]."""

    def __init__(
        self,
        kp_per_s: float,
        ki_per_s2: float,
        integral_limit_mps: float,
        max_speed_mps: float,
        deadband_m: float = 0.0,
    ) -> None:
        self.kp = kp_per_s
        self.deadband = deadband_m
        self.ki = ki_per_s2
        self.integral_limit = integral_limit_mps
        self.max_speed = max_speed_mps
        self.integral = np.zeros(2)  # ki * integral(e dt) [m/s]
        self.t: float | None = None  # vehicle time of the last update [s]

    @classmethod
    def from_config(cls, cfg: GuidanceConfig) -> StationKeeper:
        """The station keeper of ``cfg.arrival`` (gains, anti-windup), capped at ``command.max_speed_mps``."""
        a = cfg.arrival
        return cls(a.station_gain, a.integral_gain_per_s2, a.integral_limit_mps, cfg.command.max_speed_mps, a.radius_m)

    def reset(self) -> None:
        """Forget the integral (a new approach, a restarted estimate, a teleport)."""
        self.integral = np.zeros(2)
        self.t = None

    def update(
        self, t: float, error_ned: np.ndarray, proportional_ned: np.ndarray | None = None, integrate: bool = True
    ) -> np.ndarray:
        """The wanted ground velocity at vehicle time ``t`` for position error ``error_ned`` = goal - p;
        ``proportional_ned`` replaces the term kp e (e.g. one capped by a model of the boat) [m/s].
        ``integrate=False`` adds the integral as it is without growing it: direct pursuit from afar, where the
        error is the way still to go, not a bias (integrated, it wound up to the limit in 3 s at 0.5 m and the
        boat overshot its goal by 0.2 m on arrival, then sat there while P and the wound-up I cancelled)."""
        e = np.asarray(error_ned, dtype=float)
        if not np.all(np.isfinite(e)):
            self.reset()
            return np.zeros(2)
        dt = 0.0 if self.t is None or t <= self.t else min(t - self.t, MAX_STEP_S)
        if self.t is None or t > self.t:
            self.t = t
        proportional = self.kp * e if proportional_ned is None else np.asarray(proportional_ned, dtype=float)
        out = proportional + self.integral
        saturated = float(np.hypot(*out)) >= self.max_speed
        if integrate and dt > 0.0 and not (saturated and float(e @ out) > 0.0):  # conditional integration
            norm_e = float(np.hypot(*e))
            if norm_e <= self.deadband:
                integral = self.integral * math.exp(-dt / LEAK_S)
            else:
                integral = self.integral + self.ki * e * (1.0 - self.deadband / norm_e) * dt
            norm = float(np.hypot(*integral))
            self.integral = integral * (self.integral_limit / norm) if norm > self.integral_limit else integral
            out = proportional + self.integral
        speed = float(np.hypot(*out))
        return out * (self.max_speed / speed) if speed > self.max_speed else out
