"""The pure parts of the intake and of station keeping: the vehicle clock's checks, the vehicle facade
(real pymavlink message objects, no sockets), the PI station keeper's anti-windup and the progress
watchdog. Conventions: NED [m], [m/s]; vehicle and wall times [s]."""

from __future__ import annotations

import math

import numpy as np
import pytest

from koopguide.guidance import events as ev
from koopguide.guidance.estimation.clock import ClockVerdict, VehicleClock
from koopguide.guidance.estimation.progress import ProgressWatchdog
from koopguide.guidance.law.station import LEAK_S, StationKeeper
from koopguide.guidance.vehicle_events import VehicleEvents
from koopguide.mavlink.wire import mavlink


def running_clock(seconds: float = 5.0) -> tuple[VehicleClock, list[float]]:
    """A clock that has seen a real-time vehicle at 20 Hz for ``seconds``; the wall time is in ``wall[0]``."""
    wall = [0.0]
    clock = VehicleClock(lambda: wall[0], window_s=5.0, confirm=3)
    for k in range(round(seconds * 20)):
        wall[0] = k * 0.05
        assert clock.observe(100.0 + wall[0]) in (ClockVerdict.FIRST, ClockVerdict.OK)
    return clock, wall


def test_one_stamp_far_ahead_is_rejected_and_the_clock_runs_on() -> None:
    clock, wall = running_clock()
    wall[0] += 0.05
    assert clock.observe(4_000_000.0) is ClockVerdict.AHEAD  # time_boot_ms = 4e9
    assert clock.now() == pytest.approx(100.0 + wall[0], abs=0.06)
    wall[0] += 0.05
    assert clock.observe(100.0 + wall[0]) is ClockVerdict.OK
    assert clock.jumps == 0 and clock.reboots == 0


def test_a_jump_confirmed_by_three_stamps_restarts_the_clock() -> None:
    clock, wall = running_clock()
    verdicts = []
    for k in range(3):
        wall[0] += 0.05
        verdicts.append(clock.observe(5000.0 + 0.05 * k))
    assert verdicts == [ClockVerdict.AHEAD, ClockVerdict.AHEAD, ClockVerdict.JUMP]
    assert clock.jumps == 1 and clock.now() == pytest.approx(5000.1)
    wall[0] += 0.05
    assert clock.observe(5000.15) is ClockVerdict.OK


def test_a_late_message_keeps_the_clock_monotonic() -> None:
    clock, _ = running_clock()
    t = clock.now()
    assert clock.observe(t - 0.3) is ClockVerdict.LATE and clock.now() >= t


def message(kind: str, *fields):
    return getattr(mavlink, f"MAVLink_{kind}_message")(*fields)


def test_the_facade_decodes_units_and_turns_clock_trouble_into_events() -> None:
    wall = [7.0]  # the facade is given each message's arrival time; the clock reads the same clock
    clock = VehicleClock(lambda: wall[0], window_s=5.0, confirm=3)
    facade = VehicleEvents(clock)
    (fix,) = facade.decode(message("local_position_ned", 12_500, 1.0, -2.0, 0.0, 0.1, 0.2, 0.0), 7.0)
    assert fix == ev.PositionFix(7.0, 12.5, (1.0, -2.0), (pytest.approx(0.1), pytest.approx(0.2)))
    (glob,) = facade.decode(message("global_position_int", 12_520, 470_000_000, 80_000_000, 0, 0, 0, 0, 0, 0), 7.0)
    assert glob.lat_deg == pytest.approx(47.0) and glob.lon_deg == pytest.approx(8.0) and glob.t_s == 12.52
    wall[0] = 7.1
    hb = message("heartbeat", 11, 3, mavlink.MAV_MODE_FLAG_SAFETY_ARMED | 1, 15, 4, 3)
    assert facade.decode(hb, 7.1) == [ev.Heartbeat(7.1, 15, True)]
    (rejected,) = facade.decode(message("attitude", 4_000_000_000, 0, 0, 0.5, 0, 0, 0.1), 7.1)
    assert isinstance(rejected, ev.InputRejected) and rejected.kind == "timestamp" and "4000000000" in rejected.detail
    # a reboot: the third stamp in a row from the new clock restarts it, before its own event
    wall[0] = 7.2
    out = [facade.decode(message("attitude", 200 + 50 * k, 0, 0, 0.5, 0, 0, 0.1), 7.2) for k in range(3)]
    assert [type(e) for e in out[0] + out[1]] == [ev.InputRejected, ev.InputRejected]
    restart, attitude = out[2]
    assert restart == ev.ClockRestart(7.2, 0.3, pytest.approx(12.52 + 0.2), rebooted=True)  # ran on 0.2 s
    assert attitude == ev.Attitude(7.2, 0.3, pytest.approx(0.5), pytest.approx(0.1))
    assert facade.decode(message("command_ack", 176, 4), 7.3) == []
    assert "refused command 176" in facade.take_notes()[0].text


def test_the_integral_is_clamped_and_does_not_wind_up_while_the_output_saturates() -> None:
    keeper = StationKeeper(kp_per_s=0.5, ki_per_s2=0.1, integral_limit_mps=0.05, max_speed_mps=0.3, deadband_m=0.15)
    for k in range(400):  # 20 s, 1 m off: the proportional term alone saturates the output
        v = keeper.update(k * 0.05, np.array([0.0, 1.0]))
        assert math.hypot(*v) <= 0.3 + 1e-12
    assert np.allclose(keeper.integral, 0.0)  # nothing integrated while saturated toward the error
    for k in range(400, 1600):  # 0.3 m off (not saturated): integrates the 0.15 m beyond the dead band
        keeper.update(k * 0.05, np.array([0.0, 0.3]))
    assert math.hypot(*keeper.integral) == pytest.approx(0.05)  # clamped at the limit
    t = 80.0
    keeper.update(t, np.array([0.0, 0.1]))  # inside the dead band: it leaks away
    keeper.update(t + LEAK_S, np.array([0.0, 0.1]))
    # two steps: 0.05 s, then a gap integrated as MAX_STEP_S (0.5 s)
    assert math.hypot(*keeper.integral) == pytest.approx(0.05 * math.exp(-0.55 / LEAK_S), rel=1e-6)
    for k in range(1, 61 * 20):
        keeper.update(t + LEAK_S + k * 0.05, np.array([0.0, 0.1]))
    assert math.hypot(*keeper.integral) < 0.05 * math.exp(-1.5)


def test_direct_pursuit_adds_the_integral_without_growing_it() -> None:
    """From afar the error is the way still to go, not a bias: integrated, it wound up and the boat overshot."""
    keeper = StationKeeper(kp_per_s=0.5, ki_per_s2=0.1, integral_limit_mps=0.1, max_speed_mps=0.3, deadband_m=0.15)
    keeper.integral = np.array([0.01, 0.0])  # a bias learnt while holding
    for k in range(200):  # 10 s of pursuit 0.5 m off
        v = keeper.update(k * 0.05, np.array([0.0, 0.5]), integrate=False)
    np.testing.assert_array_equal(keeper.integral, [0.01, 0.0])  # kept, not grown
    np.testing.assert_allclose(v, [0.01, 0.25])  # P + the bias as it was
    keeper.update(10.05, np.array([0.0, 0.5]))  # holding again: it integrates
    assert keeper.integral[1] > 0.0


def test_the_progress_watchdog_forgives_an_overshoot_but_not_a_stall() -> None:
    watch = ProgressWatchdog(stall_s=10.0, stall_progress_m=0.05)
    goal, p, t = np.array([0.0, 0.0]), np.array([0.0, -3.0]), 0.0
    east = np.array([0.0, 1.0])
    for _ in range(100):  # 10 s along the field toward the goal at 0.2 m/s
        t += 0.1
        p = p + east * 0.02
        assert not watch.update(t, p, east * 0.2, float(np.hypot(*(goal - p))))
    for _ in range(120):  # overshooting a turn: the field now points north, the boat still goes east ...
        t += 0.1
        p = p + east * 0.01
        assert not watch.update(t, p, np.array([0.2, 0.0]), float(np.hypot(*(goal - p))))  # ... yet nears the goal
    stalled = [watch.update(t + 0.1 * k, p, np.array([0.2, 0.0]), float(np.hypot(*(goal - p)))) for k in range(1, 121)]
    assert not stalled[0] and stalled[-1]  # standing still: stalled once stall_s passed without progress
    assert stalled.index(True) == pytest.approx(100 - 20, abs=25)
