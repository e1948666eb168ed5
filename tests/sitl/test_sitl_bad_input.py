"""Issue 11: the simulator cannot be crashed or driven into a wall by a bad command (real sockets on loopback).

Every case of the issue's table that concerns the simulator: DO_SET_HOME with NaN or 1e30; PARAM_SET
CRUISE_SPEED 0 and then a setpoint; NaN velocity or position setpoints; WP_SPEED -5; NaN in DO_SET_MODE
or SET_MESSAGE_INTERVAL over TCP (the connection stays open). Plus a sweep of NaN/inf/1e30 through every
parameter of every command the simulator serves, and a property test of the setpoint rules.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sitl.autopilot import SUPPORTED_MODES, Frame, Navigation, SetpointRejected, interpret_position_target
from sitl.runner import SimulationThread
from tests.support.sitl_gcs import GCS_COMPONENT, GCS_SYSTEM, Gcs, mavlink, mavutil, sim_config

GUIDED, MANUAL = 15, 0
NAN, INF = float("nan"), float("inf")
SOUTH_END = {"start_poses": [[0.4, 1.5, 0.0]]}  # room to run north in the 4.5 m tank
POSITION_MASK = 0b110111111000
DENIED = mavlink.MAV_RESULT_DENIED
FAILED = mavlink.MAV_RESULT_FAILED


def guided_and_armed(gcs: Gcs) -> None:
    gcs.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_POSITION, 10, 1)
    gcs.wait_type("LOCAL_POSITION_NED")  # a position fix first: GUIDED needs one
    assert gcs.set_mode(GUIDED).result == mavlink.MAV_RESULT_ACCEPTED
    assert gcs.arm().result == mavlink.MAV_RESULT_ACCEPTED


def drive(gcs: Gcs, seconds: float, send) -> list:
    """Call ``send()`` every 0.2 s simulated for ``seconds``; the LOCAL_POSITION_NEDs seen meanwhile."""
    positions = []
    last = [-1.0]

    def each(m):
        if gcs.t - last[0] >= 0.2:
            send()
            last[0] = gcs.t
        if m.get_type() == "LOCAL_POSITION_NED":
            positions.append(m)

    gcs.run_for(seconds, each)
    return positions


def home(gcs: Gcs):
    gcs.command(mavlink.MAV_CMD_GET_HOME_POSITION)
    return gcs.wait_type("HOME_POSITION")


def param(gcs: Gcs, name: str, value: float | None = None) -> float:
    """Set (if value given) or read a parameter; the PARAM_VALUE the boat answers with."""
    if value is None:
        gcs.mav.param_request_read_send(1, 1, name.encode(), -1)
    else:
        gcs.mav.param_set_send(1, 1, name.encode(), value, mavlink.MAV_PARAM_TYPE_REAL32)
    reply = gcs.wait(lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == name, f"PARAM_VALUE {name}")
    return reply.param_value


def test_do_set_home_with_nan_or_1e30_is_refused_and_home_stays(gcs_and_sim):
    gcs, sim = gcs_and_sim()
    before = home(gcs)
    for lat, lon in ((NAN, 149.0), (-35.0, NAN), (1e30, 149.0), (-35.0, 1e30), (INF, -INF)):
        ack = gcs.command(mavlink.MAV_CMD_DO_SET_HOME, 0, 0, 0, 0, lat, lon, 0)
        assert ack.result == DENIED, (lat, lon)
    ack = gcs.command(mavlink.MAV_CMD_DO_SET_HOME, NAN)  # param1 (use current position) NaN
    assert ack.result == DENIED
    ack = gcs.command(mavlink.MAV_CMD_DO_SET_HOME, 0, 0, 0, 0, 0.0, 0.0, 0)  # valid, but 4000 km away
    assert ack.result == FAILED
    mode = mavlink.MAV_CMD_DO_SET_HOME  # COMMAND_INT: latitude 214 deg as degE7
    gcs.mav.command_int_send(1, 1, 0, mode, 0, 0, 0, 0, 0, 0, 2_140_000_000, 1_490_000_000, 0)
    assert gcs.wait(lambda m: m.get_type() == "COMMAND_ACK" and m.command == mode, "ack").result == DENIED
    after = home(gcs)
    assert (after.latitude, after.longitude, after.x, after.y) == (
        before.latitude,
        before.longitude,
        before.x,
        before.y,
    )
    assert sim.call(lambda s: s.boat(1).autopilot.home) == (2.25, 1.5)
    t = gcs.t
    gcs.wait_type("HEARTBEAT")  # still running
    assert gcs.t >= t


def test_cruise_speed_zero_is_harmless_and_a_setpoint_still_drives(gcs_and_sim):
    gcs, sim = gcs_and_sim(SOUTH_END)
    assert param(gcs, "CRUISE_SPEED", 0.0) == 0.0  # accepted: ArduPilot's range starts at 0 (no feed-forward)
    guided_and_armed(gcs)
    positions = drive(gcs, 8.0, lambda: gcs.velocity(0.3, 0.0))
    settled = positions[-15:]
    assert min(p.vx for p in positions) > -0.02  # never astern
    assert sum(p.vx for p in settled) / len(settled) == pytest.approx(0.3, abs=0.03)
    assert sim.call(lambda s: s.boat(1).autopilot.mode) == GUIDED


@pytest.mark.parametrize(
    "bad",
    [
        {"velocity": (NAN, 0.0)},
        {"velocity": (0.0, INF)},
        {"velocity": (NAN, NAN), "mask": 2535, "yaw": 0.0},
        {"velocity": (0.2, 0.0), "mask": 2535, "yaw": NAN},
        {"position": (NAN, 1.5)},
        {"position": (1e30, 1.5)},
    ],
    ids=["vx-nan", "vy-inf", "vel-yaw-nan", "yaw-nan", "position-nan", "position-1e30"],
)
def test_nan_setpoints_are_ignored_never_full_astern(gcs_and_sim, bad):
    gcs, _ = gcs_and_sim(SOUTH_END)
    guided_and_armed(gcs)

    def send_bad():
        mask = bad.get("mask", POSITION_MASK if "position" in bad else 3559)
        x, y = bad.get("position", (0.0, 0.0))
        vx, vy = bad.get("velocity", (0.0, 0.0))
        gcs.mav.set_position_target_local_ned_send(
            round(gcs.t * 1000), 1, 1, 1, mask, x, y, 0, vx, vy, 0, 0, 0, 0, bad.get("yaw", 0.0), 0
        )

    # the bad setpoint alone: nothing moves
    start = gcs.wait_type("LOCAL_POSITION_NED")
    positions = drive(gcs, 3.0, send_bad)
    assert max(math.hypot(p.vx, p.vy) for p in positions) < 0.03
    assert math.hypot(positions[-1].x - start.x, positions[-1].y - start.y) < 0.03
    assert any("not finite" in text or "beyond" in text for _, text in gcs.statustexts)
    # while driving north at 0.3 m/s: the bad setpoints change nothing, the last good one stays in force
    drive(gcs, 5.0, lambda: gcs.velocity(0.3, 0.0))
    positions = drive(gcs, 2.5, send_bad)  # within GUID_TIMEOUT of the last good setpoint
    assert min(p.vx for p in positions) > 0.25
    assert max(abs(p.vy) for p in positions) < 0.05


def test_wp_speed_minus_5_is_refused_and_the_boat_never_goes_astern(gcs_and_sim):
    gcs, _ = gcs_and_sim(SOUTH_END)
    assert param(gcs, "WP_SPEED", -5.0) == pytest.approx(0.4)  # refused: the value in force comes back
    assert any("WP_SPEED" in text and "refused" in text for _, text in gcs.statustexts)
    for value in (NAN, INF, 1e30):
        assert param(gcs, "WP_SPEED", value) == pytest.approx(0.4)
    assert param(gcs, "CRUISE_SPEED", -1.0) == pytest.approx(0.2)
    assert param(gcs, "LOIT_TYPE", 1.5) == 0.0  # an enumeration: whole numbers only
    assert param(gcs, "GUID_TIMEOUT", 0.0) == 3.0
    guided_and_armed(gcs)
    positions = drive(gcs, 8.0, lambda: gcs.velocity(1.0, 0.0))  # capped at WP_SPEED 0.4
    assert min(p.vx for p in positions) > -0.02
    assert max(p.vx for p in positions) < 0.43


@pytest.fixture
def tcp_gcs() -> Iterator[tuple[Gcs, SimulationThread]]:
    """A simulator serving tcpin on a free loopback port, and a pymavlink TCP client on it."""
    cfg = sim_config({"mavlink": {"endpoints": ["tcpin:127.0.0.1:0"]}})
    sim = SimulationThread(cfg)
    with sim:
        address = sim.addresses()[1][0]
        port = int(address.rsplit(":", 1)[1])
        conn = mavutil.mavlink_connection(
            f"tcp:127.0.0.1:{port}", source_system=GCS_SYSTEM, source_component=GCS_COMPONENT
        )
        try:
            gcs = Gcs(conn)
            gcs.wait_type("HEARTBEAT", sim_timeout=3.0)
            yield gcs, sim
        finally:
            conn.close()


def test_nan_in_do_set_mode_or_set_message_interval_is_denied_and_tcp_stays_open(tcp_gcs):
    gcs, sim = tcp_gcs
    set_mode, interval = mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL
    position = mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED
    for params in ((NAN, GUIDED), (1.0, NAN), (INF, GUIDED), (1.0, 1e30), (1.0, 15.5)):
        assert gcs.command(set_mode, *params).result == DENIED, params
    for params in ((NAN, 50_000), (position, NAN), (position, -INF), (1e30, 50_000), (position, -7.0)):
        assert gcs.command(interval, *params).result == DENIED, params
    assert gcs.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, NAN).result == DENIED
    assert gcs.command(mavlink.MAV_CMD_REQUEST_MESSAGE, NAN).result == DENIED
    # the same connection still works, and nothing changed
    assert len(sim.call(lambda s: s.links[0].peers)) == 1  # the one TCP client is still connected
    assert gcs.wait_type("HEARTBEAT").custom_mode == MANUAL
    assert gcs.command(interval, position, 100_000).result == mavlink.MAV_RESULT_ACCEPTED
    stamps = []
    gcs.run_for(2.0, lambda m: stamps.append(1) if m.get_type() == "LOCAL_POSITION_NED" else None)
    assert 17 <= len(stamps) <= 23  # 10 Hz, as asked once the request was valid
    assert gcs.set_mode(GUIDED).result == mavlink.MAV_RESULT_ACCEPTED


SERVED_COMMANDS = (
    mavlink.MAV_CMD_DO_SET_MODE,
    mavlink.MAV_CMD_COMPONENT_ARM_DISARM,
    mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH,
    mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
    mavlink.MAV_CMD_GET_MESSAGE_INTERVAL,
    mavlink.MAV_CMD_REQUEST_MESSAGE,
    mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
    mavlink.MAV_CMD_GET_HOME_POSITION,
    mavlink.MAV_CMD_DO_SET_HOME,
)


def test_every_command_with_nan_inf_or_1e30_in_any_parameter_is_answered_and_changes_no_mode(gcs_and_sim):
    gcs, sim = gcs_and_sim()
    results = set()
    for command in SERVED_COMMANDS:
        for index in range(7):
            for bad in (NAN, INF, 1e30):
                params = [1.0, float(GUIDED), 0.0, 0.0, -35.36, 149.17, 0.0]
                params[index] = bad
                ack = gcs.command(command, *params)  # raises if no ACK comes
                results.add(ack.result)
    assert results <= {mavlink.MAV_RESULT_ACCEPTED, DENIED, FAILED, mavlink.MAV_RESULT_UNSUPPORTED}
    assert DENIED in results
    mode, home_ned = sim.call(lambda s: (s.boat(1).autopilot.mode, s.boat(1).autopilot.home))
    assert mode in SUPPORTED_MODES and all(math.isfinite(v) for v in home_ned)
    assert math.hypot(home_ned[0] - 2.25, home_ned[1] - 1.5) < 0.5  # only "home = here" was accepted
    assert gcs.wait_type("HEARTBEAT").custom_mode == mode  # still running


NAV = Navigation(t=0.0, n=1.0, e=2.0, vn=0.0, ve=0.0, psi=0.7, r=0.0, position_ok=True)
ANY_FLOAT = st.floats(allow_nan=True, allow_infinity=True, width=32)


@given(
    mask=st.integers(0, 0xFFFF),
    frame=st.sampled_from(list(Frame)),
    position=st.tuples(ANY_FLOAT, ANY_FLOAT),
    velocity=st.tuples(ANY_FLOAT, ANY_FLOAT),
    yaw=ANY_FLOAT,
    yaw_rate=ANY_FLOAT,
)
def test_a_setpoint_is_finite_and_within_wp_speed_or_it_is_rejected(mask, frame, position, velocity, yaw, yaw_rate):
    try:
        target = interpret_position_target(mask, frame, position, velocity, yaw, yaw_rate, NAV, 0.4)
    except SetpointRejected:
        return
    assert target.is_finite()
    assert abs(target.speed_mps) <= 0.4
    assert -math.pi <= target.heading_rad <= math.pi
