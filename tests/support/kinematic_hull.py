"""The hull shared by the independent kinematic boats (tests/support/kinematic_rudder.py, kinematic_skid.py).

A boat with no sway and no hull dynamics: each physics step its autopilot's steering rule (the caller's) turns the
guided target into a demand for speed through the water and a yaw rate; the speed through the water ``u`` follows
that demand with a first-order lag ``tau_s`` (at most ``ahead_mps`` ahead, ``astern_mps`` astern), the heading turns
at the yaw rate, and the water carries the boat. It reads a guided target as Rover does (sitl.guided: heading and
signed speed); outside GUIDED, disarmed or without a target the steering rule is told none (it then asks nothing,
and the boat drifts).

It replaces the simulator's boat physics (``sitl.boat.Boat.physics_step``) for the duration of a test; the rest
is the real thing (the simulated autopilot's modes and setpoint rules, sensors, MAVLink over loopback, the real
service).

Conventions: NED [m], [m/s], headings [rad] from north; the boat state's body velocities are through the water.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import pytest

from sitl import boat as sim_boat
from sitl.guided import GuidedTarget
from sitl.sensors import wrap_pi
from tests.support.velocity_follower import asked_target, settle

# (boat, target (None: none asked), heading psi [rad], way u [m/s], the current along the heading [m/s], dt [s]) ->
# (speed through the water demanded [m/s], yaw rate [rad/s])
Steering = Callable[[sim_boat.Boat, GuidedTarget | None, float, float, float, float], tuple[float, float]]


def speed_demand(target: GuidedTarget, current_along: float, stops_at_zero: bool) -> float:
    """The speed through the water [m/s] the autopilot's speed loop asks: the speed over ground asked along the heading
    less the water's share of it (``current_along``); with ``stops_at_zero`` (Rover's stop controller) none at speed
    0, throttle off, so the water carries the boat, where without it speed 0 holds the boat's ground."""
    if stops_at_zero and target.speed_mps == 0.0:
        return 0.0
    return target.speed_mps - current_along


def install(
    monkeypatch: pytest.MonkeyPatch, steer: Steering, tau_s: float, ahead_mps: float, astern_mps: float
) -> None:
    """Make every simulated boat a kinematic hull driven by ``steer`` until the test ends."""

    def physics_step(self: sim_boat.Boat, t: float, dt: float) -> None:
        n, e, psi, u = self.state[:4]
        target = asked_target(self)
        vc_n, vc_e = self.flow.velocity(n, e, t)
        demand, r = steer(self, target, psi, u, math.cos(psi) * vc_n + math.sin(psi) * vc_e, dt)
        u += (max(-astern_mps, min(ahead_mps, demand)) - u) * min(1.0, dt / tau_s)
        psi = wrap_pi(psi + r * dt)
        n, e = n + (math.cos(psi) * u + vc_n) * dt, e + (math.sin(psi) * u + vc_e) * dt
        settle(self, (n, e, psi, u, 0.0, r, *self.state[6:]), t, dt)

    monkeypatch.setattr(sim_boat.Boat, "physics_step", physics_step)
