"""Sanity limits on everything the vehicle tells the service (issue 11): pure checks, counts, one log line
per kind per ``log_every_s``.

:class:`InputGate` rejects positions, velocities, headings, turn rates and coordinates outside physical
bounds (``limits`` in the config) and counts every rejection by kind; :class:`TeleportGuard` tells a fix
that moved farther from the estimate than the vehicle can move (a teleport: a spoofer, a glitch) from one
that stays there long enough to be a real jump (an EKF reset). Conventions: local NED [m], [m/s]; headings
[rad]; vehicle seconds ``t``; wall seconds ``wall`` only for rate-limiting the log.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from koopguide.guidance.events import Attitude, GlobalFix, Note, PositionFix
from koopguide.guidance.settings import LimitSettings

Point = np.ndarray | tuple[float, float]  # (N, E) [m]


class InputGate:
    """Checks inputs against ``limits``; counts rejections per kind; rate-limits the log lines."""

    def __init__(self, limits: LimitSettings) -> None:
        self.limits = limits
        self.counts: dict[str, int] = {}  # kind -> inputs rejected so far
        self._logged: dict[str, tuple[float, int]] = {}  # kind -> (wall s of the last line, count then)
        self._notes: list[Note] = []

    def reject(self, kind: str, detail: str, wall: float) -> None:
        """Count one rejected input of ``kind``; log it unless a line of that kind went out within log_every_s."""
        self.counts[kind] = self.counts.get(kind, 0) + 1
        last = self._logged.get(kind)
        if last is not None and wall - last[0] < self.limits.log_every_s:
            return
        since = self.counts[kind] - (last[1] if last else 0) - 1
        more = f" (+{since} more since the last line)" if since > 0 else ""
        self._notes.append(Note(logging.WARNING, f"rejected {kind}: {detail}{more}; {self.counts[kind]} so far"))
        self._logged[kind] = (wall, self.counts[kind])

    def take_notes(self) -> list[Note]:
        notes, self._notes = self._notes, []
        return notes

    def fix_ok(self, fix: PositionFix) -> bool:
        """Finite, within max_position_m, at most max_speed_mps; otherwise rejected (False)."""
        lim = self.limits
        p, v = fix.position_ned, fix.velocity_ned
        if not (math.isfinite(p[0]) and math.isfinite(p[1]) and math.isfinite(v[0]) and math.isfinite(v[1])):
            self.reject("non-finite", f"LOCAL_POSITION_NED position {list(p)} velocity {list(v)}", fix.wall_s)
            return False
        if max(abs(p[0]), abs(p[1])) > lim.max_position_m:
            self.reject("position", f"LOCAL_POSITION_NED {list(p)} m beyond +-{lim.max_position_m:g} m", fix.wall_s)
            return False
        speed = math.hypot(*v)
        if speed > lim.max_speed_mps:
            self.reject(
                "velocity", f"LOCAL_POSITION_NED speed {speed:.4g} m/s above {lim.max_speed_mps:g} m/s", fix.wall_s
            )
            return False
        return True

    def attitude_ok(self, att: Attitude) -> bool:
        if not (math.isfinite(att.heading_rad) and math.isfinite(att.turn_rate_radps)):
            self.reject("non-finite", f"ATTITUDE yaw {att.heading_rad} yawspeed {att.turn_rate_radps}", att.wall_s)
            return False
        if abs(att.heading_rad) > 2 * math.pi:
            self.reject("heading", f"ATTITUDE yaw {att.heading_rad:.4g} rad outside +-2 pi", att.wall_s)
            return False
        rate_dps = math.degrees(abs(att.turn_rate_radps))
        if rate_dps > self.limits.max_turn_rate_dps:
            self.reject(
                "turn rate",
                f"ATTITUDE yawspeed {rate_dps:.4g} deg/s above {self.limits.max_turn_rate_dps:g} deg/s",
                att.wall_s,
            )
            return False
        return True

    def global_ok(self, fix: GlobalFix) -> bool:
        if not (abs(fix.lat_deg) <= 90.0 and abs(fix.lon_deg) <= 180.0):
            self.reject("coordinates", f"GLOBAL_POSITION_INT lat {fix.lat_deg} lon {fix.lon_deg} deg", fix.wall_s)
            return False
        return True


class TeleportGuard:
    """Whether a fix is where the vehicle can be: within ``max_jump_m + max_speed_mps * dt`` of the estimate.

    A fix beyond that is a teleport and is not followed. If the fixes stay at the new place, consistent
    with each other, for ``teleport_confirm_s`` with no fix at the estimate in between, the jump is real
    (e.g. the vehicle's EKF reset its origin): :meth:`check` then says "confirmed".
    """

    def __init__(self, limits: LimitSettings) -> None:
        self.limits = limits
        self._run: tuple[float, np.ndarray, float] | None = None  # (t first, position last, t last)

    def reachable(self, p_from: Point, t_from: float, p_to: Point, t_to: float) -> bool:
        reach = self.limits.max_jump_m + self.limits.max_speed_mps * max(t_to - t_from, 0.0)
        return math.hypot(p_to[0] - p_from[0], p_to[1] - p_from[1]) <= reach

    def check(self, t: float, p: Point, predicted: Point, t_estimate: float) -> str:
        """ "ok" (reachable from the estimate), "teleport" or "confirmed" (a jump that stayed)."""
        if self.reachable(predicted, t_estimate, p, t):
            self._run = None
            return "ok"
        run = self._run
        if run is None or not self.reachable(run[1], run[2], p, t):
            self._run = (t, np.asarray(p, dtype=float), t)
            return "teleport"
        self._run = (run[0], np.asarray(p, dtype=float), t)
        if t - run[0] >= self.limits.teleport_confirm_s:
            self._run = None
            return "confirmed"
        return "teleport"

    def reset(self) -> None:
        self._run = None
