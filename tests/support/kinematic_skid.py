"""An independent differential-thrust boat unlike the simulator's: a kinematic one that pivots in GUIDED.

Issue 10's second vehicle ("a differential-thrust boat with ArduPilot's semantics: heading plus speed over ground,
pivot turns") as one might build it from the issue's list of Rover facts alone, taking "skid-steer vehicles pivot
when the heading error exceeds WP_PIVOT_ANGLE" to hold for guided velocity targets too (the simulator follows
Rover's source, where only waypoint navigation pivots): beyond ``pivot_deg`` off the heading asked it stops
driving and turns in place at ``pivot_rate_dps`` until within ``pivot_exit_deg``; otherwise it turns at
``k_per_s`` times the error (at most ``turn_rate_dps``) while its speed loop holds the speed over ground along the
heading at the speed asked, scaled by the cosine of the heading error (skid steering slows while turning). Asked 0
it holds its ground along its heading (no stop controller) or, with ``stops_at_zero``, lets the water carry it
(Rover's stop controller). The hull, its lag ``tau_s`` (at most ``ahead_mps`` ahead, ``astern_mps`` astern) and how
it reads a guided target: tests/support/kinematic_hull.py.
"""

from __future__ import annotations

import math

import pytest

from sitl import boat as sim_boat
from sitl.guided import GuidedTarget
from sitl.sensors import wrap_pi
from tests.support import kinematic_hull


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

    def steer(
        boat: sim_boat.Boat, target: GuidedTarget | None, psi: float, u: float, current_along: float, dt: float
    ) -> tuple[float, float]:
        if target is None:
            pivoting[boat.sysid] = False
            return 0.0, 0.0
        error = wrap_pi(target.heading_rad - psi)
        pivoting[boat.sysid] = abs(error) > (pivot_exit if pivoting.get(boat.sysid, False) else pivot)
        if pivoting[boat.sysid]:  # throttle off, turning in place
            return 0.0, math.copysign(min(pivot_rate, abs(error) / dt), error)
        demand = kinematic_hull.speed_demand(target, current_along, stops_at_zero)
        return demand * max(math.cos(error), 0.0), max(-turn_rate, min(turn_rate, k_per_s * error))

    kinematic_hull.install(monkeypatch, steer, tau_s, ahead_mps, astern_mps)
