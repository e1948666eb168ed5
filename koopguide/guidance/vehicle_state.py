"""What the service believes about the vehicle's motion: checked inputs in, bounded estimates out (pure).

Every position, heading and coordinate passes the :class:`~koopguide.guidance.intake.InputGate` (physical
bounds, counted and logged once per second per kind) and, for positions, the
:class:`~koopguide.guidance.intake.TeleportGuard` before it reaches the estimators; the estimates
themselves (position, velocity, current) are checked after each update and reset when out of bounds.
Conventions: local NED [m], [m/s]; headings [rad] from north; ``t`` vehicle seconds, ``wall`` service seconds.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from koopguide.base.geodesy import geodetic_to_ned
from koopguide.guidance.estimation.current import CurrentEstimator
from koopguide.guidance.estimation.tracker import KalmanTracker
from koopguide.guidance.events import Attitude, GlobalFix, Note, PositionFix
from koopguide.guidance.intake import InputGate, TeleportGuard
from koopguide.guidance.settings import GuidanceConfig

ATTITUDE_PAIR_S = 0.2  # a heading this close in vehicle time to a fix pairs with it for the current estimate
GEODETIC_PAIR_S = 0.25  # local and global fixes this close in vehicle time place a geodetic goal


class VehicleState:
    """The checked estimates of one vehicle: position/velocity (tracker), heading, current, global fix."""

    def __init__(self, cfg: GuidanceConfig) -> None:
        self.cfg = cfg
        self.gate = InputGate(cfg.limits)
        self.teleports = TeleportGuard(cfg.limits)
        self.tracker = KalmanTracker(cfg.estimator)
        self.current = CurrentEstimator(cfg.estimator)
        self.fix_t: float | None = None  # vehicle time of the newest accepted fix [s]
        self.fix_ned: tuple[float, float] | None = None  # its (N, E) [m]
        self.fix_interval = 0.05  # typical vehicle time between fixes [s], learned from them
        self.attitude: tuple[float, float, float] | None = None  # (t, heading rad, turn rate rad/s)
        self.heading_rad: float | None = None  # the last known heading (any age): zero commands keep it
        self.global_fix: tuple[float, float, float] | None = None  # (t, lat deg, lon deg)
        self.teleport_until = -math.inf  # hold until this vehicle time: positions are teleporting [s]
        self.teleport_reason = ""
        self.notes: list[Note] = []

    def restart(self, forget_fixes: bool = False) -> None:
        """Fresh estimators (a confirmed jump); ``forget_fixes`` also drops every fact (a clock restart)."""
        self.tracker = KalmanTracker(self.cfg.estimator)
        self.current = CurrentEstimator(self.cfg.estimator)
        self.teleports.reset()
        self.teleport_until = -math.inf
        if forget_fixes:
            self.fix_t = self.fix_ned = self.attitude = self.global_fix = None

    def on_position(self, fix: PositionFix) -> bool:
        """Fold in a fix; False when it was rejected (out of bounds, out of order, a teleport).

        On the fix-to-setpoint path: plain floats, no arrays (docs/guidance.md "Latency")."""
        if not self.gate.fix_ok(fix):
            return False
        t = fix.t_s
        (n, e), (vn, ve) = fix.position_ned, fix.velocity_ned
        tracker = self.tracker
        if tracker.t is not None and t < tracker.t:
            self.gate.reject(
                "out-of-order", f"LOCAL_POSITION_NED at {t:.3f} s, older than {tracker.t:.3f} s", fix.wall_s
            )
            return False
        if tracker.t is not None and t - tracker.t <= self.cfg.estimator.max_dt_s:
            predicted = tracker.predict_floats(t)[:2]
            verdict = self.teleports.check(t, (n, e), predicted, tracker.t)
            if verdict == "teleport":
                p = np.array((n, e))
                jump = math.hypot(n - predicted[0], e - predicted[1])
                self.teleport_reason = (
                    f"position {np.round(p, 2).tolist()} m is {jump:.2f} m from the estimate, "
                    "farther than the vehicle can move; not following it"
                )
                self.teleport_until = t + self.cfg.limits.teleport_hold_s
                self.gate.reject("teleport", self.teleport_reason, fix.wall_s)
                return False
            if verdict == "confirmed":
                self.notes.append(
                    Note(
                        logging.WARNING,
                        f"the position jumped to {np.round(np.array((n, e)), 2).tolist()} m and "
                        f"stayed there for {self.cfg.limits.teleport_confirm_s:g} s; estimate restarted",
                    )
                )
                self.restart()
        fix_vector = (n, e, vn, ve)
        if not self.tracker.update(t, fix_vector).accepted:
            return False
        pn, pe, vn_est, ve_est = self.tracker.predict_floats(t)
        lim = self.cfg.limits
        inside = max(abs(pn), abs(pe)) <= lim.max_position_m and math.hypot(vn_est, ve_est) <= lim.max_speed_mps
        if not inside:  # also False for NaN
            self.notes.append(
                Note(
                    logging.WARNING,
                    f"position estimate {[pn, pe]} m, {[vn_est, ve_est]} m/s out of bounds; restarted at the fix",
                )
            )
            self.tracker.reset(t, fix_vector)
        if self.fix_t is not None and t > self.fix_t:
            self.fix_interval += 0.1 * (min(t - self.fix_t, 1.0) - self.fix_interval)
        self.fix_t, self.fix_ned = t, (n, e)
        return True

    def on_attitude(self, att: Attitude) -> None:
        if self.gate.attitude_ok(att):
            self.attitude = (att.t_s, att.heading_rad, att.turn_rate_radps)
            self.heading_rad = att.heading_rad

    def on_global(self, fix: GlobalFix) -> None:
        if self.gate.global_ok(fix):
            self.global_fix = (fix.t_s, fix.lat_deg, fix.lon_deg)

    def update_current(self, t: float, drifting: bool = False, water: tuple[np.ndarray, float] | None = None) -> None:
        """Fold the fix at ``t`` and a heading of about the same moment into the current estimate; reset
        the estimate when it leaves its bounds (a current faster than ``limits.max_current_mps``). ``water``:
        the boat's velocity through the water when it is known [m/s] (a boat that goes where it is sent: the
        velocity sent; one stopped, adrift: 0) and the standard deviation of its way along the heading [m/s], so
        that the ground velocity less it measures both components, as when drifting."""
        att = self.attitude
        if att is None or self.fix_t is None or abs(att[0] - t) > ATTITUDE_PAIR_S:
            return
        v, way_std = self.tracker.predict(t)[1], 0.0
        if water is not None:
            v, drifting, way_std = v - np.asarray(water[0], dtype=float), True, water[1]
        self.current.update(t, v, att[1], att[2], drifting, way_std)
        c = self.current.current_ned
        if not (np.all(np.isfinite(c)) and float(np.hypot(*c)) <= self.cfg.limits.max_current_mps):
            self.notes.append(
                Note(
                    logging.WARNING,
                    f"current estimate {np.round(c, 4).tolist()} m/s beyond "
                    f"{self.cfg.limits.max_current_mps:g} m/s; reset",
                )
            )
            self.current = CurrentEstimator(self.cfg.estimator)

    def position_age(self, now: float) -> float | None:
        return None if self.fix_t is None else max(0.0, now - self.fix_t)

    def estimate(self, now: float) -> tuple[np.ndarray, np.ndarray] | None:
        """Position and velocity at ``now``; a stale estimate is not run on past the stale allowance."""
        if self.fix_t is None or self.tracker.t is None:
            return None
        return self.tracker.predict(min(now, self.fix_t + self.cfg.failsafe.stale_after_s))

    def heading_at(self, now: float) -> float | None:
        """The heading if measured within the stale allowance, else None."""
        att = self.attitude
        return att[1] if att is not None and now - att[0] <= self.cfg.failsafe.stale_after_s else None

    def geodetic_to_local(self, latlon_deg: tuple[float, float]) -> tuple[float, float] | None:
        """Where ``latlon_deg`` lies in local NED [m], once a local and a global fix of about the same moment
        exist (within GEODETIC_PAIR_S); None before."""
        if self.global_fix is None or self.fix_t is None:
            return None
        t_global, lat, lon = self.global_fix
        if abs(t_global - self.fix_t) > GEODETIC_PAIR_S:
            return None
        dn, de = geodetic_to_ned(latlon_deg[0], latlon_deg[1], lat, lon)
        return round(float(self.fix_ned[0] + dn), 3), round(float(self.fix_ned[1] + de), 3)

    def take_notes(self) -> list[Note]:
        notes, self.notes = self.notes + self.gate.take_notes(), []
        return notes
