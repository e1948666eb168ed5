"""What a boat does with the MAVLink messages it receives, and how it answers (like ArduPilot Rover).

A ``Channel`` is one boat on one link: replies (COMMAND_ACK, PARAM_VALUE, requested messages) go back
on the channel a request came in on. Messages addressed to another system (target_system not 0 and not
this boat) or another component are ignored. Setpoints are honoured only in GUIDED while armed.

Nothing a client sends can crash the simulator or drive a boat by accident: every command parameter
the simulator reads is checked against its MAVLink range first (NaN, inf, fractions where a whole
number is meant, out of range -> COMMAND_ACK DENIED and nothing changes); PARAM_SET outside a
parameter's range (sitl.parameters) changes nothing; a setpoint with a NaN/inf in a field it uses, or
an impossible position, is ignored (sitl.guided). Should a handler still meet a value it cannot use,
the command is answered FAILED and the link stays open.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from koopguide.base.geodesy import geodetic_to_ned
from koopguide.mavlink.wire import mavlink
from sitl.autopilot import (
    MODE_NUMBERS,
    Frame,
    MavResult,
    SetpointRejected,
    Severity,
    interpret_position_target,
)
from sitl.boat import Boat
from sitl.config import OriginConfig
from sitl.guided import POS_IGNORE
from sitl.mavlink_endpoint import Link
from sitl.parameters import PARAMS
from sitl.telemetry import StreamSchedule, TelemetryWriter

log = logging.getLogger(__name__)

FORCE_ARM_MAGIC = 21196  # MAV_CMD_COMPONENT_ARM_DISARM param2 that skips pre-arm checks
MAX_MESSAGE_ID = (1 << 24) - 1  # MAVLink 2 message ids are 24 bits
MAX_INTERVAL_US = 1e9  # SET_MESSAGE_INTERVAL: at most one message per 1000 s [us]
REJECTION_TEXT_INTERVAL_S = 1.0  # at most one "setpoint ignored" STATUSTEXT per second per boat
GLOBAL_INT_FRAMES = frozenset({Frame.GLOBAL_INT, Frame.GLOBAL_RELATIVE_ALT_INT, Frame.GLOBAL_TERRAIN_ALT_INT})


@dataclass
class Channel:
    boat: Boat
    link: Link
    writer: TelemetryWriter
    schedule: StreamSchedule
    origin: OriginConfig
    publish: Callable[[], None]  # sends queued STATUSTEXTs on all links (they precede an ACK)
    last_rejection_text_t: float = field(default=-math.inf)

    def send_due(self) -> None:
        """Send this link's messages that are due now (simulated time)."""
        for msg_id in self.schedule.due(self.boat.t):
            self.writer.senders[msg_id]()


def addressed_to(msg: Any, sysid: int) -> bool:
    """True unless the message names another system or a component other than the autopilot."""
    target_system = getattr(msg, "target_system", 0)
    if target_system not in (0, sysid):
        return False
    return getattr(msg, "target_component", 0) in (0, mavlink.MAV_COMP_ID_AUTOPILOT1)


def handle(channel: Channel, msg: Any) -> None:
    """Act on one decoded message for this channel's boat."""
    if not addressed_to(msg, channel.boat.sysid):
        return
    handler = HANDLERS.get(msg.get_type())
    if handler is not None:
        handler(channel, msg)


# ---- commands ----------------------------------------------------------------------------------------
def _command(channel: Channel, msg: Any) -> None:
    boat = channel.boat
    command = msg.command
    try:
        result = _run_command(channel, command, msg)
    except CommandDenied as exc:
        log.debug("boat %d: command %d denied: %s", boat.sysid, command, exc)
        result = MavResult.DENIED
    except (ValueError, ArithmeticError) as exc:  # a value no check foresaw: refuse it, keep running
        log.warning("boat %d: command %d failed: %s", boat.sysid, command, exc)
        result = MavResult.FAILED
    channel.publish()
    channel.writer.mav.command_ack_send(command, int(result), 0, 0, msg.get_srcSystem(), msg.get_srcComponent())
    # requested messages go out after the ACK, as ArduPilot does
    if result == MavResult.ACCEPTED:
        requested = _requested_message(command, msg)
        if requested is not None:
            channel.writer.senders[requested]()
    log.debug("boat %d: command %d -> %s", boat.sysid, command, MavResult(result).name)


class CommandDenied(ValueError):
    """A command parameter outside its MAVLink range; the text names it and the value seen."""


def _whole(value: float, low: float, high: float, what: str) -> int:
    """``value`` as an int if it is a whole number in [low, high], else CommandDenied."""
    if not (math.isfinite(value) and value == round(value) and low <= value <= high):
        raise CommandDenied(f"{what} must be a whole number in [{low:g}, {high:g}], got {value!r}")
    return int(value)


def _finite(value: float, low: float, high: float, what: str) -> float:
    if not (math.isfinite(value) and low <= value <= high):
        raise CommandDenied(f"{what} must be in [{low:g}, {high:g}], got {value!r}")
    return value


def _requested_message(command: int, msg: Any) -> int | None:
    if command == mavlink.MAV_CMD_REQUEST_MESSAGE:
        return _whole(msg.param1, 0, MAX_MESSAGE_ID, "param1 (message id)")
    if command == mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
        return mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION
    if command == mavlink.MAV_CMD_GET_HOME_POSITION:
        return mavlink.MAVLINK_MSG_ID_HOME_POSITION
    return None


def _run_command(channel: Channel, command: int, msg: Any) -> MavResult:
    """Run one command; raises CommandDenied for a parameter outside its range (nothing changed)."""
    boat = channel.boat
    ap = boat.autopilot
    nav = boat.navigation()
    if command == mavlink.MAV_CMD_DO_SET_MODE:
        base_mode = _whole(msg.param1, 0, 255, "param1 (base mode)")
        custom_mode = _whole(msg.param2, 0, 0xFFFFFFFF, "param2 (custom mode)")
        if not base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return MavResult.UNSUPPORTED
        return ap.set_mode(custom_mode, nav)
    if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
        arm = _whole(msg.param1, 0, 1, "param1 (arm)")
        return ap.arm(arm == 1, msg.param2 == FORCE_ARM_MAGIC, nav)
    if command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
        return ap.set_mode(MODE_NUMBERS["RTL"], nav)
    if command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
        msg_id = _whole(msg.param1, 0, MAX_MESSAGE_ID, "param1 (message id)")
        interval_us = _finite(msg.param2, -1.0, MAX_INTERVAL_US, "param2 (interval, us)")
        if -1.0 < interval_us < 0.0:
            raise CommandDenied(f"param2 (interval, us) must be -1, 0 or positive, got {interval_us!r}")
        if msg_id not in channel.writer.senders:
            return MavResult.UNSUPPORTED
        interval = None if interval_us == 0 else (0.0 if interval_us < 0 else interval_us / 1e6)
        channel.schedule.set_interval(msg_id, interval, boat.t)
        return MavResult.ACCEPTED
    if command == mavlink.MAV_CMD_GET_MESSAGE_INTERVAL:
        msg_id = _whole(msg.param1, 0, MAX_MESSAGE_ID, "param1 (message id)")
        if msg_id not in channel.writer.senders:
            return MavResult.UNSUPPORTED
        interval = channel.schedule.intervals.get(msg_id, 0.0)
        channel.writer.mav.message_interval_send(msg_id, round(interval * 1e6) if interval > 0 else -1)
        return MavResult.ACCEPTED
    if command == mavlink.MAV_CMD_REQUEST_MESSAGE:
        msg_id = _whole(msg.param1, 0, MAX_MESSAGE_ID, "param1 (message id)")
        return MavResult.ACCEPTED if msg_id in channel.writer.senders else MavResult.UNSUPPORTED
    if command in (mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, mavlink.MAV_CMD_GET_HOME_POSITION):
        return MavResult.ACCEPTED
    if command == mavlink.MAV_CMD_DO_SET_HOME:
        return _set_home(channel, msg, nav)
    return MavResult.UNSUPPORTED


def _set_home(channel: Channel, msg: Any, nav: Any) -> MavResult:
    """DO_SET_HOME: param1 1 = here, 0 = the latitude/longitude given (checked like check_latlng)."""
    ap = channel.boat.autopilot
    if _whole(msg.param1, 0, 1, "param1 (use current location)") == 1:
        if not nav.position_ok:
            return MavResult.FAILED
        return ap.set_home(nav.n, nav.e)
    if msg.get_type() == "COMMAND_INT":
        lat = _whole(msg.x, -90e7, 90e7, "x (latitude, degE7)") / 1e7
        lon = _whole(msg.y, -180e7, 180e7, "y (longitude, degE7)") / 1e7
    else:
        lat = _finite(msg.param5, -90.0, 90.0, "param5 (latitude, deg)")
        lon = _finite(msg.param6, -180.0, 180.0, "param6 (longitude, deg)")
    origin = channel.origin
    return ap.set_home(*geodetic_to_ned(lat, lon, origin.latitude_deg, origin.longitude_deg))


def _set_mode(channel: Channel, msg: Any) -> None:
    boat = channel.boat
    if msg.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
        result = boat.autopilot.set_mode(msg.custom_mode, boat.navigation())
    else:
        result = MavResult.UNSUPPORTED
    channel.publish()
    # ArduPilot acknowledges SET_MODE with a COMMAND_ACK whose command is the message id (11)
    channel.writer.mav.command_ack_send(
        mavlink.MAVLINK_MSG_ID_SET_MODE, int(result), 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
    )


# ---- setpoints ---------------------------------------------------------------------------------------
def _position_target_local(channel: Channel, msg: Any) -> None:
    _apply_setpoint(channel, msg, msg.coordinate_frame, (msg.x, msg.y))


def _position_target_global(channel: Channel, msg: Any) -> None:
    if msg.coordinate_frame not in GLOBAL_INT_FRAMES:
        _reject(channel, f"SET_POSITION_TARGET_GLOBAL_INT frame {msg.coordinate_frame} not supported, ignored")
        return
    if msg.type_mask & POS_IGNORE != POS_IGNORE and not (
        abs(msg.lat_int) <= 90e7 and abs(msg.lon_int) <= 180e7
    ):  # ArduPilot's check_latlng: the message is ignored
        _reject(channel, f"SET_POSITION_TARGET_GLOBAL_INT lat/lon {msg.lat_int}, {msg.lon_int} invalid, ignored")
        return
    origin = channel.origin
    n, e = geodetic_to_ned(msg.lat_int / 1e7, msg.lon_int / 1e7, origin.latitude_deg, origin.longitude_deg)
    _apply_setpoint(channel, msg, Frame.LOCAL_NED, (n, e))


def _apply_setpoint(channel: Channel, msg: Any, frame: int, position: tuple[float, float]) -> None:
    boat = channel.boat
    ap = boat.autopilot
    if ap.mode != MODE_NUMBERS["GUIDED"] or not ap.armed:
        return  # ArduPilot ignores setpoints outside GUIDED; a disarmed boat does not move
    nav = boat.navigation()
    try:
        target = interpret_position_target(
            msg.type_mask,
            frame,
            position,
            (msg.vx, msg.vy),
            msg.yaw,
            msg.yaw_rate,
            nav,
            ap.params.get("WP_SPEED"),
        )
    except SetpointRejected as exc:
        _reject(channel, str(exc))
        return
    ap.set_guided_target(target, boat.t, (nav.n, nav.e))


def _reject(channel: Channel, text: str) -> None:
    boat = channel.boat
    if boat.t - channel.last_rejection_text_t >= REJECTION_TEXT_INTERVAL_S:
        channel.last_rejection_text_t = boat.t
        boat.autopilot.say(Severity.WARNING, text)
    log.debug("boat %d: %s", boat.sysid, text)


# ---- parameters, streams, time ----------------------------------------------------------------------
def _param_value(channel: Channel, name: str) -> None:
    params = channel.boat.autopilot.params
    channel.writer.mav.param_value_send(
        name.encode("ascii"),
        params.get(name),
        mavlink.MAV_PARAM_TYPE_REAL32,
        len(params.names),
        params.names.index(name),
    )


def _param_request_list(channel: Channel, msg: Any) -> None:
    for name in channel.boat.autopilot.params.names:
        _param_value(channel, name)


def _param_request_read(channel: Channel, msg: Any) -> None:
    names = channel.boat.autopilot.params.names
    if msg.param_index >= 0:
        if msg.param_index < len(names):
            _param_value(channel, names[msg.param_index])
        return
    name = _param_name(msg.param_id)
    if name in names:
        _param_value(channel, name)


def _param_set(channel: Channel, msg: Any) -> None:
    name = _param_name(msg.param_id)
    params = channel.boat.autopilot.params
    if name not in params:
        log.debug("boat %d: PARAM_SET of unknown %r ignored", channel.boat.sysid, name)
        return
    value = float(msg.param_value)
    if not params.set(name, value):
        _reject(channel, f"{name} {value:g} refused: must be {PARAMS[name].describe()}"[:50])
        channel.publish()
    _param_value(channel, name)  # the value now in force (unchanged if the new one was refused)


def _param_name(param_id: str | bytes) -> str:
    if isinstance(param_id, bytes):
        param_id = param_id.decode("ascii", "replace")
    return param_id.rstrip("\x00")


def _request_data_stream(channel: Channel, msg: Any) -> None:
    rate = float(msg.req_message_rate) if msg.start_stop else 0.0
    channel.schedule.set_group_rate(msg.req_stream_id, rate, channel.boat.t)


def _timesync(channel: Channel, msg: Any) -> None:
    if msg.tc1 == 0:  # a request: answer with our (simulated) clock in ns
        channel.writer.mav.timesync_send(round(channel.boat.t * 1e9), msg.ts1)


HANDLERS = {
    "COMMAND_LONG": _command,
    "COMMAND_INT": _command,
    "SET_MODE": _set_mode,
    "SET_POSITION_TARGET_LOCAL_NED": _position_target_local,
    "SET_POSITION_TARGET_GLOBAL_INT": _position_target_global,
    "PARAM_REQUEST_LIST": _param_request_list,
    "PARAM_REQUEST_READ": _param_request_read,
    "PARAM_SET": _param_set,
    "REQUEST_DATA_STREAM": _request_data_stream,
    "TIMESYNC": _timesync,
}
