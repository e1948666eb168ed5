"""The position tracker's per-axis float filter is filterpy's 4-state constant-velocity filter, exactly.

The tracker runs between a fix and its setpoint, so it computes the filter in plain floats one axis at a
time (koopguide/guidance/estimation/tracker.py). Here filterpy's ``KalmanFilter`` with the 4 x 4 F, Q, H
and R of the recipe is the reference: states, covariances and the gate's Mahalanobis distance agree to
rounding over random fix sequences (intervals, noise, outliers). Conventions: state [N, vN, E, vE] (m, m/s).
"""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter
from hypothesis import given, settings
from hypothesis import strategies as st

from koopguide.guidance import settings as guidance_settings
from koopguide.guidance.estimation.tracker import KalmanTracker

EST = guidance_settings.load().estimator
H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])  # [N, E, vN, vE] from the state


def reference(fix: np.ndarray) -> KalmanFilter:
    kf = KalmanFilter(dim_x=4, dim_z=4)
    kf.H = H.copy()
    kf.R = np.diag([EST.position_std_m**2] * 2 + [EST.velocity_std_mps**2] * 2)
    kf.x = np.array([fix[0], fix[2], fix[1], fix[3]])
    kf.P = np.diag([EST.position_std_m**2, EST.velocity_std_mps**2] * 2)
    return kf


fix_step = st.tuples(
    st.sampled_from([0.01, 0.02, 0.05, 0.1, 0.3]),  # interval [s]
    st.lists(st.floats(-0.05, 0.05), min_size=4, max_size=4),  # noise on (N, E, vN, vE)
    st.booleans(),  # an outlier (a jump of 3 m)
)


@settings(max_examples=60, deadline=None)
@given(st.lists(fix_step, min_size=5, max_size=60), st.floats(-50, 50), st.floats(-50, 50))
def test_per_axis_float_filter_equals_filterpy_4_state_filter(steps, n0, e0):
    fix = np.array([n0, e0, 0.3, -0.2])
    tracker = KalmanTracker(EST)
    tracker.update(0.0, fix)
    kf, t = reference(fix), 0.0
    for dt, noise, outlier in steps:
        t += dt
        fix = fix + np.array([fix[2] * dt, fix[3] * dt, 0.0, 0.0]) + np.array(noise)
        z = fix + (np.array([3.0, 0.0, 0.0, 0.0]) if outlier else 0.0)
        kf.F = np.eye(4)
        kf.F[0, 1] = kf.F[2, 3] = dt
        kf.Q = Q_discrete_white_noise(dim=2, dt=dt, var=EST.accel_std_mps2**2, block_size=2)
        kf.predict()
        y = z - H @ kf.x
        d2 = float(y @ np.linalg.solve(H @ kf.P @ H.T + kf.R, y))
        result = tracker.update(t, z)
        assert result.mahalanobis2 == pytest.approx(d2, rel=1e-9, abs=1e-12)
        if result.reset:  # the gate's reset path restarts both at the fix
            kf = reference(z)
        elif result.accepted:
            kf.update(z)
        np.testing.assert_allclose(tracker.x, kf.x, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(tracker.P, kf.P, rtol=1e-9, atol=1e-15)
        p, v = tracker.predict(t + 0.5)
        x = kf.x
        np.testing.assert_allclose([*p, *v], [x[0] + 0.5 * x[1], x[2] + 0.5 * x[3], x[1], x[3]], rtol=1e-9, atol=1e-12)
