"""The guidance law: from an estimated position in local NED to a velocity setpoint (pure math, no I/O).

Conventions: positions ``(2,)`` local NED [m], velocities ``(2,)`` NED [m/s]; model quantities in model
units, the field's velocity in model units per learned step.

Speed scaling (the paper's rule): the largest field speed over the model's domain, found once on a
grid, maps to ``max_speed_mps``; every command is ``gain * R v_field`` with ``gain = max_speed / v_max``,
so no command exceeds ``max_speed_mps``. Two changes to it, both measured in docs/guidance.md:
``turn_slowdown`` scales the speed by cos(heading error) while the boat turns onto the field's direction
(a boat turning at ~8 deg/s at full speed swings metres wide of a tight field), and ``min_speed_mps``
keeps at least that speed in the field's direction until the arrival radius, so neither a turn nor a
converging field's vanishing speed near the goal lets a current stall the boat short of it.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

from koopguide.field import FlowField
from koopguide.guidance.frames import ModelFrame
from koopguide.guidance.settings import (
    ArrivalSettings,
    CommandSettings,
    FailsafeSettings,
    GuidanceConfig,
    OutsideDomain,
)


class GuidanceState(enum.Enum):
    """The service's state as published in the status (DESIGN.md)."""

    IDLE = "idle"  # not started
    WAITING = "waiting"  # no vehicle heartbeat / position yet, or not in GUIDED
    GUIDING = "guiding"  # following the field
    ARRIVED = "arrived"  # within the arrival radius; keeping station
    HOLD = "hold"  # stale position, outside the domain or geofence: zero velocity
    FAULT = "fault"  # the field gave NaN or raised: zero velocity


ZERO = np.zeros(2)
PURSUIT_STEPS = 4  # streamline steps per look-ahead (field evaluations per setpoint)


@dataclass(frozen=True)
class Setpoint:
    """One decision: the NED velocity to send [m/s], the resulting state and why (for hold/fault)."""

    velocity_ned: np.ndarray
    state: GuidanceState
    reason: str | None = None

    @property
    def yaw_rad(self) -> float | None:
        """The velocity's direction (radians from north), None when the velocity is zero."""
        vn, ve = self.velocity_ned
        return math.atan2(ve, vn) if math.hypot(vn, ve) > 1e-9 else None


def hold(reason: str) -> Setpoint:
    return Setpoint(ZERO.copy(), GuidanceState.HOLD, reason)


class GuidanceLaw:
    """Field + frame + limits. ``decide`` maps an estimated NED position to a :class:`Setpoint`."""

    def __init__(self, field: FlowField, frame: ModelFrame, command: CommandSettings, arrival: ArrivalSettings,
                 failsafe: FailsafeSettings) -> None:
        if field.dim != 2:
            raise ValueError(f"the guidance service steers in the plane: the model has dim {field.dim}, expected 2")
        self.field = field
        self.frame = frame
        self.command = command
        self.arrival = arrival
        self.failsafe = failsafe
        lo, hi = field.bounds
        pad = command.domain_margin * (hi - lo)
        self.domain_lo, self.domain_hi = lo - pad, hi + pad  # the model's domain [model units]
        self.v_max = max_field_speed(field, self.domain_lo, self.domain_hi, command.speed_grid)
        self.gain = command.max_speed_mps / self.v_max  # m/s per (model unit / learned step)

    @classmethod
    def from_config(cls, field: FlowField, cfg: GuidanceConfig) -> GuidanceLaw:
        """The law for ``field`` placed and limited as ``cfg`` says."""
        return cls(field, ModelFrame.place(field.goal, cfg.frame), cfg.command, cfg.arrival, cfg.failsafe)

    @property
    def goal_ned(self) -> np.ndarray:
        return np.asarray(self.frame.goal_ned, dtype=float)

    def distance_to_goal(self, p_ned: np.ndarray) -> float:
        return float(np.hypot(*(np.asarray(p_ned) - self.goal_ned)))

    def field_velocity_ned(self, p_ned: np.ndarray) -> np.ndarray:
        """The scaled field velocity at ``p_ned`` [m/s] (the paper's rule; may contain NaN from a bad model)."""
        x = np.clip(self.frame.to_model(p_ned), self.domain_lo, self.domain_hi)
        return self.gain * self.frame.direction_to_ned(self.field.velocity(x))

    def decide(self, p_ned: np.ndarray, arrived: bool, heading_rad: float | None = None) -> Setpoint:
        """The setpoint at estimated position ``p_ned``; ``arrived`` is sticky once reached.

        ``heading_rad`` (the vehicle's heading from north, when known) slows the command while the boat
        turns toward it: a boat turns at a limited rate, and at full speed it would swing wide of the field.
        """
        p_ned = np.asarray(p_ned, dtype=float)
        if not np.all(np.isfinite(p_ned)):
            return Setpoint(ZERO.copy(), GuidanceState.FAULT, f"non-finite position estimate {p_ned.tolist()}")
        fence = self.failsafe.geofence_ned
        if fence is not None and not all(lo <= v <= hi for v, (lo, hi) in zip(p_ned, fence, strict=True)):
            return hold(f"position {np.round(p_ned, 3).tolist()} is outside the geofence {fence}")
        distance = self.distance_to_goal(p_ned)
        if arrived or distance <= self.arrival.radius_m:
            v = self.arrival.station_gain * (self.goal_ned - p_ned)
            return Setpoint(limit(v, self.command.max_speed_mps), GuidanceState.ARRIVED)
        x = self.frame.to_model(p_ned)
        x0 = np.clip(x, self.domain_lo, self.domain_hi)
        if np.any(x0 != x) and self.failsafe.outside_domain is OutsideDomain.HOLD:
            return hold(f"position {np.round(p_ned, 3).tolist()} is outside the model's domain")
        try:
            v_model = self.field.velocity(x0)
            v = self.gain * self.frame.direction_to_ned(v_model)
            direction = self.pursuit_direction(x0, v_model) if self.command.lookahead_m > 0 else v
        except (ArithmeticError, ValueError) as exc:
            return Setpoint(ZERO.copy(), GuidanceState.FAULT, f"field error: {exc}")
        if not (np.all(np.isfinite(v)) and np.all(np.isfinite(direction))):
            return Setpoint(ZERO.copy(), GuidanceState.FAULT, f"field gave {v.tolist()} at {p_ned.tolist()}")
        speed = float(np.hypot(*v))
        if speed <= 1e-12:
            return Setpoint(ZERO.copy(), GuidanceState.GUIDING)
        direction = direction / float(np.hypot(*direction))
        if heading_rad is not None and self.command.turn_slowdown:
            error = math.atan2(direction[1], direction[0]) - heading_rad
            speed *= max(math.cos(error), 0.0)  # full speed on course; min_speed_mps while facing away
        speed = min(max(speed, self.command.min_speed_mps), self.command.max_speed_mps)
        return Setpoint(direction * speed, GuidanceState.GUIDING)

    def pursuit_direction(self, x0: np.ndarray, v0: np.ndarray) -> np.ndarray:
        """NED direction (not normalised) toward the point ``lookahead_m`` along the field's streamline
        from model point ``x0`` (where the field is ``v0``).

        Pure pursuit of the field's own streamline: a boat with a bounded turn rate anticipates the
        field's turns instead of overshooting them, and near the goal it aims at the goal itself.
        """
        h = self.command.lookahead_m / self.frame.scale / PURSUIT_STEPS  # [model units]
        goal = np.asarray(self.frame.goal_model, dtype=float)
        x, v = x0, v0
        for k in range(PURSUIT_STEPS):
            if np.hypot(*(goal - x)) <= h:
                x = goal
                break
            if k:
                v = self.field.velocity(x)
            norm = float(np.hypot(*v))
            if not norm > 1e-12:  # zero or NaN: stop here (NaN is caught by the caller)
                break
            x = x + v * (h / norm)
        d = self.frame.direction_to_ned(x - x0)
        return d if float(np.hypot(*d)) > 1e-12 else self.frame.direction_to_ned(v0)

    def sample_grid(self, n: int) -> dict:
        """The field over the domain on an ``n x n`` grid, in NED (for dashboards): JSON-ready."""
        P = self.frame.to_ned(box_grid(self.domain_lo, self.domain_hi, n))
        V = self.field_velocity_ned(P)
        return {
            "frame": "local_ned",
            "units": {"position_ned": "m", "velocity_ned": "m/s"},
            "n": n,
            "goal_ned": self.goal_ned.tolist(),
            "position_ned": np.round(P, 4).tolist(),
            "velocity_ned": np.round(V, 5).tolist(),
        }


def limit(v: np.ndarray, max_speed: float) -> np.ndarray:
    """``v`` with its norm capped at ``max_speed`` (direction kept)."""
    speed = float(np.hypot(*v))
    return v * (max_speed / speed) if speed > max_speed else v


def max_field_speed(field: FlowField, lo: np.ndarray, hi: np.ndarray, n: int) -> float:
    """The largest field speed [model units / learned step] on an ``n x n`` grid over the box [lo, hi]."""
    speeds = np.linalg.norm(field.velocity(box_grid(lo, hi, n)), axis=1)
    if not np.all(np.isfinite(speeds)):
        raise ValueError("the model's field is not finite over its domain (NaN or inf velocities)")
    v_max = float(speeds.max())
    if v_max <= 0.0:
        raise ValueError("the model's field is zero over its whole domain; nothing to follow")
    return v_max


def box_grid(lo: np.ndarray, hi: np.ndarray, n: int) -> np.ndarray:
    """``(n * n, 2)`` points of an ``n x n`` grid over the box [lo, hi], x varying fastest."""
    X = np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n))
    return np.stack(X, axis=-1).reshape(-1, 2)
