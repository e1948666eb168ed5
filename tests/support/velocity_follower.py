"""An independent vehicle unlike the simulator's: its velocity through the water follows the guided setpoint.

Issue 10's first vehicle ("a vehicle whose velocity through the water follows the setpoint"): no hull dynamics, no
sway, no turning circle. It reads a guided target as Rover does (sitl.guided: heading and signed speed, so a
velocity-only setpoint is its direction at its norm and velocity + yaw is the yaw's direction, astern when
negative) and its velocity through the water approaches that vector with a first-order lag ``tau_s``, in any
direction (holonomic), while the water carries it. Its heading (``heading``) stays where it started (``"fixed"``: a
vehicle whose reported heading says nothing of how it moves), turns toward the heading asked at ``yaw_rate_dps``
(``"asked"``), or is the direction it moves in through the water (``"course"``, astern too).
Outside GUIDED, disarmed or without a target, it is asked nothing: it comes to rest in the water and drifts.

It replaces the simulator's boat physics (``sitl.boat.Boat.physics_step``) for the duration of a test, so the
rest is the real thing: the simulated autopilot's modes, arming and setpoint rules, sensors, MAVLink over
loopback, and the real service.

Conventions: NED [m], [m/s], headings [rad] from north; the boat state's body velocities are through the water.
"""

from __future__ import annotations

import math

import pytest

from sitl import boat as sim_boat
from sitl.guided import GuidedTarget, TargetKind
from sitl.sensors import wrap_pi


def asked_target(boat: sim_boat.Boat) -> GuidedTarget | None:
    """The heading-and-speed target its autopilot asks it to make good; None outside GUIDED, disarmed or without one."""
    ap = boat.autopilot
    target = ap.target
    if not ap.armed or ap.mode_name != "GUIDED" or target is None or target.kind is not TargetKind.HEADING_SPEED:
        return None
    return target


def asked_water_velocity(boat: sim_boat.Boat) -> tuple[tuple[float, float], float | None]:
    """The velocity through the water [m/s] its autopilot's guided target asks, and the heading it asks [rad]."""
    target = asked_target(boat)
    if target is None:
        return (0.0, 0.0), None
    return (target.speed_mps * math.cos(target.heading_rad), target.speed_mps * math.sin(target.heading_rad)), (
        target.heading_rad
    )


def install(monkeypatch: pytest.MonkeyPatch, heading: str = "fixed", tau_s: float = 0.5, yaw_rate_dps: float = 45.0):
    """Make every simulated boat a velocity follower until the test ends."""
    if heading not in ("fixed", "asked", "course"):
        raise ValueError(f"heading: fixed, asked or course, not {heading!r}")

    def physics_step(self: sim_boat.Boat, t: float, dt: float) -> None:
        n, e, psi, u, v = self.state[:5]
        c, s = math.cos(psi), math.sin(psi)
        wn, we = c * u - s * v, s * u + c * v  # through the water, NED
        (an, ae), asked = asked_water_velocity(self)
        k = min(1.0, dt / tau_s)
        wn, we = wn + (an - wn) * k, we + (ae - we) * k
        r = 0.0
        if heading == "course" and math.hypot(wn, we) > 0.02:
            r = wrap_pi(math.atan2(we, wn) - psi) / dt
            psi = wrap_pi(psi + r * dt)
        elif heading == "asked" and asked is not None:
            step = max(-1.0, min(1.0, wrap_pi(asked - psi) / (math.radians(yaw_rate_dps) * dt)))
            r = step * math.radians(yaw_rate_dps)
            psi = wrap_pi(psi + r * dt)
        vc_n, vc_e = self.flow.velocity(n, e, t)
        n, e = n + (wn + vc_n) * dt, e + (we + vc_e) * dt
        c, s = math.cos(psi), math.sin(psi)
        settle(self, (n, e, psi, c * wn + s * we, -s * wn + c * we, r, *self.state[6:]), t, dt)

    monkeypatch.setattr(sim_boat.Boat, "physics_step", physics_step)


def settle(boat: sim_boat.Boat, x: tuple[float, ...], t: float, dt: float) -> None:
    """End a replaced physics step at state ``x``, time ``t + dt``: stopped at the tank's wall, sensed."""
    boat.t = t + dt
    if not boat.tank.contains(x[0], x[1]):
        x = boat._stop_at_wall(x)
    boat.state = x
    boat.sensors.update(boat.truth())
