"""ArduPilot Rover's SET_POSITION_TARGET rules (type_mask, frames), as the autopilot applies them."""

from __future__ import annotations

import math

import pytest

from sitl.autopilot import (
    Frame,
    GuidedTarget,
    Navigation,
    SetpointRejected,
    TargetKind,
    interpret_position_target,
)

NAV = Navigation(t=0.0, n=1.0, e=2.0, vn=0.0, ve=0.0, psi=math.pi / 2, r=0.0, position_ok=True)  # heading east
CAP = 0.4


def target(mask, frame=Frame.LOCAL_NED, pos=(0.0, 0.0), vel=(0.0, 0.0), yaw=0.0, yaw_rate=0.0):
    return interpret_position_target(mask, frame, pos, vel, yaw, yaw_rate, NAV, CAP)


def test_velocity_only_gives_course_and_speed():
    t = target(3559, vel=(0.0, -0.3))  # west
    assert t.kind == TargetKind.HEADING_SPEED
    assert t.heading_rad == pytest.approx(-math.pi / 2) and t.speed_mps == pytest.approx(0.3)


def test_speed_is_capped_at_wp_speed():
    assert target(3559, vel=(1.0, 1.0)).speed_mps == CAP


def test_velocity_and_yaw():
    t = target(2535, vel=(0.2, 0.0), yaw=1.0)
    assert t == GuidedTarget(TargetKind.HEADING_SPEED, speed_mps=pytest.approx(0.2), heading_rad=pytest.approx(1.0))


def test_velocity_and_yaw_rate():
    t = target(1511, vel=(0.1, 0.0), yaw_rate=0.2)
    assert t.kind == TargetKind.TURN_RATE_SPEED and t.turn_rate_radps == 0.2 and t.speed_mps == pytest.approx(0.1)


def test_body_frame_velocity_is_rotated_by_the_heading():
    t = target(3559, frame=Frame.BODY_NED, vel=(0.2, 0.0))  # forward while heading east
    assert t.heading_rad == pytest.approx(math.pi / 2)
    t = target(2535, frame=Frame.BODY_OFFSET_NED, vel=(0.2, 0.0), yaw=0.5)  # yaw relative in body frames
    assert t.heading_rad == pytest.approx(math.pi / 2 + 0.5)


@pytest.mark.parametrize("accel_bit", [0x40, 0x80, 0x100])
def test_any_acceleration_bit_rejects_the_message(accel_bit):
    with pytest.raises(SetpointRejected, match="acceleration"):
        target(3559 & ~accel_bit, vel=(0.3, 0.0))


def test_position_overrides_velocity_and_frames_place_it():
    absolute = target(0b110111111000, pos=(3.0, 1.0), vel=(0.3, 0.0))
    assert absolute.kind == TargetKind.POSITION and (absolute.n, absolute.e) == (3.0, 1.0)
    offset = target(0b110111111000, frame=Frame.LOCAL_OFFSET_NED, pos=(0.5, 0.0))
    assert (offset.n, offset.e) == (1.5, 2.0)
    body = target(0b110111111000, frame=Frame.BODY_OFFSET_NED, pos=(0.5, 0.0))  # 0.5 m ahead = east
    assert (body.n, body.e) == (pytest.approx(1.0), pytest.approx(2.5))


def test_unsupported_frames_and_empty_masks_are_rejected():
    with pytest.raises(SetpointRejected, match="frame"):
        target(3559, frame=Frame.GLOBAL_INT, vel=(0.3, 0.0))
    with pytest.raises(SetpointRejected, match="not supported"):
        target(0xFFF)


def test_zero_velocity_means_north_at_speed_zero_not_the_current_heading():
    t = target(3559, vel=(0.0, 0.0))  # the boat heads east (NAV.psi = 90 deg)
    assert t.kind == TargetKind.HEADING_SPEED and t.speed_mps == 0.0
    assert t.heading_rad == 0.0  # atan2(0, 0) = 0: north, as ArduPilot Rover computes it
    body = target(3559, frame=Frame.BODY_NED, vel=(0.0, 0.0))  # in a body frame it is relative: ahead
    assert body.heading_rad == pytest.approx(math.pi / 2)


def test_velocity_and_yaw_reverses_when_vx_is_negative_and_keeps_the_heading_at_zero():
    astern = target(2535, vel=(-0.2, 0.0), yaw=1.0)
    assert astern.speed_mps == pytest.approx(-0.2) and astern.heading_rad == pytest.approx(1.0)
    assert target(2535, vel=(-1.0, 0.0), yaw=1.0).speed_mps == -CAP  # capped both ways
    hold = target(2535, vel=(0.0, 0.0), yaw=math.pi / 2)  # "speed 0, keep heading east"
    assert hold.speed_mps == 0.0 and hold.heading_rad == pytest.approx(math.pi / 2)
    assert target(3559, vel=(-0.2, 0.0)).speed_mps == pytest.approx(0.2)  # velocity only: always ahead


@pytest.mark.parametrize(
    ("mask", "kwargs"),
    [
        (3559, {"vel": (math.nan, 0.0)}),
        (3559, {"vel": (0.1, math.inf)}),
        (2535, {"vel": (0.1, 0.0), "yaw": math.nan}),
        (1511, {"vel": (0.1, 0.0), "yaw_rate": -math.inf}),
        (0b110111111000, {"pos": (math.nan, 0.0)}),
        (0b110111111000, {"pos": (1e30, 0.0)}),
    ],
)
def test_non_finite_or_far_fields_that_are_used_reject_the_setpoint(mask, kwargs):
    with pytest.raises(SetpointRejected, match=r"not finite|beyond"):
        target(mask, **kwargs)


def test_non_finite_fields_the_mask_ignores_do_not_matter():
    t = target(3559, pos=(math.nan, math.nan), vel=(0.3, 0.0), yaw=math.nan, yaw_rate=math.inf)
    assert t.speed_mps == pytest.approx(0.3) and t.heading_rad == 0.0
