"""CurrentEstimator: the water current at the boat in local NED, from how the boat slips sideways (filterpy).

A displacement boat moves through the water along its heading (its sway through the water is small), so
the component of its ground velocity across its heading is the current's component across it:

    v_ground . n(psi) = c . n(psi),   n(psi) = (-sin psi, cos psi)   (NED; psi = heading from north)

One heading shows one component of the current; as the heading changes along a route both become
observable. The component along the heading cannot be told from the boat's own speed through the water,
and does not need to be: the autopilot holds the speed over ground along the heading (see
:func:`koopguide.guidance.law.command.crab`).

Model: state ``c = (c_N, c_E)`` [m/s], a random walk in time and in space: over ``dt`` seconds in which the
boat covers ``|v_ground| dt`` metres the covariance grows by ``(walk^2 dt + shear^2 |v_ground| dt) I``
(``current_walk_mps_per_sqrt_s``, ``current_shear_mps_per_sqrt_m``). With time alone, the component along a
long straight leg (never observed on it) keeps the value seen a metre or two back: in a vortex, 0.04-0.05 m/s
off at the goal. Growing with the distance covered, that component's spread lets the next headings' slip
correct it (shear 0.04: the error at the goal in a vortex 0.015-0.024 m/s RMS against 0.020-0.051 m/s), but
the spread a moving boat then carries keeps a rudder boat off the current's line in a uniform current (its
hold needs the estimate clear of twice its spread; docs/guidance.md, "Where it fails"), so the default is 0.
Prior ``c = 0`` with ``current_prior_std_mps``; measurement ``z = v_ground . n(psi)`` with ``H = n(psi)^T``
and the fix's velocity noise. Measurements while the boat turns faster than ``current_max_turn_dps`` are
skipped: in a turn the hull does slip sideways through the water, which would read as current. A boat that is
not propelled (disarmed) drifts with the water: then its whole ground velocity measures the current (H = I).

Conventions: velocities NED [m/s], headings [rad] from north, time in vehicle seconds.
"""

from __future__ import annotations

import math

import numpy as np
from filterpy.kalman import KalmanFilter

from koopguide.guidance.settings import EstimatorSettings


class CurrentEstimator:
    """Filters sideways-slip measurements into an estimate of the current (N, E) [m/s]."""

    def __init__(self, settings: EstimatorSettings) -> None:
        self.settings = settings
        self.kf = KalmanFilter(dim_x=2, dim_z=1)
        self.kf.F = np.eye(2)
        self.kf.R = np.array([[settings.velocity_std_mps**2]])
        self.kf.P = np.eye(2) * settings.current_prior_std_mps**2
        self.kf.x = np.zeros(2)
        self.t: float | None = None  # vehicle time of the last measurement [s]
        self.updates = 0

    @property
    def current_ned(self) -> np.ndarray:
        """The estimate (c_N, c_E) [m/s]."""
        return self.kf.x.copy()

    @property
    def std_mps(self) -> float:
        """The estimate's larger standard deviation [m/s] (the prior's until both components are seen)."""
        return float(math.sqrt(max(np.linalg.eigvalsh(self.kf.P))))

    def update(
        self, t: float, v_ground: np.ndarray, heading_rad: float, turn_rate_radps: float, drifting: bool = False
    ) -> bool:
        """Fold in the ground velocity (N, E) [m/s] seen at vehicle time ``t`` [s] with the boat's heading
        and turn rate; False when the measurement was skipped (turning fast, or not finite). ``drifting``: the
        boat is not propelled (disarmed), so its whole ground velocity is the current's."""
        v_ground = np.asarray(v_ground, dtype=float)
        if not (np.all(np.isfinite(v_ground)) and math.isfinite(heading_rad) and math.isfinite(turn_rate_radps)):
            return False
        if self.t is not None and t > self.t:  # random walk over the time since the last measurement and the way
            dt = min(t - self.t, self.settings.max_dt_s)
            metres = float(np.hypot(*v_ground)) * dt
            s = self.settings
            q = s.current_walk_mps_per_sqrt_s**2 * dt + s.current_shear_mps_per_sqrt_m**2 * metres
            self.kf.P = self.kf.P + np.eye(2) * q
        if self.t is None or t > self.t:
            self.t = t
        if abs(turn_rate_radps) > math.radians(self.settings.current_max_turn_dps):
            return False
        if drifting:  # both components at once
            self.kf.update(v_ground.copy(), R=np.eye(2) * self.settings.velocity_std_mps**2, H=np.eye(2))
        else:
            n = np.array([[-math.sin(heading_rad), math.cos(heading_rad)]])  # across the heading (starboard)
            self.kf.update(np.array([float(n[0] @ v_ground)]), H=n)
        self.updates += 1
        return True
