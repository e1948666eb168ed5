"""The independent skid-steer boat the missions are also flown on (tests/support/kinematic_skid.py) is what it says:
asked a heading beyond its pivot angle it turns in place, then drives; asked speed 0 in a current it holds its
ground, or drifts with the stop controller. Socket-free: one boat in open water, stepped by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from koopguide.mavlink.rover import MASK_VELOCITY, MASK_VELOCITY_YAW
from tests.support import kinematic_skid
from tests.support.open_water import current, fly, make_boat


def test_asked_a_heading_beyond_its_pivot_angle_it_turns_in_place_then_drives(monkeypatch: pytest.MonkeyPatch) -> None:
    kinematic_skid.install(monkeypatch, pivot_rate_dps=45.0)
    boat, flow = make_boat("diff_thrust")  # still water, bow north
    run = fly(boat, flow, 6.0, mask=MASK_VELOCITY, velocity=(0.0, 0.2))  # east, 90 deg off
    t, n, e, psi = run[:, 0] - run[0, 0], run[:, 1], run[:, 2], run[:, 3]
    pivot = t < 1.6  # 80 deg at 45 deg/s: within 10 deg of east after 1.8 s
    assert float(np.max(np.hypot(n[pivot] - n[0], e[pivot] - e[0]))) < 0.005  # no way while it pivots
    assert abs(math.degrees(psi[-1]) - 90.0) < 2.0
    speed = np.hypot(run[-50:, 4], run[-50:, 5])
    assert float(np.min(speed)) > 0.19  # then it drives at the speed asked


@pytest.mark.parametrize("stops_at_zero", [False, True])
def test_asked_speed_0_in_a_current_it_holds_its_ground_unless_it_has_a_stop_controller(
    monkeypatch: pytest.MonkeyPatch, stops_at_zero: bool
) -> None:
    kinematic_skid.install(monkeypatch, stops_at_zero=stops_at_zero)
    boat, flow = make_boat("diff_thrust", overrides=current(0.03, 180.0))  # toward S, the bow N
    fly(boat, flow, 4.0, mask=MASK_VELOCITY_YAW, velocity=(0.1, 0.0), yaw=0.0)
    run = fly(boat, flow, 20.0, mask=MASK_VELOCITY_YAW, velocity=(0.0, 0.0), yaw=0.0)
    drift = float(run[-1, 1] - run[500, 1])  # N over the last 15 s [m]
    if stops_at_zero:
        assert drift == pytest.approx(-0.45, abs=0.03)  # the water's 0.03 m/s
    else:
        assert abs(drift) < 0.01
