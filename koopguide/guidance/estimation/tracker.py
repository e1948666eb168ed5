"""KalmanTracker: a constant-velocity Kalman filter of the vehicle in local NED.

Conventions: state ``x = [N, vN, E, vE]`` (m, m/s); fixes ``(N, E, vN, vE)`` from LOCAL_POSITION_NED;
time is the vehicle's own clock (its messages' ``time_boot_ms``, in seconds), so a simulator running at
a speed-up is filtered exactly as real time would be.

Model (filterpy's constant-velocity recipe; docs/guidance.md "The estimator"): F = blockdiag([[1, dt],
[0, 1]]) per axis, Q = white-acceleration noise (filterpy's Q_discrete_white_noise, block_size 2), H
picks all four measured values, R diagonal.
Robustness: a fix whose innovation has squared Mahalanobis distance above ``gate_chi2`` is rejected;
``reset_after_rejections`` rejections in a row (a real jump, e.g. an EKF reset) restart the filter at the
fix; so does a gap or a backwards step in vehicle time (a reboot).

Speed: the filter runs between a fix arriving and its setpoint going out, so it is computed in plain
floats, one axis at a time. That is exact, not an approximation: F, Q, H and R are block-diagonal per
axis (N with vN, E with vE), and so is P from its diagonal start, so the 4-state filter is two
independent 2-state filters (Simon (2006), "Optimal State Estimation", sec. 5.1 eqs. 5.17-5.19, with the
Joseph-form covariance update of eq. 5.19 as filterpy uses it). tests/guidance checks it against
filterpy's 4-state ``KalmanFilter``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from filterpy.common import Q_discrete_white_noise

from koopguide.guidance.settings import EstimatorSettings

MAX_CACHED_STEPS = 64  # distinct fix intervals whose Q is kept


@dataclass(frozen=True)
class FixResult:
    accepted: bool
    reset: bool
    mahalanobis2: float


class AxisFilter:
    """One axis of the tracker: position ``p`` [m], velocity ``v`` [m/s] and their covariance
    ``[[p00, p01], [p01, p11]]`` [m^2, m^2/s, m^2/s^2]; the measurement is (p, v) with variances
    ``r_p``, ``r_v``."""

    __slots__ = ("p", "p00", "p01", "p11", "r_p", "r_v", "v")

    def __init__(self, r_p: float, r_v: float) -> None:
        self.r_p, self.r_v = r_p, r_v
        self.reset(0.0, 0.0)

    def reset(self, p: float, v: float) -> None:
        """Restart at the measurement, with the measurement's own uncertainty."""
        self.p, self.v = p, v
        self.p00, self.p01, self.p11 = self.r_p, 0.0, self.r_v

    def predict(self, dt: float, q: tuple[float, float, float]) -> None:
        """x <- F x, P <- F P F' + Q over ``dt`` [s]; ``q`` = (q00, q01, q11) of Q."""
        p01, p11 = self.p01, self.p11
        self.p += dt * self.v
        self.p00 += dt * (2.0 * p01 + dt * p11) + q[0]
        self.p01 = p01 + dt * p11 + q[1]
        self.p11 = p11 + q[2]

    def innovation(self, z_p: float, z_v: float) -> tuple[float, float, float, float, float, float]:
        """(y_p, y_v, s00, s01, s11, d2): the innovation, S = P + R, and y' S^-1 y."""
        y_p, y_v = z_p - self.p, z_v - self.v
        s00, s01, s11 = self.p00 + self.r_p, self.p01, self.p11 + self.r_v
        det = s00 * s11 - s01 * s01
        return y_p, y_v, s00, s01, s11, (s11 * y_p * y_p - 2.0 * s01 * y_p * y_v + s00 * y_v * y_v) / det

    def update(self, y_p: float, y_v: float, s00: float, s01: float, s11: float) -> None:
        """K = P S^-1; x <- x + K y; P <- (I - K) P (I - K)' + K R K' (Joseph form)."""
        p00, p01, p11 = self.p00, self.p01, self.p11
        det = s00 * s11 - s01 * s01
        k00, k01 = (p00 * s11 - p01 * s01) / det, (p01 * s00 - p00 * s01) / det
        k10, k11 = (p01 * s11 - p11 * s01) / det, (p11 * s00 - p01 * s01) / det
        self.p += k00 * y_p + k01 * y_v
        self.v += k10 * y_p + k11 * y_v
        a00, a01, a10, a11 = 1.0 - k00, -k01, -k10, 1.0 - k11
        m00, m01 = a00 * p00 + a01 * p01, a00 * p01 + a01 * p11  # A P
        m10, m11 = a10 * p00 + a11 * p01, a10 * p01 + a11 * p11
        r_p, r_v = self.r_p, self.r_v
        self.p00 = m00 * a00 + m01 * a01 + k00 * k00 * r_p + k01 * k01 * r_v
        self.p01 = m00 * a10 + m01 * a11 + k00 * k10 * r_p + k01 * k11 * r_v
        self.p11 = m10 * a10 + m11 * a11 + k10 * k10 * r_p + k11 * k11 * r_v


class KalmanTracker:
    """Filters fixes stamped in vehicle time; predicts the position at any later vehicle time."""

    def __init__(self, settings: EstimatorSettings) -> None:
        self.settings = settings
        r_p, r_v = settings.position_std_m**2, settings.velocity_std_mps**2
        self.north, self.east = AxisFilter(r_p, r_v), AxisFilter(r_p, r_v)
        self.t: float | None = None  # vehicle time of the state [s]
        self.rejections = 0
        self.resets = 0
        self._q: dict[float, tuple[float, float, float]] = {}

    @property
    def initialised(self) -> bool:
        return self.t is not None

    @property
    def x(self) -> np.ndarray:
        """The state [N, vN, E, vE] (m, m/s)."""
        return np.array([self.north.p, self.north.v, self.east.p, self.east.v])

    @property
    def P(self) -> np.ndarray:
        """The state's covariance (4 x 4, block-diagonal per axis)."""
        P = np.zeros((4, 4))
        for i, axis in ((0, self.north), (2, self.east)):
            P[i : i + 2, i : i + 2] = [[axis.p00, axis.p01], [axis.p01, axis.p11]]
        return P

    def position_std_m(self) -> float:
        """The position estimate's spread: the larger axis's standard deviation [m] (0 before the first fix)."""
        return math.sqrt(max(self.north.p00, self.east.p00, 0.0)) if self.t is not None else 0.0

    def reset(self, t: float, fix: np.ndarray | tuple[float, ...]) -> None:
        """Restart at ``fix`` = (N, E, vN, vE) at vehicle time ``t``."""
        n, e, vn, ve = (float(value) for value in fix)
        self.north.reset(n, vn)
        self.east.reset(e, ve)
        self.t = t
        self.rejections = 0
        self.resets += 1

    def update(self, t: float, fix: np.ndarray | tuple[float, ...]) -> FixResult:
        """Fold in ``fix`` = (N, E, vN, vE) [m, m/s] taken at vehicle time ``t`` [s]."""
        n, e, vn, ve = (float(value) for value in fix)
        if not (math.isfinite(n) and math.isfinite(e) and math.isfinite(vn) and math.isfinite(ve)):
            raise ValueError(f"non-finite position fix {[n, e, vn, ve]}")
        if self.t is None or t < self.t or t - self.t > self.settings.max_dt_s:
            self.reset(t, (n, e, vn, ve))
            return FixResult(accepted=True, reset=True, mahalanobis2=0.0)
        self._predict_to(t)
        north, east = self.north.innovation(n, vn), self.east.innovation(e, ve)
        d2 = north[5] + east[5]
        if d2 > self.settings.gate_chi2:
            self.rejections += 1
            if self.rejections >= self.settings.reset_after_rejections:
                self.reset(t, (n, e, vn, ve))
                return FixResult(accepted=True, reset=True, mahalanobis2=d2)
            return FixResult(accepted=False, reset=False, mahalanobis2=d2)
        self.rejections = 0
        self.north.update(*north[:5])
        self.east.update(*east[:5])
        return FixResult(accepted=True, reset=False, mahalanobis2=d2)

    def _predict_to(self, t: float) -> None:
        dt = t - self.t
        if dt > 0:
            q = self._noise(round(dt, 6))
            self.north.predict(dt, q)
            self.east.predict(dt, q)
            self.t = t

    def _noise(self, dt: float) -> tuple[float, float, float]:
        """Q's per-axis (q00, q01, q11) for a step of ``dt`` s, cached: fixes come at a few fixed intervals."""
        cached = self._q.get(dt)
        if cached is None:
            if len(self._q) > MAX_CACHED_STEPS:
                self._q.clear()
            Q = Q_discrete_white_noise(dim=2, dt=dt, var=self.settings.accel_std_mps2**2, block_size=2)
            cached = self._q[dt] = (float(Q[0, 0]), float(Q[0, 1]), float(Q[1, 1]))
        return cached

    def predict(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Position (N, E) and velocity (vN, vE) extrapolated to vehicle time ``t`` (state unchanged)."""
        n, e, vn, ve = self.predict_floats(t)
        return np.array((n, e)), np.array((vn, ve))

    def predict_floats(self, t: float) -> tuple[float, float, float, float]:
        """(N, E, vN, vE) [m, m/s] extrapolated to vehicle time ``t``, as floats (the hot path's form)."""
        if self.t is None:
            raise RuntimeError("the tracker has no fix yet")
        dt = max(0.0, t - self.t)
        north, east = self.north, self.east
        return north.p + dt * north.v, east.p + dt * east.v, north.v, east.v
