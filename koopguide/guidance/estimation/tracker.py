"""KalmanTracker: a constant-velocity Kalman filter of the vehicle in local NED (filterpy).

Conventions: state ``x = [N, vN, E, vE]`` (m, m/s); fixes ``(N, E, vN, vE)`` from LOCAL_POSITION_NED;
time is the vehicle's own clock (its messages' ``time_boot_ms``, in seconds), so a simulator running at
a speed-up is filtered exactly as real time would be.

Model (filterpy's constant-velocity recipe; docs/guidance.md "The estimator"): F = blockdiag([[1, dt],
[0, 1]]) per axis, Q = white-acceleration noise (Q_discrete_white_noise, block_size 2), H picks all four
measured values.
Robustness: a fix whose innovation has squared Mahalanobis distance above ``gate_chi2`` is rejected;
``reset_after_rejections`` rejections in a row (a real jump, e.g. an EKF reset) restart the filter at the
fix; so does a gap or a backwards step in vehicle time (a reboot).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter

from koopguide.guidance.settings import EstimatorSettings

# Measurement [N, E, vN, vE] from state [N, vN, E, vE].
H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])


@dataclass(frozen=True)
class FixResult:
    accepted: bool
    reset: bool
    mahalanobis2: float


class KalmanTracker:
    """Filters fixes stamped in vehicle time; predicts the position at any later vehicle time."""

    def __init__(self, settings: EstimatorSettings) -> None:
        self.settings = settings
        self.kf = KalmanFilter(dim_x=4, dim_z=4)
        self.kf.H = H.copy()
        s = settings
        self.kf.R = np.diag([s.position_std_m**2, s.position_std_m**2, s.velocity_std_mps**2, s.velocity_std_mps**2])
        self.t: float | None = None  # vehicle time of the state [s]
        self.rejections = 0
        self.resets = 0
        self._models: dict[float, tuple[np.ndarray, np.ndarray]] = {}

    @property
    def initialised(self) -> bool:
        return self.t is not None

    def reset(self, t: float, fix: np.ndarray) -> None:
        """Restart at ``fix`` = (N, E, vN, vE) at vehicle time ``t``."""
        n, e, vn, ve = fix
        self.kf.x = np.array([n, vn, e, ve], dtype=float)
        self.kf.P = self.kf.R[[0, 2, 1, 3]][:, [0, 2, 1, 3]].copy()  # the measurement's own uncertainty
        self.t = t
        self.rejections = 0
        self.resets += 1

    def update(self, t: float, fix: np.ndarray) -> FixResult:
        """Fold in ``fix`` = (N, E, vN, vE) [m, m/s] taken at vehicle time ``t`` [s]."""
        fix = np.asarray(fix, dtype=float)
        if not np.all(np.isfinite(fix)):
            raise ValueError(f"non-finite position fix {fix.tolist()}")
        if self.t is None or t < self.t or t - self.t > self.settings.max_dt_s:
            self.reset(t, fix)
            return FixResult(accepted=True, reset=True, mahalanobis2=0.0)
        self._predict_to(t)
        y = fix - H @ self.kf.x
        S = H @ self.kf.P @ H.T + self.kf.R
        d2 = float(y @ np.linalg.solve(S, y))
        if d2 > self.settings.gate_chi2:
            self.rejections += 1
            if self.rejections >= self.settings.reset_after_rejections:
                self.reset(t, fix)
                return FixResult(accepted=True, reset=True, mahalanobis2=d2)
            return FixResult(accepted=False, reset=False, mahalanobis2=d2)
        self.rejections = 0
        self.kf.update(fix)
        return FixResult(accepted=True, reset=False, mahalanobis2=d2)

    def _predict_to(self, t: float) -> None:
        dt = t - self.t
        if dt > 0:
            self.kf.F, self.kf.Q = self._model(round(dt, 6))
            self.kf.predict()
            self.t = t

    def _model(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """F and Q for a step of ``dt`` s, cached: fixes come at a few fixed intervals."""
        cached = self._models.get(dt)
        if cached is None:
            if len(self._models) > 64:
                self._models.clear()
            Q = Q_discrete_white_noise(dim=2, dt=dt, var=self.settings.accel_std_mps2**2, block_size=2)
            cached = self._models[dt] = (transition(dt), Q)
        return cached

    def predict(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Position (N, E) and velocity (vN, vE) extrapolated to vehicle time ``t`` (state unchanged)."""
        if self.t is None:
            raise RuntimeError("the tracker has no fix yet")
        x = transition(max(0.0, t - self.t)) @ self.kf.x
        return np.array([x[0], x[2]]), np.array([x[1], x[3]])


def transition(dt: float) -> np.ndarray:
    """Constant-velocity transition for state [N, vN, E, vE] over ``dt`` seconds."""
    F = np.eye(4)
    F[0, 1] = F[2, 3] = dt
    return F
