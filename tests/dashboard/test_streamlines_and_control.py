"""Pure parts of the dashboard: the sampled field's interpolation and streamlines, and the signed
control requests (koopguide/bus/streamlines.py, koopguide/bus/control.py)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from koopguide.bus.control import (
    ControlError,
    ControlInbox,
    ReplayGuard,
    check_token,
    control_key,
    decode_control,
    encode_control,
)
from koopguide.bus.streamlines import FieldGrid, FieldGridError, streamlines

TOKEN = "0123456789abcdef-token"


def reply_of(velocity, n: int = 12, heading_deg: float = 0.0, scale: float = 0.1, origin=(0.0, 0.0), goal=None):
    """A field reply like the service's: an n x n grid (model x fastest) rotated by ``heading_deg``."""
    h = math.radians(heading_deg)
    axes = scale * np.array([[math.cos(h), math.sin(h)], [-math.sin(h), math.cos(h)]])
    i, j = np.meshgrid(np.arange(n), np.arange(n))
    positions = np.asarray(origin) + np.stack([i.ravel(), j.ravel()], 1) @ axes
    return {
        "frame": "local_ned",
        "n": n,
        "goal_ned": goal,
        "position_ned": np.round(positions, 4).tolist(),
        "velocity_ned": np.round(velocity(positions), 5).tolist(),
    }


def uniform(positions):
    return np.tile([0.0, 0.2], (len(positions), 1))  # 0.2 m/s toward the east


def rotation(positions, centre=(0.55, 0.55)):
    d = positions - np.asarray(centre)
    return 0.3 * np.stack([-d[:, 1], d[:, 0]], 1)  # counter-clockwise about the centre (N, E)


@given(heading=st.floats(-180, 180), n=st.integers(3, 20))
@settings(max_examples=30, deadline=None)
def test_bilinear_interpolation_is_exact_for_a_linear_field_on_any_rotated_grid(heading, n):
    grid = FieldGrid.from_reply(reply_of(rotation, n=n, heading_deg=heading))
    ij = np.random.default_rng(0).uniform(0, n - 1, size=(50, 2))
    points = grid.origin_ned + ij @ grid.axes_ned
    assert np.allclose(grid.index_of(points), ij, atol=1e-3)
    assert np.allclose(grid.velocity_at(points), rotation(points), atol=2e-4)  # rounding of the reply only
    outside = grid.origin_ned - 0.5 * grid.axes_ned.sum(0)
    assert np.isnan(grid.velocity_at(outside)).all()


def test_streamlines_of_a_uniform_current_are_straight_evenly_spaced_lines_along_it():
    grid = FieldGrid.from_reply(reply_of(uniform))
    lines = streamlines(grid, spacing_m=0.15)
    assert len(lines) >= 5
    for line in lines:
        assert np.ptp(line[:, 0]) < 1e-6  # constant N: straight, eastward
        assert np.all(np.diff(line[:, 1]) > 0)  # ordered along the flow
    norths = np.sort([line[0, 0] for line in lines])
    assert np.diff(norths).min() >= 0.15 - 1e-9  # evenly spaced, never closer than the spacing


def test_streamlines_of_a_rotation_keep_their_radius_and_never_come_closer_than_half_the_spacing():
    centre = np.array([0.55, 0.55])
    grid = FieldGrid.from_reply(reply_of(rotation))
    spacing = 0.12
    lines = streamlines(grid, spacing_m=spacing)
    assert len(lines) >= 3
    for line in lines:
        r = np.hypot(*(line - centre).T)
        assert np.ptp(r) < 0.02  # a circle, within the midpoint rule's error
    for a, la in enumerate(lines):  # Jobard & Lefer: other lines stay at least d_test = spacing / 2 away
        for lb in lines[a + 1 :]:
            d = np.hypot(*(la[:, None, :] - lb[None, :, :]).transpose(2, 0, 1))
            assert d.min() >= 0.5 * spacing - 0.02


def test_streamlines_end_at_the_goal_of_a_converging_field():
    goal = np.array([0.5, 0.5])
    grid = FieldGrid.from_reply(reply_of(lambda p: 0.2 * (goal - p), goal=goal.tolist()))
    lines = streamlines(grid)
    assert any(np.allclose(line[-1], goal) for line in lines)
    for line in lines:  # every line runs toward the goal
        assert np.hypot(*(line[-1] - goal)) < np.hypot(*(line[0] - goal))


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"n": 1}, "'n' must be an integer 2 .. 60"),
        ({"n": True}, "'n' must be an integer"),
        ({"position_ned": [[0, 0]] * 3}, "must have 144 rows of 2 numbers"),
        ({"velocity_ned": [[float("nan"), 0.0]] * 144}, "'velocity_ned' has non-finite values"),
        ({"position_ned": np.random.default_rng(1).uniform(size=(144, 2)).tolist()}, "not a regular grid"),
        ({"position_ned": [[0.0, 0.0]] * 144}, "degenerate"),
        ({"goal_ned": [1.0]}, "'goal_ned' must be [N, E]"),
    ],
)
def test_malformed_field_replies_are_refused_with_the_fault_named(change, message):
    with pytest.raises(FieldGridError, match=message.replace("[", r"\[").replace("]", r"\]")):
        FieldGrid.from_reply({**reply_of(uniform), **change})


# --------------------------------------------------------------------------------- control
def test_a_control_request_round_trips_and_never_carries_the_token():
    payload = encode_control("hold", "boat1", TOKEN, 1000.0, "dashboard@here")
    assert TOKEN.encode() not in payload
    body = json.loads(payload)
    assert set(body) == {"action", "vehicle_id", "t", "nonce", "source", "mac"}
    request = decode_control(payload, TOKEN, "boat1", now=1003.0)
    assert (request.action, request.vehicle_id, request.t, request.source) == (
        "hold",
        "boat1",
        1000.0,
        "dashboard@here",
    )
    assert control_key("boat1") == "koopguide/boat1/control"


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda b: b.update(action="resume"), "wrong MAC"),  # tampered after signing
        (lambda b: b.update(mac="0" * 64), "wrong MAC"),
        (lambda b: b.pop("nonce"), "missing nonce"),
    ],
)
def test_tampered_requests_are_refused(mutate, message):
    body = json.loads(encode_control("hold", "boat1", TOKEN, 1000.0))
    mutate(body)
    with pytest.raises(ControlError, match=message):
        decode_control(json.dumps(body).encode(), TOKEN, "boat1", 1000.0)


def test_wrong_token_wrong_vehicle_stale_replayed_and_garbage_requests_are_refused():
    payload = encode_control("hold", "boat1", TOKEN, 1000.0)
    with pytest.raises(ControlError, match="wrong MAC"):
        decode_control(payload, "another-token-0123456789", "boat1", 1000.0)
    with pytest.raises(ControlError, match="is for 'boat1', not 'boat2'"):
        decode_control(payload, TOKEN, "boat2", 1000.0)
    with pytest.raises(ControlError, match=r"\+11.0 s old"):
        decode_control(payload, TOKEN, "boat1", 1011.0)
    guard = ReplayGuard()
    guard.admit(decode_control(payload, TOKEN, "boat1", 1001.0), 1001.0)
    with pytest.raises(ControlError, match="replay"):
        guard.admit(decode_control(payload, TOKEN, "boat1", 1002.0), 1002.0)
    for garbage, message in ((b"\xff", "not UTF-8 JSON"), (b"[1]", "JSON object"), (b'{"t": NaN}', "NaN")):
        with pytest.raises(ControlError, match=message):
            decode_control(garbage, TOKEN, "boat1", 1000.0)
    with pytest.raises(ControlError, match="action must be one of hold, resume"):
        encode_control("reboot", "boat1", TOKEN, 1000.0)
    with pytest.raises(ValueError, match="at least 16 characters, got 5"):
        check_token(" short \n")


def test_the_service_inbox_accepts_once_and_acknowledges_every_payload():
    inbox = ControlInbox("boat1", TOKEN)
    assert inbox.ack is None
    payload = encode_control("hold", "boat1", TOKEN, 1000.0)
    nonce = json.loads(payload)["nonce"]
    request = inbox.receive(payload, 1000.5)
    assert request is not None and request.action == "hold"
    assert inbox.ack == {"nonce": nonce, "action": "hold", "accepted": True, "reason": None}
    assert inbox.receive(payload, 1001.0) is None  # the same request again: a replay
    assert inbox.ack["nonce"] == nonce and inbox.ack["accepted"] is False and "replay" in inbox.ack["reason"]
    forged = encode_control("resume", "boat1", "not-the-token-0123456789", 1002.0)
    assert inbox.receive(forged, 1002.0) is None
    assert inbox.ack["action"] == "resume" and "wrong MAC" in inbox.ack["reason"]
    assert inbox.receive(b"\x00garbage", 1003.0) is None
    assert inbox.ack == {"nonce": None, "action": None, "accepted": False, "reason": inbox.ack["reason"]}
    assert inbox.refused == 3
    json.dumps(inbox.ack, allow_nan=False)  # fit for the status as it is
