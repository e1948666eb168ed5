"""An independent rudder boat unlike the simulator's: a kinematic one whose autopilot has no stop controller.

Issue 10's third vehicle ("a rudder boat, which cannot steer without way through the water") as one might build
it from the issue's list of Rover facts alone: its speed loop holds the speed over ground along the heading at
the speed asked, 0 included (no stop controller: asked 0 in a current, it keeps way on and holds its ground,
where Rover's throttle goes off and the boat drifts), its speed through the water following that demand with a
first-order lag ``tau_s`` (at most ``ahead_mps`` ahead, ``astern_mps`` astern); it turns toward the heading
asked at ``k_per_s`` times the error, but never faster than ``|u| / radius_m`` (no turn without way through the
water, a turning circle of ``radius_m`` at any speed); no sway, no hull dynamics. ``astern_mps`` 0 is a thruster
that does not reverse; ``stops_at_zero`` gives it Rover's stop controller after all (asked 0, throttle off: it
drifts). The hull, its lag and how it reads a guided target: tests/support/kinematic_hull.py.
"""

from __future__ import annotations

import pytest

from sitl import boat as sim_boat
from sitl.guided import GuidedTarget
from sitl.sensors import wrap_pi
from tests.support import kinematic_hull


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

    def steer(
        boat: sim_boat.Boat, target: GuidedTarget | None, psi: float, u: float, current_along: float, dt: float
    ) -> tuple[float, float]:
        if target is None:
            return 0.0, 0.0
        turn = abs(u) / radius_m  # no turn without way through the water
        demand = kinematic_hull.speed_demand(target, current_along, stops_at_zero)
        return demand, max(-turn, min(turn, k_per_s * wrap_pi(target.heading_rad - psi)))

    kinematic_hull.install(monkeypatch, steer, tau_s, ahead_mps, astern_mps)
