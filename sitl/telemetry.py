"""What a boat sends on its own: HEARTBEAT and the telemetry streams, on a simulated-time schedule.

Every timestamp is simulated time (time_boot_ms, time_usec). Streams are scheduled per link, as
ArduPilot's SRn_* rates are per serial port: a ground station may change its own rates with
REQUEST_DATA_STREAM or MAV_CMD_SET_MESSAGE_INTERVAL without changing another link's.
Units on the wire follow the MAVLink definitions (degE7, mm, cm/s, cdeg).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from koopguide.base.geodesy import ned_to_geodetic
from koopguide.mavlink.wire import mavlink
from sitl.autopilot import AUTOPILOT_MODES, MANUAL_INPUT_MODES
from sitl.config import OriginConfig, StreamRates, VehicleKind

if TYPE_CHECKING:
    from sitl.boat import Boat

# REQUEST_DATA_STREAM stream ids and the messages each group carries (ArduPilot's grouping).
STREAM_GROUPS: dict[str, tuple[int, tuple[int, ...]]] = {
    "extended_status": (
        mavlink.MAV_DATA_STREAM_EXTENDED_STATUS,
        (mavlink.MAVLINK_MSG_ID_SYS_STATUS, mavlink.MAVLINK_MSG_ID_GPS_RAW_INT),
    ),
    "position": (
        mavlink.MAV_DATA_STREAM_POSITION,
        (mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED),
    ),
    "extra1": (mavlink.MAV_DATA_STREAM_EXTRA1, (mavlink.MAVLINK_MSG_ID_ATTITUDE,)),
    "extra2": (mavlink.MAV_DATA_STREAM_EXTRA2, (mavlink.MAVLINK_MSG_ID_VFR_HUD,)),
    "extra3": (
        mavlink.MAV_DATA_STREAM_EXTRA3,
        (mavlink.MAVLINK_MSG_ID_SYSTEM_TIME, mavlink.MAVLINK_MSG_ID_EKF_STATUS_REPORT),
    ),
    "rc_channels": (mavlink.MAV_DATA_STREAM_RC_CHANNELS, (mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW,)),
}

# SYS_STATUS sensor bits (MAV_SYS_STATUS_SENSOR) that MAVSDK and ground stations read.
# SERVO_OUTPUT_RAW outputs (1-based) per actuator command, as ArduPilot boats are wired by default:
# skid steering SERVO1 ThrottleLeft / SERVO3 ThrottleRight; a rudder boat SERVO1 GroundSteering /
# SERVO3 Throttle; the vectored boat's bow and stern tunnel thrusters on SERVO5 / SERVO6.
SERVO_OUTPUTS = {
    VehicleKind.DIFF_THRUST: (1, 3),
    VehicleKind.RUDDER: (3, 1),
    VehicleKind.VECTORED: (1, 3, 5, 6),
}

SENSOR_GYRO = 0x1
SENSOR_ACCEL = 0x2
SENSOR_MAG = 0x4
SENSOR_GPS = 0x20
SENSOR_MOTOR_OUTPUTS = 0x8000
SENSOR_AHRS = 0x200000
SENSOR_PREARM_CHECK = 0x10000000
SENSORS_PRESENT = (
    SENSOR_GYRO | SENSOR_ACCEL | SENSOR_MAG | SENSOR_GPS | SENSOR_MOTOR_OUTPUTS | SENSOR_AHRS | SENSOR_PREARM_CHECK
)

# EKF_STATUS_REPORT flags for a healthy horizontal solution.
EKF_GOOD = (
    mavlink.EKF_ATTITUDE
    | mavlink.EKF_VELOCITY_HORIZ
    | mavlink.EKF_POS_HORIZ_REL
    | mavlink.EKF_POS_HORIZ_ABS
    | mavlink.EKF_PRED_POS_HORIZ_REL
    | mavlink.EKF_PRED_POS_HORIZ_ABS
)

# AUTOPILOT_VERSION: what a client may rely on.
CAPABILITIES = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
)
FLIGHT_SW_VERSION = (4 << 24) | (5 << 16) | (0 << 8) | 255  # reported as 4.5.0 official, like Rover


def time_boot_ms(t: float) -> int:
    """Simulated time [s] as MAVLink time_boot_ms (uint32, wraps after 49 days)."""
    return round(t * 1000.0) & 0xFFFFFFFF


def time_usec(t: float) -> int:
    return round(t * 1e6)


def heading_cdeg(psi: float) -> int:
    """Heading [rad] as centidegrees in [0, 36000)."""
    return round(math.degrees(psi) * 100.0) % 36000


def default_intervals(rates: StreamRates) -> dict[int, float]:
    """Message id -> interval [s] from the configured stream-group rates (0 = off)."""
    out: dict[int, float] = {}
    for group, (_, ids) in STREAM_GROUPS.items():
        rate = getattr(rates, group)
        for msg_id in ids:
            out[msg_id] = 1.0 / rate if rate > 0 else 0.0
    return out


class TelemetryWriter:
    """Builds and sends one boat's messages through a pymavlink encoder bound to one link."""

    def __init__(self, boat: Boat, mav: mavlink.MAVLink, origin: OriginConfig, unix_time_at_boot_s: float):
        self.boat = boat
        self.mav = mav
        self.origin = origin
        self.unix_time_at_boot_s = unix_time_at_boot_s
        self.senders: dict[int, Callable[[], None]] = {
            mavlink.MAVLINK_MSG_ID_HEARTBEAT: self.heartbeat,
            mavlink.MAVLINK_MSG_ID_SYS_STATUS: self.sys_status,
            mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: self.gps_raw_int,
            mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: self.global_position_int,
            mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: self.local_position_ned,
            mavlink.MAVLINK_MSG_ID_ATTITUDE: self.attitude,
            mavlink.MAVLINK_MSG_ID_VFR_HUD: self.vfr_hud,
            mavlink.MAVLINK_MSG_ID_SYSTEM_TIME: self.system_time,
            mavlink.MAVLINK_MSG_ID_EKF_STATUS_REPORT: self.ekf_status_report,
            mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: self.servo_output_raw,
            mavlink.MAVLINK_MSG_ID_HOME_POSITION: self.home_position,
            mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION: self.autopilot_version,
        }

    # ---- estimate helpers -------------------------------------------------------------------------
    def _fix(self) -> tuple[float, float, float, float]:
        fix = self.boat.sensors.fix
        return (fix.n, fix.e, fix.vn, fix.ve) if fix is not None else (0.0, 0.0, 0.0, 0.0)

    def _healthy(self) -> bool:
        return self.boat.sensors.position_healthy(self.boat.t)

    # ---- messages -----------------------------------------------------------------------------------
    def heartbeat(self) -> None:
        ap = self.boat.autopilot
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if ap.mode in MANUAL_INPUT_MODES:
            base |= mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        if ap.mode in AUTOPILOT_MODES:
            base |= mavlink.MAV_MODE_FLAG_GUIDED_ENABLED | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
        if ap.armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        state = mavlink.MAV_STATE_ACTIVE if ap.armed else mavlink.MAV_STATE_STANDBY
        self.mav.heartbeat_send(
            mavlink.MAV_TYPE_SURFACE_BOAT, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, base, ap.mode, state, 3
        )

    def sys_status(self) -> None:
        healthy = SENSOR_GYRO | SENSOR_ACCEL | SENSOR_MAG | SENSOR_MOTOR_OUTPUTS
        if self._healthy():
            healthy |= SENSOR_GPS | SENSOR_AHRS | SENSOR_PREARM_CHECK
        self.mav.sys_status_send(SENSORS_PRESENT, SENSORS_PRESENT, healthy, 150, 7400, -1, 100, 0, 0, 0, 0, 0, 0)

    def gps_raw_int(self) -> None:
        n, e, vn, ve = self._fix()
        lat, lon = ned_to_geodetic(n, e, self.origin.latitude_deg, self.origin.longitude_deg)
        speed = math.hypot(vn, ve)
        cog = heading_cdeg(math.atan2(ve, vn)) if speed > 0.02 else 65535
        fix_type = mavlink.GPS_FIX_TYPE_3D_FIX if self._healthy() else mavlink.GPS_FIX_TYPE_NO_FIX
        self.mav.gps_raw_int_send(
            time_usec(self.boat.t),
            fix_type,
            round(lat * 1e7),
            round(lon * 1e7),
            round(self.origin.altitude_m * 1000),
            60,
            100,
            min(round(speed * 100), 65534),
            cog,
            16,
        )

    def global_position_int(self) -> None:
        if self.boat.sensors.fix is None:
            return  # no position estimate yet: ArduPilot sends no position either
        n, e, vn, ve = self._fix()
        lat, lon = ned_to_geodetic(n, e, self.origin.latitude_deg, self.origin.longitude_deg)
        self.mav.global_position_int_send(
            time_boot_ms(self.boat.t),
            round(lat * 1e7),
            round(lon * 1e7),
            round(self.origin.altitude_m * 1000),
            0,
            round(vn * 100),
            round(ve * 100),
            0,
            heading_cdeg(self.boat.sensors.psi),
        )

    def local_position_ned(self) -> None:
        if self.boat.sensors.fix is None:
            return
        n, e, vn, ve = self._fix()
        self.mav.local_position_ned_send(time_boot_ms(self.boat.t), n, e, 0.0, vn, ve, 0.0)

    def attitude(self) -> None:
        s = self.boat.sensors
        self.mav.attitude_send(time_boot_ms(self.boat.t), 0.0, 0.0, s.psi, 0.0, 0.0, s.r)

    def vfr_hud(self) -> None:
        _, _, vn, ve = self._fix()
        speed = math.hypot(vn, ve)
        throttle = round(abs(self.boat.autopilot.control.throttle) * 100)
        heading = round(math.degrees(self.boat.sensors.psi)) % 360
        self.mav.vfr_hud_send(speed, speed, heading, throttle, self.origin.altitude_m, 0.0)

    def system_time(self) -> None:
        t = self.boat.t
        self.mav.system_time_send(time_usec(self.unix_time_at_boot_s + t), time_boot_ms(t))

    def ekf_status_report(self) -> None:
        flags = EKF_GOOD if self._healthy() else mavlink.EKF_ATTITUDE
        self.mav.ekf_status_report_send(flags, 0.01, 0.01, 0.0, 0.01, 0.0)

    def servo_output_raw(self) -> None:
        """Actuator commands as PWM [us] on the servo outputs an ArduPilot boat of this kind uses."""
        pwm = [0] * 8
        for servo, command in zip(SERVO_OUTPUTS[self.boat.params.kind], self.boat.autopilot.commands, strict=True):
            pwm[servo - 1] = round(1500 + 500 * command)
        self.mav.servo_output_raw_send(time_usec(self.boat.t) & 0xFFFFFFFF, 0, *pwm)

    def home_position(self) -> None:
        n, e = self.boat.autopilot.home
        lat, lon = ned_to_geodetic(n, e, self.origin.latitude_deg, self.origin.longitude_deg)
        self.mav.home_position_send(
            round(lat * 1e7),
            round(lon * 1e7),
            round(self.origin.altitude_m * 1000),
            n,
            e,
            0.0,
            (1.0, 0.0, 0.0, 0.0),
            0.0,
            0.0,
            0.0,
            time_usec(self.boat.t),
        )

    def autopilot_version(self) -> None:
        uid = 0x4B4F4F50_00000000 | self.boat.sysid  # "KOOP" + system id
        self.mav.autopilot_version_send(
            CAPABILITIES, FLIGHT_SW_VERSION, 0, 0, 0, b"koopsitl", [0] * 8, [0] * 8, 0, 0, uid
        )

    def statustext(self, severity: int, text: str) -> None:
        self.mav.statustext_send(severity, text.encode("ascii", "replace")[:50])


class StreamSchedule:
    """Per-link message intervals and next due times, in simulated seconds."""

    def __init__(self, intervals: dict[int, float], heartbeat_interval: float, t0: float):
        self.defaults = dict(intervals)
        self.defaults[mavlink.MAVLINK_MSG_ID_HEARTBEAT] = heartbeat_interval
        self.intervals: dict[int, float] = dict(self.defaults)
        self.next_due: dict[int, float] = {msg_id: t0 for msg_id, dt in self.intervals.items() if dt > 0}
        self._earliest = t0

    def set_interval(self, msg_id: int, interval_s: float | None, t: float) -> None:
        """Set a message's interval [s]; None restores the default, 0 stops it."""
        dt = self.defaults.get(msg_id, 0.0) if interval_s is None else interval_s
        self.intervals[msg_id] = dt
        if dt > 0:
            self.next_due[msg_id] = min(self.next_due.get(msg_id, t), t + dt)
            self._earliest = min(self._earliest, self.next_due[msg_id])
        else:
            self.next_due.pop(msg_id, None)

    def set_group_rate(self, stream_id: int, rate_hz: float, t: float) -> None:
        """REQUEST_DATA_STREAM: one group (or MAV_DATA_STREAM_ALL) at rate_hz (0 stops it)."""
        for group_id, ids in STREAM_GROUPS.values():
            if stream_id in (group_id, mavlink.MAV_DATA_STREAM_ALL):
                for msg_id in ids:
                    self.set_interval(msg_id, 1.0 / rate_hz if rate_hz > 0 else 0.0, t)

    def due(self, t: float) -> list[int]:
        """Message ids due at time t [s], rescheduled on a fixed grid (no drift)."""
        if t + 1e-9 < self._earliest:
            return []
        out = []
        earliest = math.inf
        for msg_id, due in self.next_due.items():
            if t + 1e-9 >= due:
                out.append(msg_id)
                dt = self.intervals[msg_id]
                due += dt * max(1, math.floor((t - due) / dt + 1e-9) + 1)
                self.next_due[msg_id] = due
            earliest = min(earliest, due)
        self._earliest = earliest
        return out
