"""The simulator seen from a ground station on loopback: ArduPilot Rover (boat) behaviour over MAVLink."""

from __future__ import annotations

import itertools
import math
import random
import statistics

from tests.support.sitl_gcs import VELOCITY_MASK, mavlink

GUIDED, HOLD, LOITER, MANUAL = 15, 4, 5, 0
SOUTH_END = {"start_poses": [[0.4, 1.5, 0.0]]}  # room to run north in the 4.5 m tank


def test_heartbeat_identifies_a_disarmed_rover_boat(gcs_and_sim):
    gcs, _ = gcs_and_sim()
    hb = gcs.wait_type("HEARTBEAT")
    assert hb.type == mavlink.MAV_TYPE_SURFACE_BOAT
    assert hb.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert hb.custom_mode == MANUAL
    assert hb.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert not hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    assert hb.get_srcSystem() == 1 and hb.get_srcComponent() == 1
    assert gcs.conn.WIRE_PROTOCOL_VERSION == "2.0" or hb.get_msgbuf()[0] == 0xFD  # MAVLink 2 frame
    # 1 Hz in simulated time
    stamps = []
    gcs.run_for(5.0, lambda m: stamps.append(gcs.t) if m.get_type() == "HEARTBEAT" else None)
    gaps = [b - a for a, b in itertools.pairwise(stamps)]
    assert len(gaps) >= 3 and all(abs(g - 1.0) < 0.15 for g in gaps), gaps


def test_default_streams_and_simulated_timestamps(gcs_and_sim):
    gcs, _ = gcs_and_sim()
    seen: dict[str, object] = {}
    gcs.run_for(3.0, lambda m: seen.setdefault(m.get_type(), m))
    expected = {
        "SYS_STATUS",
        "LOCAL_POSITION_NED",
        "GLOBAL_POSITION_INT",
        "GPS_RAW_INT",
        "ATTITUDE",
        "VFR_HUD",
        "EKF_STATUS_REPORT",
        "SERVO_OUTPUT_RAW",
        "SYSTEM_TIME",
    }
    assert expected <= set(seen), expected - set(seen)
    status = seen["SYS_STATUS"]
    assert status.onboard_control_sensors_health & 0x10000000  # pre-arm checks pass
    assert status.onboard_control_sensors_health & 0x20  # GPS
    gps = seen["GPS_RAW_INT"]
    assert gps.fix_type >= 3
    assert abs(gps.lat / 1e7 - (-35.363261)) < 1e-3  # local NED about the configured origin
    # time_usec and time_boot_ms are simulated time (far below the wall-clock epoch)
    assert gps.time_usec < 10e6
    sys_time = seen["SYSTEM_TIME"]
    assert abs(sys_time.time_unix_usec / 1e6 - 1_700_000_000.0 - sys_time.time_boot_ms / 1e3) < 0.01


def test_stream_rate_requests_change_rates_on_the_link(gcs_and_sim):
    gcs, _ = gcs_and_sim()
    ack = gcs.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 50_000)
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    stamps = []
    gcs.run_for(2.0, lambda m: stamps.append(m.time_boot_ms) if m.get_type() == "LOCAL_POSITION_NED" else None)
    assert 35 <= len(stamps) <= 45  # 20 Hz for 2 s simulated
    gcs.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_EXTRA1, 10, 1)
    # the request has no ack: count from the first two ATTITUDE messages at the new rate (under load, some sent at
    # the old 1 Hz before the simulator read the request were still on their way, and 16 came in the 2 s)
    seen = [gcs.wait_type("ATTITUDE").time_boot_ms]
    for _ in range(5):
        seen.append(gcs.wait_type("ATTITUDE").time_boot_ms)
        if seen[-1] - seen[-2] <= 150:
            break
    assert seen[-1] - seen[-2] <= 150, f"ATTITUDE still every {seen[-1] - seen[-2]} ms after asking for 10 Hz"
    count = []
    gcs.run_for(2.0, lambda m: count.append(1) if m.get_type() == "ATTITUDE" else None)
    assert 17 <= len(count) <= 23


def test_requested_messages_and_parameters(gcs_and_sim):
    gcs, _ = gcs_and_sim()
    ack = gcs.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    version = gcs.wait_type("AUTOPILOT_VERSION")
    assert version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    gcs.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION)
    home = gcs.wait_type("HOME_POSITION")
    assert (home.x, home.y) == (2.25, 1.5)  # the start pose: the tank centre
    assert gcs.command(4242).result == mavlink.MAV_RESULT_UNSUPPORTED

    gcs.mav.param_request_list_send(1, 1)
    params = {}
    gcs.wait(
        lambda m: m.get_type() == "PARAM_VALUE" and params.setdefault(m.param_id, m) and len(params) == m.param_count,
        "all PARAM_VALUEs",
    )
    assert params["GUID_TIMEOUT"].param_value == 3.0
    assert math.isclose(params["WP_SPEED"].param_value, 0.4, rel_tol=1e-6)
    gcs.mav.param_set_send(1, 1, b"WP_SPEED", 0.25, mavlink.MAV_PARAM_TYPE_REAL32)
    value = gcs.wait(lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == "WP_SPEED", "PARAM_VALUE")
    assert math.isclose(value.param_value, 0.25, rel_tol=1e-6)
    gcs.mav.param_request_read_send(1, 1, b"WP_SPEED", -1)
    value = gcs.wait(lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == "WP_SPEED", "PARAM_VALUE")
    assert math.isclose(value.param_value, 0.25, rel_tol=1e-6)


def test_guided_session_tracks_north_times_out_and_disarms(gcs_and_sim):
    gcs, sim = gcs_and_sim(SOUTH_END)
    gcs.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_POSITION, 10, 1)

    # setpoints while disarmed (MANUAL, then GUIDED) move nothing
    for mode in (MANUAL, GUIDED):
        if mode == GUIDED:
            assert gcs.set_mode(GUIDED).result == mavlink.MAV_RESULT_ACCEPTED
        start = gcs.wait_type("LOCAL_POSITION_NED")
        speeds = []

        def keep_sending(m, speeds=speeds):
            if m.get_type() == "LOCAL_POSITION_NED":
                speeds.append(math.hypot(m.vx, m.vy))
                gcs.velocity(0.3, 0.0)

        gcs.run_for(3.0, keep_sending)
        end = gcs.wait_type("LOCAL_POSITION_NED")
        assert math.hypot(end.x - start.x, end.y - start.y) < 0.03
        assert max(speeds) < 0.03
    assert gcs.heartbeat.custom_mode == GUIDED

    # arming is ACKed and shows in the heartbeat
    assert gcs.arm().result == mavlink.MAV_RESULT_ACCEPTED
    hb = gcs.wait_type("HEARTBEAT")
    assert hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED and hb.custom_mode == GUIDED

    # a 0.3 m/s north setpoint, resent at 2 Hz (simulated): tracked within 0.06 m/s once settled
    samples = []
    last_sent = [-1.0]

    def drive(m):
        if gcs.t - last_sent[0] >= 0.5:
            gcs.velocity(0.3, 0.0)
            last_sent[0] = gcs.t
        if m.get_type() == "LOCAL_POSITION_NED":
            samples.append((gcs.t, m.vx, m.vy))

    gcs.run_for(8.0, drive)
    settled = [(vx, vy) for t, vx, vy in samples if t >= samples[0][0] + 3.5]
    errors = [math.hypot(vx - 0.3, vy) for vx, vy in settled]
    assert len(settled) >= 40
    assert max(errors) < 0.06, f"max tracking error {max(errors):.3f} m/s"
    assert abs(statistics.mean(vx for vx, _ in settled) - 0.3) < 0.02

    # acceleration bits: ignored, with a STATUSTEXT; the boat keeps its last valid target
    gcs.velocity(0.0, 0.3, mask=VELOCITY_MASK & ~0x40)  # AX used
    gcs.wait(lambda m: m.get_type() == "STATUSTEXT" and "acceleration" in m.text, "acceleration STATUSTEXT", 3.0)
    pos = gcs.wait_type("LOCAL_POSITION_NED")
    assert pos.vx > 0.24 and abs(pos.vy) < 0.06

    # stop sending: ArduPilot's guided timeout, STATUSTEXT, and the boat stops within 3 s of it
    last_setpoint = last_sent[0]  # the last valid setpoint (the accelerated one did not count)
    text = gcs.wait(lambda m: m.get_type() == "STATUSTEXT" and "target not received" in m.text, "timeout text", 6.0)
    assert text.text == "target not received last 3.0 secs, stopping"
    t_timeout = gcs.t
    assert 2.8 <= t_timeout - last_setpoint <= 3.8, (last_setpoint, t_timeout)
    after = []
    gcs.run_for(6.0, lambda m: after.append((gcs.t - t_timeout, m)) if m.get_type() == "LOCAL_POSITION_NED" else None)
    stopped = [math.hypot(m.vx, m.vy) for dt, m in after if dt >= 3.0]
    assert max(stopped) < 0.05, stopped
    assert gcs.heartbeat.custom_mode == GUIDED  # a boat holds position in GUIDED

    # disarming is ACKed and shows in the heartbeat
    assert gcs.arm(False).result == mavlink.MAV_RESULT_ACCEPTED
    hb = gcs.wait_type("HEARTBEAT")
    assert not hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    assert sim.call(lambda s: s.boat(1).autopilot.commands) == (0.0, 0.0)


def test_body_frame_velocity_with_yaw(gcs_and_sim):
    gcs, _ = gcs_and_sim({"start_poses": [[2.25, 0.5, 90.0]]})  # heading east
    gcs.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_POSITION, 10, 1)
    gcs.set_mode(GUIDED)
    gcs.arm()
    samples = []

    def drive(m):
        gcs.velocity(0.25, 0.0, frame=mavlink.MAV_FRAME_BODY_NED, mask=2535, yaw=0.0)  # velocity + yaw
        if m.get_type() == "LOCAL_POSITION_NED":
            samples.append((m.vx, m.vy))

    gcs.run_for(6.0, drive)
    vx, vy = statistics.mean(s[0] for s in samples[-10:]), statistics.mean(s[1] for s in samples[-10:])
    assert abs(vy - 0.25) < 0.05 and abs(vx) < 0.05  # body-forward while heading east = east


def test_messages_for_another_system_are_ignored(gcs_and_sim):
    gcs, _ = gcs_and_sim()
    gcs.mav.command_long_send(7, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, GUIDED, 0, 0, 0, 0, 0)
    gcs.mav.command_long_send(1, 42, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, GUIDED, 0, 0, 0, 0, 0)
    acks = []
    gcs.run_for(2.0, lambda m: acks.append(m) if m.get_type() == "COMMAND_ACK" else None)
    assert acks == []
    assert gcs.heartbeat.custom_mode == MANUAL
    gcs.mav.set_mode_send(1, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED)  # SET_MODE message
    ack = gcs.wait(lambda m: m.get_type() == "COMMAND_ACK", "SET_MODE ack")
    assert ack.command == mavlink.MAVLINK_MSG_ID_SET_MODE and ack.result == mavlink.MAV_RESULT_ACCEPTED
    assert gcs.wait_type("HEARTBEAT").custom_mode == GUIDED
    assert gcs.set_mode(1).result == mavlink.MAV_RESULT_FAILED  # ACRO is not simulated
    assert any("ACRO" in text for _, text in gcs.statustexts)


def test_loiter_holds_against_a_current_while_hold_drifts(gcs_and_sim):
    current = {"flow": {"kinds": ["uniform"], "uniform": {"speed_mps": 0.1, "direction_deg": 0.0}}}
    tight = {"autopilot": {"params": {"loiter_radius_m": 0.05}}}  # LOIT_RADIUS 5 cm (default 2 m)
    gcs, _ = gcs_and_sim({**current, **tight})
    gcs.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_POSITION, 10, 1)
    assert gcs.set_mode(LOITER).result == mavlink.MAV_RESULT_ACCEPTED
    assert gcs.arm().result == mavlink.MAV_RESULT_ACCEPTED
    start = gcs.wait_type("LOCAL_POSITION_NED")
    offsets = []
    gcs.run_for(
        20.0,
        lambda m: (
            offsets.append(math.hypot(m.x - start.x, m.y - start.y)) if m.get_type() == "LOCAL_POSITION_NED" else None
        ),
    )
    assert max(offsets) < 0.3, f"LOITER wandered {max(offsets):.2f} m"
    assert statistics.mean(offsets[-50:]) < 0.15
    # HOLD: thrusters off, the boat drifts with the 0.1 m/s current
    assert gcs.set_mode(HOLD).result == mavlink.MAV_RESULT_ACCEPTED
    gcs.run_for(6.0)
    drift = [gcs.wait_type("LOCAL_POSITION_NED") for _ in range(5)]
    assert statistics.mean(m.vx for m in drift) > 0.09
    servo = gcs.wait_type("SERVO_OUTPUT_RAW")
    assert servo.servo1_raw == 1500 and servo.servo3_raw == 1500


def test_arming_needs_a_position_estimate(gcs_and_sim):
    gcs, _ = gcs_and_sim({"sensors": {"position": {"dropout_probability": 0.999}}})
    gcs.run_for(2.0)
    status = gcs.wait_type("SYS_STATUS")
    assert not status.onboard_control_sensors_health & 0x10000000
    assert gcs.arm().result == mavlink.MAV_RESULT_FAILED
    assert any("PreArm" in text for _, text in gcs.statustexts)
    assert gcs.set_mode(GUIDED).result == mavlink.MAV_RESULT_FAILED


def test_wall_contact_is_reported(gcs_and_sim):
    records: list[dict] = []
    gcs, _ = gcs_and_sim({"start_poses": [[3.9, 1.5, 0.0]]}, records)
    gcs.set_mode(GUIDED)
    gcs.arm()
    gcs.wait(
        lambda m: (gcs.velocity(0.35, 0.0) or True) and m.get_type() == "STATUSTEXT" and "Wall" in m.text,
        "wall STATUSTEXT",
        8.0,
    )
    pos = gcs.wait_type("LOCAL_POSITION_NED")
    assert 4.2 < pos.x <= 4.31  # stopped at the north wall minus half a hull length
    walls = [r for r in records if r["kind"] == "wall"]
    assert len(walls) == 1 and walls[0]["walls"] == ["north"] and walls[0]["n"] == 4.3


def test_garbage_bytes_are_dropped_and_counted(gcs_and_sim):
    gcs, sim = gcs_and_sim()
    sock = gcs.conn.port
    addr = next(iter(gcs.conn.clients))
    junk = bytes(range(256)) * 4
    for _ in range(5):
        sock.sendto(junk, addr)
    bad_crc = bytearray(gcs.mav.heartbeat_encode(6, 8, 0, 0, 0).pack(gcs.mav))
    bad_crc[-1] ^= 0xFF
    sock.sendto(bytes(bad_crc), addr)
    rng = random.Random(7)  # corrupted copies of real frames: flipped bytes, truncations
    frame = gcs.mav.command_long_encode(1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, HOLD, 0, 0, 0, 0, 0).pack(gcs.mav)
    for k in range(500):
        if k % 50 == 0:
            gcs.run_for(0.2)  # bursts, so the socket buffer never overflows (that would drop frames)
        corrupt = bytearray(frame)
        if rng.random() < 0.5:
            corrupt[rng.randrange(10, len(corrupt))] ^= 1 + rng.randrange(255)
        else:
            corrupt = corrupt[: rng.randrange(1, len(corrupt))]
        sock.sendto(bytes(corrupt), addr)
    ack = gcs.set_mode(GUIDED)  # the link still works
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    stats = sim.call(lambda s: s.links[0].stats)
    assert stats.garbage_bytes >= 5 * len(junk)
    assert stats.corrupt >= 500
    assert gcs.wait_type("HEARTBEAT").custom_mode == GUIDED  # no corrupted HOLD got through


def test_speedup_20_runs_at_least_16x_wall_time(gcs_and_sim):
    import time

    gcs, _ = gcs_and_sim()
    t0_sim, t0_wall = gcs.t, time.monotonic()
    gcs.run_for(40.0)
    ratio = (gcs.t - t0_sim) / (time.monotonic() - t0_wall)
    assert ratio >= 16.0, f"simulated/wall = {ratio:.1f}"


def test_global_int_setpoints_and_command_int(gcs_and_sim):
    records: list[dict] = []
    gcs, _ = gcs_and_sim(SOUTH_END, records)
    gcs.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_POSITION, 10, 1)
    mode = mavlink.MAV_CMD_DO_SET_MODE
    gcs.mav.command_int_send(1, 1, 0, mode, 0, 0, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED, 0, 0, 0, 0, 0)
    ack = gcs.wait(lambda m: m.get_type() == "COMMAND_ACK" and m.command == mode, "COMMAND_INT ack")
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    gcs.arm()
    here = gcs.wait_type("GLOBAL_POSITION_INT")
    # a position 1 m north of the boat, as lat/lon: the boat drives there and holds it
    goal_lat = here.lat + round(1.0 / 111195.0 * 1e7)
    pos_only = 0b110111111000

    def send_goal(m):
        gcs.mav.set_position_target_global_int_send(
            0,
            1,
            1,
            mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
            pos_only,
            goal_lat,
            here.lon,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
        )

    gcs.run_for(1.0, send_goal)
    gcs.run_for(14.0)
    end = gcs.wait_type("LOCAL_POSITION_NED")
    assert abs(end.x - (0.4 + 1.0)) < 0.1 and abs(end.y - 1.5) < 0.1
    assert math.hypot(end.vx, end.vy) < 0.05
    targets = [r["target"] for r in records if r["kind"] == "state" and r["target"]]
    assert targets[-1]["kind"] == "position"
