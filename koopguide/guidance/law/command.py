"""The guidance law: from an estimated position in local NED to a velocity setpoint (pure math, no I/O).

Conventions: positions ``(2,)`` local NED [m], velocities ``(2,)`` NED [m/s]; model quantities in model
units, the field's velocity in model units per learned step; headings [rad] from north.

Speed scaling (the paper's rule): the largest field speed over the model's domain, found once on a
grid, maps to ``max_speed_mps``; every command is ``gain * R v_field`` with ``gain = max_speed / v_max``,
so no command exceeds ``max_speed_mps``. What a real boat needs on top of it (each measured in
docs/guidance.md):

- pure pursuit of the field's own streamline ``lookahead_m`` ahead, and ``turn_slowdown`` (speed times
  cos(heading error)): a boat turning at ~8 deg/s at full speed swings metres wide of a tight field;
- ``min_speed_mps``: the field's speed vanishes near the goal; this floor keeps the boat coming;
- ``current_compensation``: the field is a ground track; the boat is crabbed into the estimated current
  (:func:`crab`) so that it follows it, and within ``approach_radius_m`` it is slowed just enough to
  come to face the current (:meth:`GuidanceLaw.approach_cap`), so that it arrives able to hold station;
- within ``capture_radius_m`` the boat heads straight for the goal (turning on the spot when facing
  away): near the goal the learned field is least certain, and at the speed floor the boat's turning
  circle is wider than the goal's neighbourhood.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from koopguide.guidance.law.area import outside_area
from koopguide.guidance.law.field_distance import field_distance_table
from koopguide.guidance.law.frames import ModelFrame
from koopguide.guidance.settings import (
    ArrivalSettings,
    CommandSettings,
    FailsafeSettings,
    GuidanceConfig,
    OutsideDomain,
)
from koopguide.model.field import FlowField
from koopguide.model.grid_table import GridTable


class GuidanceState(enum.Enum):
    """The service's state as published in the status (docs/zenoh.md, docs/guidance.md "States")."""

    IDLE = "idle"  # not started
    WAITING = "waiting"  # no vehicle heartbeat / position yet, or not in GUIDED
    GUIDING = "guiding"  # following the field
    ARRIVED = "arrived"  # within the arrival radius; keeping station
    HOLD = "hold"  # stale position, outside the domain or geofence: zero velocity
    FAULT = "fault"  # the field gave NaN or raised: zero velocity


ZERO = np.zeros(2)
PURSUIT_STEPS = 4  # streamline steps per look-ahead_m (field evaluations per setpoint)
MAX_PURSUIT_STEPS = 16  # ... at most, for a look-ahead lengthened for a boat's turning circle
CRAB_MIN_SPEED_MPS = 0.002  # the smallest crabbed setpoint: it carries the heading into the current [m/s]
CURRENT_MIN_MPS = 0.005  # a current estimate below this is no reason to slow the approach [m/s]
GRID_CHUNK = 1024  # field evaluations at a time when sampling a grid (bounds the lifted batch's memory)


@dataclass(frozen=True)
class Setpoint:
    """One decision: the NED velocity to send [m/s], the resulting state and why (for hold/fault);
    ``ground_ned``: the ground velocity the law wanted [m/s] (before crabbing and slowing), when guiding."""

    velocity_ned: np.ndarray
    state: GuidanceState
    reason: str | None = None
    ground_ned: np.ndarray | None = None

    @property
    def yaw_rad(self) -> float | None:
        """The velocity's direction (radians from north), None when the velocity is zero."""
        vn, ve = self.velocity_ned
        return math.atan2(ve, vn) if math.hypot(vn, ve) > 1e-9 else None


def hold(reason: str) -> Setpoint:
    return Setpoint(ZERO.copy(), GuidanceState.HOLD, reason)


class GuidanceLaw:
    """Field + frame + limits. ``decide`` maps an estimated NED position to a :class:`Setpoint`."""

    def __init__(
        self,
        field: FlowField,
        frame: ModelFrame,
        command: CommandSettings,
        arrival: ArrivalSettings,
        failsafe: FailsafeSettings,
    ) -> None:
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

    def place_goal(self, goal_ned: tuple[float, float]) -> None:
        """Move the model's goal to ``goal_ned`` [m] (a geodetic goal, once placed in local NED)."""
        self.frame = replace(self.frame, goal_ned=(float(goal_ned[0]), float(goal_ned[1])))

    @property
    def goal_ned(self) -> np.ndarray:
        return np.asarray(self.frame.goal_ned, dtype=float)

    def distance_to_goal(self, p_ned: np.ndarray) -> float:
        g = self.frame.goal_ned
        return math.hypot(float(p_ned[0]) - g[0], float(p_ned[1]) - g[1])

    @cached_property
    def along_table(self) -> GridTable:
        """The distance to the goal along the field over the domain (law/field_distance.py), built on first use."""
        radius = self.arrival.radius_m / self.frame.scale
        return field_distance_table(self.field, self.domain_lo, self.domain_hi, radius)

    def distance_along_field(self, p_ned: np.ndarray) -> float:
        """How far the boat at ``p_ned`` still has to go to the goal by following the field [m] (from outside
        the domain: the straight way to its edge first)."""
        x = self.frame.to_model(np.asarray(p_ned, dtype=float))
        x0 = np.clip(x, self.domain_lo, self.domain_hi)
        inside = self.along_table.at_one(x0)
        along = inside[0] if inside is not None else float(np.hypot(*(x0 - self.frame.goal_model)))
        return (along + float(np.hypot(*(x - x0)))) * self.frame.scale

    def outside_area(self, p_ned: np.ndarray) -> np.ndarray | float:
        """How far points ``(K, 2)`` (or one ``(2,)``) [m] lie outside the area to manoeuvre in [m] (law/area.py)."""
        out = outside_area(
            p_ned, self.frame, self.domain_lo, self.domain_hi, self.failsafe.geofence_ned, self.command.turning_room_m
        )
        return float(out[0]) if np.ndim(p_ned) == 1 else out

    def field_velocity_ned(self, p_ned: np.ndarray) -> np.ndarray:
        """The scaled field velocity at ``p_ned`` [m/s] (the paper's rule; may contain NaN from a bad model)."""
        x = np.clip(self.frame.to_model(p_ned), self.domain_lo, self.domain_hi)
        return self.gain * self.frame.direction_to_ned(self.field.velocity(x))

    def decide(
        self,
        p_ned: np.ndarray,
        arrived: bool,
        heading_rad: float | None = None,
        current_ned: np.ndarray | None = None,
        lookahead_m: float | None = None,
    ) -> Setpoint:
        """The setpoint at estimated position ``p_ned``; ``arrived`` is sticky once reached.

        ``heading_rad`` (the vehicle's heading from north, when known) slows the command while the boat
        turns toward it: a boat turns at a limited rate, and at full speed it would swing wide of the field.
        ``current_ned`` (the estimated water current [m/s], when known) is crabbed into, so that the ground
        track, not the heading, follows the field, and near the goal the boat comes to face the current.
        Within ``capture_radius_m`` the boat heads straight for the goal; within the arrival radius (and
        once arrived) it keeps station there (``station_gain``). ``lookahead_m`` replaces the configured
        look-ahead (a boat with a wide turning circle needs a longer one: guidance/helm.py).
        """
        p_ned = np.asarray(p_ned, dtype=float)
        if not finite(p_ned):
            return Setpoint(ZERO.copy(), GuidanceState.FAULT, f"non-finite position estimate {p_ned.tolist()}")
        fence = self.failsafe.geofence_ned
        if fence is not None and not all(lo <= v <= hi for v, (lo, hi) in zip(p_ned, fence, strict=True)):
            return hold(f"position {np.round(p_ned, 3).tolist()} is outside the geofence {fence}")
        distance = self.distance_to_goal(p_ned)
        to_goal = (self.goal_ned - p_ned) / distance if distance > 1e-9 else ZERO
        if arrived or distance <= self.arrival.radius_m:  # keep station at the goal
            v = self.steer(self.station_velocity(p_ned, current_ned), heading_rad, current_ned, CRAB_MIN_SPEED_MPS)
            return Setpoint(v, GuidanceState.ARRIVED)
        x = self.frame.to_model(p_ned)
        x0 = np.clip(x, self.domain_lo, self.domain_hi)
        if np.any(x0 != x) and self.failsafe.outside_domain is OutsideDomain.HOLD:
            return hold(f"position {np.round(p_ned, 3).tolist()} is outside the model's domain")
        try:
            v_model = self.field.velocity(x0)
            v = self.gain * self.frame.direction_to_ned(v_model)
            ahead = self.command.lookahead_m if lookahead_m is None else lookahead_m
            direction = self.pursuit_direction(x0, v_model, ahead) if ahead > 0 else v
        except (ArithmeticError, ValueError) as exc:
            return Setpoint(ZERO.copy(), GuidanceState.FAULT, f"field error: {exc}")
        if not (finite(v) and finite(direction)):
            return Setpoint(ZERO.copy(), GuidanceState.FAULT, f"field gave {v.tolist()} at {p_ned.tolist()}")
        speed = math.hypot(v[0], v[1])
        if speed <= 1e-12:
            return Setpoint(ZERO.copy(), GuidanceState.GUIDING)
        captured = distance <= self.arrival.capture_radius_m
        # Near the goal the learned field is least certain (few demonstrations end from every side), and a
        # boat circling it at the speed floor never turns tightly enough to get in: head for the goal,
        # turning on the spot when facing away.
        direction = to_goal if captured else direction / math.hypot(direction[0], direction[1])
        # The approach cap is a model of the boat (it turns to face the current while it still moves); it
        # never slows the boat below min_approach_mps, or a boat unlike the model stalls short of the goal.
        cap = max(self.approach_cap(distance, direction, current_ned), self.arrival.min_approach_mps)
        speed = min(max(speed, self.command.min_speed_mps), self.command.max_speed_mps, cap)  # over ground
        # Captured and facing away, a skid-steer boat turns on the spot (the turn slowdown's floor); a boat
        # that cannot (a rudder boat) makes no progress, and the progress watchdog switches to pursuit.
        floor = CRAB_MIN_SPEED_MPS if captured else self.command.min_speed_mps
        wanted = direction * speed
        return Setpoint(self.steer(wanted, heading_rad, current_ned, floor), GuidanceState.GUIDING, ground_ned=wanted)

    def station_velocity(self, p_ned: np.ndarray, current_ned: np.ndarray | None) -> np.ndarray:
        """Keeping station: the ground velocity [m/s] toward the goal, ``station_gain`` per metre from it, no
        faster than keeps the boat facing into the current (:meth:`approach_cap`) - the proportional term;
        the supervisor's :class:`~koopguide.guidance.law.station.StationKeeper` adds the integral."""
        offset = self.goal_ned - np.asarray(p_ned, dtype=float)
        distance = float(np.hypot(*offset))
        if distance <= 1e-9:
            return ZERO.copy()
        to_goal = offset / distance
        speed = min(
            self.arrival.station_gain * distance,
            self.command.max_speed_mps,
            self.approach_cap(distance, to_goal, current_ned),
        )
        return to_goal * speed

    def approach_cap(self, distance: float, direction: np.ndarray, current_ned: np.ndarray | None) -> float:
        """The largest ground speed [m/s] along ``direction`` that keeps the boat facing into the current.

        Through the water the boat moves along its heading, at w = v_ground - c; for heading within theta of
        straight upstream, the ground speed s along direction d at angle alpha from the current must satisfy
        (sine rule in the triangle 0, -c, s d - c):  s <= |c| sin(theta) / sin(theta + alpha).
        theta narrows from 180 deg (no limit) at ``approach_radius_m`` to ``facing_deg`` at the arrival
        radius, so the boat turns to face the current while it still moves, and arrives facing it: it can
        then hold station against it (a boat, turning at a few degrees per second, cannot turn in time
        once there; the current carries it off while it turns).
        """
        if current_ned is None or not self.command.current_compensation:
            return math.inf
        cn, ce = float(current_ned[0]), float(current_ned[1])
        c_norm = math.hypot(cn, ce)
        if c_norm < CURRENT_MIN_MPS:
            return math.inf
        arrival = self.arrival
        facing = math.radians(arrival.facing_deg)
        span = max(arrival.approach_radius_m - arrival.radius_m, 1e-9)
        theta = facing + (math.pi - facing) * min(max((distance - arrival.radius_m) / span, 0.0), 1.0)
        alpha = math.acos(min(max((cn * float(direction[0]) + ce * float(direction[1])) / c_norm, -1.0), 1.0))
        if theta + alpha >= math.pi:  # the heading stays within theta at any speed
            return math.inf
        return c_norm * math.sin(theta) / math.sin(theta + alpha)

    def steer(
        self, v_ground: np.ndarray, heading_rad: float | None, current_ned: np.ndarray | None, floor_mps: float
    ) -> np.ndarray:
        """The setpoint that moves the boat over ground at ``v_ground``: crabbed into the estimated current
        (``current_compensation``), then slowed by cos(heading error) while the boat turns onto it
        (``turn_slowdown``), but not below ``floor_mps`` (nor above the unslowed speed)."""
        v = v_ground
        if current_ned is not None and self.command.current_compensation:
            v = crab(v_ground, current_ned, math.radians(self.arrival.facing_deg))
        speed = math.hypot(v[0], v[1])
        if speed <= 1e-12:
            return ZERO.copy()
        if heading_rad is not None and self.command.turn_slowdown:
            error = math.atan2(v[1], v[0]) - heading_rad
            slowed = speed * max(math.cos(error), 0.0)  # full speed on course; the floor while facing away
            v = v * (max(slowed, min(floor_mps, speed)) / speed)
        return limit(v, self.command.max_speed_mps)

    def pursuit_direction(self, x0: np.ndarray, v0: np.ndarray, lookahead_m: float) -> np.ndarray:
        """NED direction (not normalised) toward the point ``lookahead_m`` along the field's streamline
        from model point ``x0`` (where the field is ``v0``).

        Pure pursuit of the field's own streamline: a boat with a bounded turn rate anticipates the
        field's turns instead of overshooting them, and near the goal it aims at the goal itself.
        """
        base = max(self.command.lookahead_m, 1e-9)
        steps = min(MAX_PURSUIT_STEPS, max(PURSUIT_STEPS, math.ceil(PURSUIT_STEPS * lookahead_m / base)))
        h = lookahead_m / self.frame.scale / steps  # [model units]
        gx, gy = self.frame.goal_model
        x0x, x0y = float(x0[0]), float(x0[1])
        x, y, vx, vy = x0x, x0y, float(v0[0]), float(v0[1])  # in plain floats: this runs for every setpoint
        for k in range(steps):
            if math.hypot(gx - x, gy - y) <= h:
                x, y = gx, gy
                break
            if k:
                vx, vy = self.field.velocity_xy(x, y)
            norm = math.hypot(vx, vy)
            if not norm > 1e-12:  # zero or NaN: stop here (NaN is caught by the caller)
                break
            x, y = x + vx * (h / norm), y + vy * (h / norm)
        d = self.frame.direction_to_ned(np.array((x - x0x, y - x0y)))
        return d if float(np.hypot(*d)) > 1e-12 else self.frame.direction_to_ned(v0)

    def sample_grid(self, n: int) -> dict:
        """The field over the domain on an ``n x n`` grid, in NED (for dashboards): JSON-ready; evaluated in
        chunks, so memory stays bounded for any ``n``."""
        P = self.frame.to_ned(box_grid(self.domain_lo, self.domain_hi, n))
        V = np.concatenate([self.field_velocity_ned(P[i : i + GRID_CHUNK]) for i in range(0, len(P), GRID_CHUNK)])
        return {
            "frame": "local_ned",
            "units": {"position_ned": "m", "velocity_ned": "m/s"},
            "n": n,
            "goal_ned": self.goal_ned.tolist(),
            "position_ned": np.round(P, 4).tolist(),
            "velocity_ned": np.round(V, 5).tolist(),
        }


def crab(v_ground: np.ndarray, current_ned: np.ndarray, glide_limit_rad: float = math.pi / 2) -> np.ndarray:
    """The velocity setpoint that makes the boat move over ground at ``v_ground`` in current ``current_ned``.

    ArduPilot Rover (GUIDED, velocity setpoint; docs/rover.md) steers the heading to the
    setpoint's direction h and holds the ground speed *along* h at the setpoint's norm s (s >= 0: no
    reverse); the current's component across h, (c . n) n, is not corrected and sets the boat sideways. The
    ground velocity is then s h + (c . n) n. It equals ``v_ground`` when h is the direction of
    w = v_ground - c (the velocity through the water: the boat heads partly into the current) and
    s = v_ground . h. Near the goal, where v_ground -> 0, h turns to face the current.

    That needs s >= 0, i.e. v_ground outside the disc on the diameter [0, c] (drifting slower than the
    current would need reverse). Inside it, the nearest ground velocity without reverse lies on the disc's
    rim: s = 0, the heading across it, and the current alone sets the boat there (a ferry glide), with
    the heading no more than ``glide_limit_rad`` off straight upstream. s is kept at least
    ``CRAB_MIN_SPEED_MPS`` so that the setpoint still carries the heading.
    """
    v_ground = np.asarray(v_ground, dtype=float)
    c = np.asarray(current_ned, dtype=float)
    w = v_ground - c  # through the water [m/s]
    w_norm = math.hypot(w[0], w[1])
    c_norm = math.hypot(c[0], c[1])
    if w_norm <= 1e-9 or c_norm <= 1e-12:  # the current alone carries the boat there, or there is none
        return v_ground.copy()
    h = w / w_norm
    s = float(v_ground @ h)
    if s >= CRAB_MIN_SPEED_MPS:
        return h * s
    u = v_ground - 0.5 * c  # from the disc's centre toward v_ground
    u_norm = float(np.hypot(*u))
    rim = 0.5 * c + 0.5 * c_norm * (u / u_norm if u_norm > 1e-12 else -c / c_norm)
    rim_norm = float(np.hypot(*rim))
    upstream = -c / c_norm
    if rim_norm <= 1e-9:  # hold still: face straight upstream
        return upstream * CRAB_MIN_SPEED_MPS
    h = np.array([-rim[1], rim[0]]) / rim_norm  # across the rim velocity; of the two, the one into the water flow
    h = h if h @ w >= 0 else -h
    # ... but no further than glide_limit_rad off upstream: a boat turned across the current is swept off
    off = math.atan2(upstream[0] * h[1] - upstream[1] * h[0], float(upstream @ h))
    off = min(max(off, -glide_limit_rad), glide_limit_rad)
    h = np.array(
        [
            upstream[0] * math.cos(off) - upstream[1] * math.sin(off),
            upstream[0] * math.sin(off) + upstream[1] * math.cos(off),
        ]
    )
    return h * CRAB_MIN_SPEED_MPS


def along_current(heading_rad: float | None, current_ned: np.ndarray | None, within_deg: float) -> bool:
    """Whether the boat faces up- or downstream within ``within_deg``; True when either is unknown or the
    current is too weak to matter."""
    if heading_rad is None or current_ned is None or float(np.hypot(*current_ned)) < CURRENT_MIN_MPS:
        return True
    across = math.sin(heading_rad - math.atan2(current_ned[1], current_ned[0]))
    return abs(across) <= math.sin(math.radians(within_deg))


def finite(v: np.ndarray) -> bool:
    """Whether both components of a 2-vector are finite (cheaper than np.all(np.isfinite(v)) per setpoint)."""
    return math.isfinite(v[0]) and math.isfinite(v[1])


def limit(v: np.ndarray, max_speed: float) -> np.ndarray:
    """``v`` with its norm capped at ``max_speed`` (direction kept)."""
    speed = math.hypot(v[0], v[1])
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
