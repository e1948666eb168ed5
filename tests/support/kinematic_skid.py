"""An independent differential-thrust boat unlike the simulator's: a kinematic one that pivots in GUIDED.

Issue 10's second vehicle ("a differential-thrust boat with ArduPilot's semantics: heading plus speed over ground,
pivot turns") as one might build it from the issue's list of Rover facts alone, taking "skid-steer vehicles pivot
when the heading error exceeds WP_PIVOT_ANGLE" to hold for guided velocity targets too (the simulator follows
Rover's source, where only waypoint navigation pivots): beyond ``pivot_deg`` off the heading asked it stops
driving and turns in place at ``pivot_rate_dps`` until within ``pivot_exit_deg``; otherwise it turns at
``k_per_s`` times the error (at most ``turn_rate_dps``) while its speed loop holds the speed over ground along the
heading at the speed asked, scaled by the cosine of the heading error (skid steering slows while turning). Its
speed through the water follows that demand with a first-order lag ``tau_s`` (at most ``ahead_mps`` ahead,
``astern_mps`` astern); asked 0 it either holds its ground along its heading (no stop controller) or, with
``stops_at_zero``, lets the water carry it (Rover's stop controller). No sway, no hull dynamics. It reads a guided
target as Rover does (sitl.guided: heading and signed speed); outside GUIDED, disarmed or without a target it is
asked nothing and drifts.

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
    pivot_deg: float = 60.0,
    pivot_exit_deg: float = 10.0,
    pivot_rate_dps: float = 45.0,
    turn_rate_dps: float = 60.0,
    k_per_s: float = 1.5,
    tau_s: float = 0.8,
    ahead_mps: float = 0.4,
    astern_mps: float = 0.3,
    stops_at_zero: bool = False,
) -> None:
    """Make every simulated boat this kinematic skid-steer boat until the test ends."""
    pivot, pivot_exit = math.radians(pivot_deg), math.radians(pivot_exit_deg)
    pivot_rate, turn_rate = math.radians(pivot_rate_dps), math.radians(turn_rate_dps)
    pivoting: dict[int, bool] = {}  # per boat (sysid): a pivot turn is under way

    def physics_step(self: sim_boat.Boat, t: float, dt: float) -> None:
        n, e, psi, u = self.state[:4]
        target = asked_target(self)
        vc_n, vc_e = self.flow.velocity(n, e, t)
        demand, r = 0.0, 0.0
        if target is None:
            pivoting[self.sysid] = False
        else:
            error = wrap_pi(target.heading_rad - psi)
            was = pivoting.get(self.sysid, False)
            now = abs(error) > (pivot_exit if was else pivot)
            pivoting[self.sysid] = now
            if now:
                r = math.copysign(min(pivot_rate, abs(error) / dt), error)
            else:
                r = max(-turn_rate, min(turn_rate, k_per_s * error))
                current_along = math.cos(psi) * vc_n + math.sin(psi) * vc_e
                demand = (target.speed_mps - current_along) * max(math.cos(error), 0.0)
                demand = 0.0 if stops_at_zero and target.speed_mps == 0.0 else demand
        u += (max(-astern_mps, min(ahead_mps, demand)) - u) * min(1.0, dt / tau_s)
        psi = wrap_pi(psi + r * dt)
        n, e = n + (math.cos(psi) * u + vc_n) * dt, e + (math.sin(psi) * u + vc_e) * dt
        settle(self, (n, e, psi, u, 0.0, r, *self.state[6:]), t, dt)

    monkeypatch.setattr(sim_boat.Boat, "physics_step", physics_step)
