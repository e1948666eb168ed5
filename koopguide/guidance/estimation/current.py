"""CurrentEstimator: the water current at the boat in local NED, from how the boat slips sideways (filterpy).

A displacement boat moves through the water along its heading (its sway through the water is small), so
the component of its ground velocity across its heading is the current's component across it:

    v_ground . n(psi) = c . n(psi),   n(psi) = (-sin psi, cos psi)   (NED; psi = heading from north)

One heading shows one component of the current; as the heading changes along a route both become
observable. The component along the heading cannot be told from the boat's own speed through the water,
and does not need to be: the autopilot holds the speed over ground along the heading (see
:func:`koopguide.guidance.law.command.crab`).

Model: state ``c = (c_N, c_E)`` [m/s], a random walk in time and, where the water shows shear, in space: over
``dt`` seconds in which the boat covers ``|v_ground| dt`` metres the covariance grows by
``(walk^2 dt + w shear^2 |v_ground| dt) I`` (``current_walk_mps_per_sqrt_s``, ``current_shear_mps_per_sqrt_m``).
With time alone, the component along a long straight leg (never observed on it) keeps the value seen a metre or
two back: in a vortex, 0.04-0.05 m/s off at the goal; grown with the distance covered, the next headings' slip
corrects it. In uniform water that growth only lets the hull's own sideways slip (after a turn) leak into the
unobserved component, so it applies in proportion ``w`` (0..1) to how far the slip's innovations exceed what
uniform water gives: none below ``current_shear_onset_mps`` RMS (over ``SLIP_WINDOW_S``), all of it from twice
that; an innovation-based adaptive filter (Mehra (1970), "On the identification of variances and adaptive Kalman
filtering", IEEE TAC 15(2); Mohamed & Schwarz (1999), J. Geodesy 73). ``P_seen`` is the covariance of the same
measurements with the walk in time only: how well the headings flown pin the current down, which decides whether
the hold may follow the current's line (docs/guidance-notes.md, "Where it fails").
Prior ``c = 0`` with ``current_prior_std_mps``; measurement ``z = v_ground . n(psi)`` with ``H = n(psi)^T``
and the fix's velocity noise. Measurements while the boat turns faster than ``current_max_turn_dps`` are
skipped: in a turn the hull does slip sideways through the water, which would read as current. A boat that is
not propelled (disarmed) drifts with the water: then its whole ground velocity measures the current (H = I); so
does one stopped with the throttle off, its way still dying along its heading counted as noise there.

The hull's own slip in the gentler turns that are measured is learned with the current: in a steady turn a hull
slips sideways in proportion to its speed through the water times its turn rate (the steady turn of the linear
sway-yaw manoeuvring model, Fossen (2021), "Handbook of Marine Craft Hydrodynamics and Motion Control", 2nd ed.,
ch. 7: ``v = kappa u r``, ``kappa`` [s] set by the hull's mass, sway damping and rudder), which it reaches with
the sway's own lag (``m22 / |Y_v|``: 0.5 s for the simulator's hull, 1.2 s for a heavier one) and keeps for as
long after the turn. So the state is ``(c_N, c_E, kappa_0, kappa_1)`` and the measurement
``z = c . n(psi) + kappa_0 u r + kappa_1 <u r>``, ``<u r>`` being ``u r`` low-passed over ``SWAY_LAG_S`` (through
the fast turns whose measurements are skipped too: their sway outlasts them), with the prior ``kappa = 0 +-
SWAY_PRIOR_S``; the two together stand for a lag of 0 to a second or two. A heavier hull that slips more (2 kg,
Y_v -3 kg/s) took 0.01 m/s of its slip in the last turn before the goal for current, 23-27 deg of the current's
direction, and held along that line up to 0.8 m off (stop 42).

Conventions: velocities NED [m/s], headings [rad] from north, time in vehicle seconds.
"""

from __future__ import annotations

import math

import numpy as np
from filterpy.kalman import KalmanFilter
from filterpy.kalman import update as kalman_update

from koopguide.guidance.settings import EstimatorSettings

SLIP_WINDOW_S = 3.0  # the time constant of the innovations' running mean square [s]
SLIP_SAMPLE_S = 0.2  # one innovation stands for at most this long of that window (two command periods) [s]
SLIP_CLIP_ONSETS = 3.0  # ... and counts at most this many current_shear_onset_mps (a spike is one; shear keeps coming)
SWAY_PRIOR_S = 1.0  # the prior spread of kappa, the hull's slip per unit of speed times turn rate [s]
SWAY_LAG_S = 1.0  # the second sway regressor: speed times turn rate low-passed with this time constant [s]
WAY_BIAS = 3.0  # the way a stopped boat has left is one bias through the stop, not noise from fix to fix: its spread
# counts this many times over (counted once, the filter took the same bias at each fix: stopped from 0.2 m/s, fixes at
# 20 Hz, the current along the heading overshot by 0.066 m/s; 0.023 so; stop 54)
C = slice(0, 2)  # the current's part of the state (c_N, c_E); then kappa_0, kappa_1 [s]


class CurrentEstimator:
    """Filters sideways-slip measurements into an estimate of the current (N, E) [m/s]."""

    def __init__(self, settings: EstimatorSettings) -> None:
        self.settings = settings
        self.kf = KalmanFilter(dim_x=4, dim_z=1)
        self.kf.F = np.eye(4)
        self.kf.R = np.array([[settings.velocity_std_mps**2]])
        self.kf.P = np.diag([settings.current_prior_std_mps**2] * 2 + [SWAY_PRIOR_S**2] * 2)
        self.kf.x = np.zeros(4)
        self.turning = 0.0  # speed through the water times turn rate, low-passed over SWAY_LAG_S [m/s^2]
        self.P_seen = self.kf.P.copy()  # the same measurements' covariance with the walk in time only [m^2/s^2]
        self.slip_ms = 0.0  # mean square of the slip's innovations over about SLIP_WINDOW_S [m^2/s^2]
        self.t: float | None = None  # vehicle time of the last measurement [s]
        self.updates = 0

    @property
    def current_ned(self) -> np.ndarray:
        """The estimate (c_N, c_E) [m/s]."""
        return self.kf.x[C].copy()

    @property
    def std_mps(self) -> float:
        """The estimate's larger standard deviation [m/s] (the prior's until both components are seen)."""
        return larger_std(self.kf.P[C, C])

    @property
    def seen_std_mps(self) -> float:
        """How well the headings flown pin the current down [m/s]: the larger standard deviation the same
        measurements give with the random walk in time only (no shear). Along a straight leg the shear's spread
        grows in the component the slip cannot see; this one does not, so it tells a current seen from enough
        headings (trust its direction) from one not yet seen (``std_mps`` is the filter's own)."""
        return larger_std(self.P_seen[C, C])

    @property
    def shear_weight(self) -> float:
        """How much of ``current_shear_mps_per_sqrt_m`` applies now, 0..1: none while the slip's innovations
        (RMS over ``SLIP_WINDOW_S``) stay below ``current_shear_onset_mps``, all of it from twice that."""
        onset = self.settings.current_shear_onset_mps
        return min(max(math.sqrt(self.slip_ms) / onset - 1.0, 0.0), 1.0)

    def update(
        self,
        t: float,
        v_ground: np.ndarray,
        heading_rad: float,
        turn_rate_radps: float,
        drifting: bool = False,
        way_std_mps: float = 0.0,
    ) -> bool:
        """Fold in the ground velocity (N, E) [m/s] seen at vehicle time ``t`` [s] with the boat's heading
        and turn rate; False when the measurement was skipped (turning fast, or not finite). ``drifting``: the
        boat is not propelled (disarmed, or stopped with the throttle off), so its whole ground velocity is the
        current's, less any way it has left along its heading, of standard deviation ``way_std_mps``."""
        v_ground = np.asarray(v_ground, dtype=float)
        if not (np.all(np.isfinite(v_ground)) and math.isfinite(heading_rad) and math.isfinite(turn_rate_radps)):
            return False
        s, dt = self.settings, 0.0
        if self.t is not None and t > self.t:  # random walk over the time since the last measurement and the way
            dt = min(t - self.t, s.max_dt_s)
            metres = float(np.hypot(*v_ground)) * dt
            walk = s.current_walk_mps_per_sqrt_s**2 * dt
            self.kf.P[C, C] += np.eye(2) * (walk + self.shear_weight * s.current_shear_mps_per_sqrt_m**2 * metres)
            self.P_seen[C, C] += np.eye(2) * walk
        if self.t is None or t > self.t:
            self.t = t
        h = np.array([math.cos(heading_rad), math.sin(heading_rad)])
        ur = 0.0 if drifting else float((v_ground - self.kf.x[C]) @ h) * turn_rate_radps  # u r [m/s^2]
        self.turning += (1.0 - math.exp(-dt / SWAY_LAG_S)) * (ur - self.turning)
        if abs(turn_rate_radps) > math.radians(s.current_max_turn_dps):
            return False
        if drifting:  # both components at once
            z, H, R = (
                v_ground.copy(),
                np.eye(2, 4),
                np.eye(2) * s.velocity_std_mps**2 + (WAY_BIAS * way_std_mps) ** 2 * np.outer(h, h),
            )
        else:
            H = np.array([[-h[1], h[0], ur, self.turning]])  # across the heading (starboard), and the hull's slip
            z, R = np.array([float(H[0, C] @ v_ground)]), self.kf.R
        self.kf.update(z, R=R, H=H)
        _, self.P_seen = kalman_update(self.kf.x, self.P_seen, z, R, H)
        if not drifting:  # the slip's innovation [m/s], averaged in its square over SLIP_WINDOW_S; after a gap
            # (a turn, the area's edge) the first one is one sample, not the window's worth, and a spike counts as
            # SLIP_CLIP_ONSETS: the hull's sway as it left a tank's wall, one innovation weighted by the gap before
            # it, latched a uniform current as sheared (rudder, stop 31)
            a = min(dt, SLIP_SAMPLE_S) / SLIP_WINDOW_S
            y = min(abs(float(self.kf.y[0])), SLIP_CLIP_ONSETS * s.current_shear_onset_mps)
            self.slip_ms += a * (y**2 - self.slip_ms)
        self.updates += 1
        return True


def larger_std(P: np.ndarray) -> float:
    """The larger standard deviation [m/s] of a 2x2 covariance ``P`` [m^2/s^2]: its larger eigenvalue's root."""
    return float(math.sqrt(max(np.linalg.eigvalsh(P))))
