"""Property-based fuzzing of the simulator's MAVLink intake (issue 11): any field values, no crash, no NaN.

Real frames: hypothesis draws COMMAND_LONG, COMMAND_INT, PARAM_SET and SET_POSITION_TARGET_* messages
with arbitrary field values (NaN, inf, huge, negative), a pymavlink encoder packs them into MAVLink 2
frames and the simulator's own decoder parses them, as a link does; each is handled by sitl.inbound
for a real boat, which is then stepped. The link has no socket (nothing is sent anywhere); everything
else is the simulator as it runs.
"""

from __future__ import annotations

import math

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from koopguide.mavlink.endpoint import Endpoint
from koopguide.mavlink.link import Link
from koopguide.mavlink.link_settings import LinkSettings
from koopguide.mavlink.wire import new_decoder
from sitl import inbound
from sitl.recorder import Recorder
from sitl.runner import Simulation
from sitl.telemetry import StreamSchedule, TelemetryWriter, default_intervals
from tests.support.sitl_gcs import sim_config

FLOATS = st.floats(width=32) | st.sampled_from([math.nan, math.inf, -math.inf, 1e30, -1e30, 0.0, 1.0, 15.0])
INT32 = st.integers(-(2**31), 2**31 - 1)
COMMANDS = st.sampled_from(
    [176, 400, 20, 511, 510, 512, 520, 410, 179, 4242]  # served ones and an unknown one
)
PARAM_NAMES = st.sampled_from(["WP_SPEED", "CRUISE_SPEED", "GUID_TIMEOUT", "LOIT_TYPE", "ATC_STR_RAT_MAX", "NOPE"])
MASKS = st.sampled_from([3559, 2535, 1511, 0b110111111000, 0x9F8, 0xDC7, 0xFFF]) | st.integers(0, 0xFFFF)


def messages() -> st.SearchStrategy:
    command_long = st.builds(
        lambda c, p: mavlink.MAVLink_command_long_message(1, 1, c, 0, *p),
        COMMANDS,
        st.tuples(*[FLOATS] * 7),
    )
    command_int = st.builds(
        lambda c, p, x, y, z: mavlink.MAVLink_command_int_message(1, 1, 0, c, 0, 0, *p, x, y, z),
        COMMANDS,
        st.tuples(*[FLOATS] * 4),
        INT32,
        INT32,
        FLOATS,
    )
    param_set = st.builds(
        lambda name, value: mavlink.MAVLink_param_set_message(1, 1, name.encode(), value, 9),
        PARAM_NAMES,
        FLOATS,
    )
    local = st.builds(
        lambda frame, mask, f: mavlink.MAVLink_set_position_target_local_ned_message(0, 1, 1, frame, mask, *f),
        st.sampled_from([1, 7, 8, 9, 5]),
        MASKS,
        st.tuples(*[FLOATS] * 11),
    )
    global_int = st.builds(
        lambda frame, mask, lat, lon, f: mavlink.MAVLink_set_position_target_global_int_message(
            0, 1, 1, frame, mask, lat, lon, *f
        ),
        st.sampled_from([5, 6, 11, 1]),
        MASKS,
        INT32,
        INT32,
        st.tuples(*[FLOATS] * 9),
    )
    return st.one_of(command_long, command_int, param_set, local, global_int)


def socketless_simulation() -> tuple[Simulation, inbound.Channel]:
    """A simulator armed in GUIDED whose one link has no socket (its messages go nowhere)."""
    cfg = sim_config({"autopilot": {"initial_mode": "GUIDED", "start_armed": True}})
    sim = Simulation(cfg, Recorder(None))
    settings = LinkSettings(Endpoint.parse("udpout:127.0.0.1:9"), sources=((1, mavlink.MAV_COMP_ID_AUTOPILOT1),))
    link = Link(settings, sim._on_message)  # never opened: no socket
    sim.links.append(link)
    boat = sim.boat(1)
    writer = TelemetryWriter(boat, link.encoders[1], cfg.origin, 0.0)
    schedule = StreamSchedule(default_intervals(cfg.mavlink.streams), 1.0, sim.t)
    channel = inbound.Channel(boat, link, writer, schedule, cfg.origin, sim._publish)
    sim.channels[(id(link), 1)] = channel
    for _ in range(30):  # a first position fix
        sim.step()
    return sim, channel


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(batch=st.lists(messages(), min_size=1, max_size=8))
def test_any_message_values_leave_the_simulator_running_with_finite_state(batch):
    sim, channel = socketless_simulation()
    sender = mavlink.MAVLink(None, 255, 190)
    decoder = new_decoder()
    for msg in batch:
        frame = msg.pack(sender)
        decoded = decoder.parse_buffer(frame) or []
        assert len(decoded) == 1 and decoded[0].get_type() == msg.get_type()
        inbound.handle(channel, decoded[0])  # must not raise
        for _ in range(5):
            sim.step()
    boat = sim.boat(1)
    assert all(math.isfinite(v) for v in boat.state)
    assert all(math.isfinite(v) and -1.0 <= v <= 1.0 for v in boat.autopilot.commands)
    assert all(math.isfinite(v) for v in boat.autopilot.home)
    params = boat.autopilot.params
    assert 0.0 <= params.get("WP_SPEED") <= 100.0 and params.get("GUID_TIMEOUT") >= 0.1
