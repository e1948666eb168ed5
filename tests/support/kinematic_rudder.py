"""An independent rudder boat unlike the simulator's: a kinematic one whose autopilot has no stop controller.

Issue 10's third vehicle ("a rudder boat, which cannot steer without way through the water") as one might build
it from the issue's list of Rover facts alone: its speed loop holds the speed over ground along the heading at
the speed asked, 0 included (no stop controller: asked 0 in a current, it keeps way on and holds its ground,
where Rover's throttle goes off and the boat drifts), its speed through the water following that demand with a
first-order lag ``tau_s`` (at most ``ahead_mps`` ahead, ``astern_mps`` astern); it turns toward the heading
asked at ``k_per_s`` times the error, but never faster than ``|u| / radius_m`` (no turn without way through the
water, a turning circle of ``radius_m`` at any speed); no sway, no hull dynamics. ``astern_mps`` 0 is a thruster
that does not reverse; ``stops_at_zero`` gives it Rover's stop controller after all (asked 0, throttle off: it
drifts). It reads a guided target as Rover does (sitl.guided: heading and signed speed); outside GUIDED, disarmed
or without a target it is asked nothing and drifts.

It replaces the simulator's boat physics (``sitl.boat.Boat.physics_step``) for the duration of a test; the rest
is the real thing (the simulated autopilot's modes and setpoint rules, sensors, MAVLink over loopback, the real
service).

Conventions: NED [m], [m/s], headings [rad] from north; the boat state's body velocities are through the water.
"""

from __future__ import annotations

import math

import pytest

from sitl import boat as sim_boat
from sitl.sensors import wrap_pi
from tests.support.velocity_follower import asked_target, settle


def install(
    monkeypatch: pytest.MonkeyPatch,
    radius_m: float = 0.6,
    tau_s: float = 1.0,
    ahead_mps: float = 0.4,
    astern_mps: float = 0.15,
    k_per_s: float = 1.5,
    stops_at_zero: bool = False,
) -> None:
    """Make every simulated boat this kinematic rudder boat until the test ends."""

    def physics_step(self: sim_boat.Boat, t: float, dt: float) -> None:
        n, e, psi, u = self.state[:4]
        target = asked_target(self)
        vc_n, vc_e = self.flow.velocity(n, e, t)
        demand, r = 0.0, 0.0
        if target is not None:
            current_along = math.cos(psi) * vc_n + math.sin(psi) * vc_e
            demand = target.speed_mps - current_along  # over ground along the heading: the water's share taken off
            demand = 0.0 if stops_at_zero and target.speed_mps == 0.0 else demand  # Rover's stop controller
            turn = abs(u) / radius_m
            r = max(-turn, min(turn, k_per_s * wrap_pi(target.heading_rad - psi)))
        u += (max(-astern_mps, min(ahead_mps, demand)) - u) * min(1.0, dt / tau_s)
        psi = wrap_pi(psi + r * dt)
        n, e = n + (math.cos(psi) * u + vc_n) * dt, e + (math.sin(psi) * u + vc_e) * dt
        settle(self, (n, e, psi, u, 0.0, r, *self.state[6:]), t, dt)

    monkeypatch.setattr(sim_boat.Boat, "physics_step", physics_step)
