"""The pure parts of the service: frames, the guidance law, the Kalman tracker, the vehicle clock, config."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from koopguide.base.config import ConfigError
from koopguide.guidance import settings
from koopguide.guidance.estimation.clock import ClockVerdict, VehicleClock
from koopguide.guidance.estimation.tracker import KalmanTracker
from koopguide.guidance.law.command import GuidanceLaw, GuidanceState
from koopguide.guidance.law.frames import ModelFrame
from koopguide.model.field import FlowField, load_field


def frame(heading: float = 90.0, goal_ned=(0.0, 0.0), scale: float = 0.04) -> ModelFrame:
    return ModelFrame(goal_model=(0.0, 0.0), goal_ned=goal_ned, scale=scale, heading_deg=heading)


def test_heading_90_puts_model_x_east_and_y_north():
    f = frame(90.0, goal_ned=(10.0, 20.0), scale=2.0)
    np.testing.assert_allclose(f.to_ned([1.0, 0.0]), [10.0, 22.0], atol=1e-12)  # +x -> East
    np.testing.assert_allclose(f.to_ned([0.0, 1.0]), [12.0, 20.0], atol=1e-12)  # +y -> North


@pytest.mark.parametrize("heading", [0.0, 37.0, 90.0, 180.0, 271.5])
def test_frame_round_trip_and_plus_y_is_90_deg_counter_clockwise(heading):
    f = frame(heading, goal_ned=(3.0, -4.0), scale=0.5)
    P = np.random.default_rng(0).normal(size=(20, 2)) * 10
    np.testing.assert_allclose(f.to_model(f.to_ned(P)), P, atol=1e-9)
    ex, ey = f.direction_to_ned([1.0, 0.0]), f.direction_to_ned([0.0, 1.0])
    h, h_y = math.radians(heading), math.radians(heading - 90.0)  # compass headings of +x and +y
    np.testing.assert_allclose(ex, [math.cos(h), math.sin(h)], atol=1e-12)
    np.testing.assert_allclose(ey, [math.cos(h_y), math.sin(h_y)], atol=1e-12)


def guidance_config(**overrides):
    return settings.load(overrides=overrides)


def law_for(model: Path, **overrides) -> GuidanceLaw:
    return GuidanceLaw.from_config(load_field(model), guidance_config(**overrides))


def test_paper_speed_rule_maps_the_domain_maximum_to_max_speed_and_never_exceeds_it(zshape_model):
    law = law_for(
        zshape_model,
        command={"max_speed_mps": 0.3, "min_speed_mps": 0.0, "turn_slowdown": False, "lookahead_m": 0.0},
        arrival={"capture_radius_m": 0.0},
    )
    grid = law.sample_grid(64)
    speeds = np.hypot(*np.asarray(grid["velocity_ned"]).T)
    assert speeds.max() == pytest.approx(0.3, rel=0.02)
    rng = np.random.default_rng(1)
    for p in rng.uniform([-0.5, -2.0], [2.2, 0.5], size=(300, 2)):
        sp = law.decide(p, arrived=False)
        assert np.hypot(*sp.velocity_ned) <= 0.3 + 1e-12
        if sp.state is GuidanceState.GUIDING:  # without extras the command is the scaled field
            np.testing.assert_allclose(sp.velocity_ned, law.field_velocity_ned(p), atol=1e-12)


def test_arrival_outside_domain_geofence_and_turn_slowdown(zshape_model):
    law = law_for(zshape_model, failsafe={"outside_domain": "hold", "geofence_ned": [[-1.0, 3.0], [-3.0, 1.0]]})
    assert law.decide([0.05, 0.05], arrived=False).state is GuidanceState.ARRIVED
    assert law.decide([2.9, -2.9], arrived=False).state is GuidanceState.HOLD  # inside fence, outside domain
    sp = law.decide([5.0, 0.0], arrived=False)
    assert sp.state is GuidanceState.HOLD and "geofence" in sp.reason and not sp.velocity_ned.any()
    p = np.array([1.5, -1.5])
    on_course = law.decide(p, False)
    facing = math.atan2(on_course.velocity_ned[1], on_course.velocity_ned[0])
    aligned = law.decide(p, False, heading_rad=facing)
    away = law.decide(p, False, heading_rad=facing + math.pi)
    assert np.hypot(*aligned.velocity_ned) > 0.1
    assert np.hypot(*away.velocity_ned) == pytest.approx(law.command.min_speed_mps)  # turn first, slowly
    clamp = law_for(zshape_model)
    assert clamp.decide([2.9, -2.9], arrived=False).state is GuidanceState.GUIDING


def test_a_nan_field_is_a_fault_with_zero_velocity(zshape_model):
    law = law_for(zshape_model)
    good = law.field
    law.field = FlowField(
        good.W, good.b, np.full_like(good.A, np.nan), good.B, good.goal, good.goal_centred, good.substeps, good.meta
    )
    sp = law.decide([1.0, -1.0], arrived=False)
    assert sp.state is GuidanceState.FAULT and not sp.velocity_ned.any()


def test_tracker_filters_gates_an_outlier_resets_on_a_jump_and_predicts():
    est = settings.load().estimator
    tracker = KalmanTracker(est)
    rng = np.random.default_rng(0)
    for k in range(50):  # 0.1 m/s north, noisy fixes at 20 Hz
        t = k * 0.05
        tracker.update(t, [0.1 * t + rng.normal(0, 0.01), rng.normal(0, 0.01), 0.1, 0.0])
    p, v = tracker.predict(2.45 + 1.0)
    assert p[0] == pytest.approx(0.1 * 3.45, abs=0.03) and v[0] == pytest.approx(0.1, abs=0.02)
    outlier = tracker.update(2.5, [5.0, 5.0, 0.1, 0.0])
    assert not outlier.accepted
    for k in range(est.reset_after_rejections - 1):
        result = tracker.update(2.55 + 0.05 * k, [5.0, 5.0, 0.0, 0.0])
    assert result.reset and tracker.predict(2.6)[0][0] == pytest.approx(5.0, abs=0.05)
    with pytest.raises(ValueError, match="non-finite"):
        tracker.update(3.0, [np.nan, 0.0, 0.0, 0.0])


def test_vehicle_clock_follows_a_speeded_up_vehicle_and_restarts_on_reboot():
    wall = [0.0]
    clock = VehicleClock(lambda: wall[0])
    for k in range(40):
        wall[0] = k * 0.05
        clock.observe(20.0 * wall[0] + 100.0)  # a simulator at speed-up 20
    assert clock.rate == pytest.approx(20.0)
    wall[0] += 0.1
    assert clock.now() == pytest.approx(20.0 * 1.95 + 100.0 + 2.0)
    # a reboot: time goes back; one stamp is not enough (it could be forged or corrupt), three in a row are
    assert clock.observe(1.0) is ClockVerdict.BEHIND and clock.now() > 100.0
    assert clock.observe(1.05) is ClockVerdict.BEHIND
    assert clock.observe(1.1) is ClockVerdict.REBOOT
    assert clock.reboots == 1 and clock.now() == pytest.approx(1.1)


@pytest.mark.parametrize(
    ("overrides", "expected"),
    [
        ({"command": {"rate_hz": 80.0}}, "command.rate_hz"),
        ({"command": {"max_speed_mps": -1.0}}, "command.max_speed_mps"),
        ({"frame": {"scale": 0}}, "frame.scale"),
        ({"vehicle_id": "boat/1"}, "vehicle_id"),
        ({"arrival": {"on_arrival": "dance"}}, "arrival.on_arrival"),
        ({"failsafe": {"geofence_ned": [[1.0, 0.0], [0.0, 1.0]]}}, "failsafe.geofence_ned"),
        ({"mavlink": {"target_system": 0}}, "mavlink.target_system"),
        ({"status": {"bogus": 1}}, "status.bogus"),
    ],
)
def test_config_errors_name_the_key(overrides, expected):
    with pytest.raises(ConfigError, match=expected.replace(".", r"\.")):
        settings.load(overrides=overrides)
