"""Helpers for the simulator tests: configs, and a pymavlink GCS on loopback (imported by conftest and tests).

The GCS side is real pymavlink over real loopback sockets, the way a ground station or the guidance
service meets the simulator. Waits are bounded in simulated time (read from the boat's own message
timestamps), with a generous wall-clock guard so a broken simulator fails instead of hanging.
"""

from __future__ import annotations

import os

os.environ["MAVLINK20"] = "1"  # before pymavlink.mavutil is imported

import time
from collections.abc import Callable
from typing import Any

from pymavlink import mavutil

from koopguide.mavlink.rover import MASK_VELOCITY
from sitl import config as sitl_config
from sitl.config import SitlConfig

mavutil.set_dialect("ardupilotmega")
mavlink = mavutil.mavlink

GCS_SYSTEM = 255
GCS_COMPONENT = 190
WALL_GUARD_S = 60.0  # no single wait in these tests may take longer on the wall clock
VELOCITY_MASK = MASK_VELOCITY  # velocity only (3559 = 0x0DE7)


def sim_config(overrides: dict[str, Any] | None = None) -> SitlConfig:
    base: dict[str, Any] = {"speedup": 20.0, "unix_time_at_boot_s": 1_700_000_000.0}
    return sitl_config.load(overrides=sitl_config_merge(base, overrides or {}))


def sitl_config_merge(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    out = dict(a)
    for k, v in b.items():
        out[k] = sitl_config_merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


class Gcs:
    """A ground station on a pymavlink connection, timing itself from the boat's time_boot_ms."""

    def __init__(self, conn: Any, target_system: int = 1):
        self.conn = conn
        self.mav = conn.mav
        self.target_system = target_system
        self.t = 0.0  # latest simulated time seen [s]
        self.statustexts: list[tuple[float, str]] = []
        self.heartbeat: Any = None

    def recv(self, timeout: float = 1.0) -> Any:
        msg = self.conn.recv_match(blocking=True, timeout=timeout)
        if msg is None:
            return None
        if msg.get_srcSystem() != self.target_system:
            return msg
        stamp = getattr(msg, "time_boot_ms", None)
        if stamp is not None:
            self.t = max(self.t, stamp / 1000.0)
        kind = msg.get_type()
        if kind == "STATUSTEXT":
            self.statustexts.append((self.t, msg.text))
        elif kind == "HEARTBEAT":
            self.heartbeat = msg
        return msg

    def wait(self, predicate: Callable[[Any], bool], what: str, sim_timeout: float = 10.0) -> Any:
        """The first message from the boat satisfying ``predicate`` within sim_timeout simulated seconds."""
        start_sim = self.t
        start_wall = time.monotonic()
        while time.monotonic() - start_wall < WALL_GUARD_S:
            msg = self.recv()
            if msg is not None and msg.get_srcSystem() == self.target_system and predicate(msg):
                return msg
            if self.t - start_sim > sim_timeout:
                break
        raise AssertionError(f"no {what} within {sim_timeout} s simulated (t = {self.t:.2f} s)")

    def wait_type(self, kind: str, sim_timeout: float = 10.0) -> Any:
        return self.wait(lambda m: m.get_type() == kind, kind, sim_timeout)

    def run_for(self, sim_seconds: float, each: Callable[[Any], None] | None = None) -> None:
        """Receive for sim_seconds of simulated time, calling ``each`` on every message from the boat."""
        end = self.t + sim_seconds
        start_wall = time.monotonic()
        while self.t < end:
            assert time.monotonic() - start_wall < WALL_GUARD_S, f"simulator stalled at t = {self.t:.2f} s"
            msg = self.recv()
            if msg is not None and each is not None and msg.get_srcSystem() == self.target_system:
                each(msg)

    def command(self, command: int, *params: float, sim_timeout: float = 5.0) -> Any:
        p = list(params) + [0.0] * (7 - len(params))
        self.mav.command_long_send(self.target_system, 1, command, 0, *p)
        return self.wait(
            lambda m: m.get_type() == "COMMAND_ACK" and m.command == command,
            f"COMMAND_ACK({command})",
            sim_timeout,
        )

    def set_mode(self, mode: int) -> Any:
        return self.command(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode)

    def arm(self, arm: bool = True) -> Any:
        return self.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0 if arm else 0.0)

    def velocity(self, vn: float, ve: float, mask: int = VELOCITY_MASK, frame: int = 1, yaw: float = 0.0) -> None:
        self.mav.set_position_target_local_ned_send(
            round(self.t * 1000), self.target_system, 1, frame, mask, 0, 0, 0, vn, ve, 0, 0, 0, 0, yaw, 0
        )

    def stream_all(self, rate_hz: int) -> None:
        self.mav.request_data_stream_send(self.target_system, 1, mavlink.MAV_DATA_STREAM_ALL, rate_hz, 1)
