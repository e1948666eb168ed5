"""A real ground station, MAVProxy, against ``koopguide sitl`` on loopback TCP, non-interactively
(``--non-interactive --cmd``): it sees the boat, its position, mode and armed state, then switches
it to GUIDED and arms it. MAVProxy is installed without its GUI dependencies (``pip install
--no-deps MAVProxy`` plus pymavlink, pyserial, numpy, pynmeagps, defusedxml; see scripts/bootstrap.sh)."""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from tests.support.processes import stop_process

pytest.importorskip("MAVProxy", reason="MAVProxy is installed by scripts/bootstrap.sh (--no-deps)")

REPO = Path(__file__).resolve().parents[2]
MAVPROXY = Path(sys.executable).parent / "mavproxy.py"
ORIGIN = (-35.363261, 149.16523)  # config/sitl.yaml origin
START_NE = (2.25, 1.5)  # one boat: the centre of the 4.5 m x 3.0 m tank
M_PER_DEG_LAT = 111195.0
GUIDED, MANUAL = 15, 0  # ArduPilot Rover custom modes
ARMED_FLAG = 128  # MAV_MODE_FLAG_SAFETY_ARMED
STATUS_LINE = re.compile(r"^\d+: (HEARTBEAT|GLOBAL_POSITION_INT) \{(.*)\}$")


class Child:
    """A process whose output lines are collected on a thread."""

    def __init__(self, argv: list[str]) -> None:
        env = {**os.environ, "PYTHONPATH": str(REPO), "PYTHONUNBUFFERED": "1"}
        self.popen = subprocess.Popen(
            argv,
            cwd=REPO,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        self.lines: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.popen.stdout:
            self.lines.append(line.rstrip("\n"))

    def wait_for(self, predicate, timeout: float, what: str):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for line in list(self.lines):
                if (found := predicate(line)) is not None:
                    return found
            time.sleep(0.05)
        raise AssertionError(f"no {what} within {timeout} s; output:\n" + "\n".join(self.lines[-30:]))

    def stop(self) -> None:
        stop_process(self.popen)


def fields(line: str, kind: str) -> dict[str, float] | None:
    """The fields of a MAVProxy ``status`` line for message ``kind``, else None."""
    match = STATUS_LINE.match(line)
    if not match or match.group(1) != kind:
        return None
    return {k.strip(): float(v) for k, v in (part.split(" : ") for part in match.group(2).split(", "))}


def guided_and_armed(line: str) -> dict[str, float] | None:
    beat = fields(line, "HEARTBEAT")
    if beat is None or beat["custom_mode"] != GUIDED or not int(beat["base_mode"]) & ARMED_FLAG:
        return None
    return beat


def mavproxy(port: int, commands: str) -> Child:
    return Child(
        [
            sys.executable,
            str(MAVPROXY),
            f"--master=tcp:127.0.0.1:{port}",
            "--non-interactive",
            "--no-state",
            "--default-modules=mode,arm,misc",
            f"--cmd={commands}",
        ]
    )


@pytest.mark.timeout(90)
def test_mavproxy_sees_the_boat_then_switches_it_to_guided_and_arms_it() -> None:
    sim = Child([sys.executable, "-m", "koopguide", "sitl", "--mavlink", "tcpin:127.0.0.1:0", "--speedup", "2"])
    watch = observe = None
    try:
        port = int(
            sim.wait_for(
                lambda s: (m := re.search(r"boat 1 mavlink tcpin:127\.0\.0\.1:(\d+)", s)) and m.group(1),
                30,
                "simulator port",
            )
        )
        # 1. watching only: a heartbeat of a MANUAL, disarmed surface boat, and its position
        watch = mavproxy(port, "repeat add 0.5 status HEARTBEAT; repeat add 0.5 status GLOBAL_POSITION_INT")
        watch.wait_for(lambda s: s if "Detected vehicle 1:1" in s else None, 30, "vehicle detection")
        beat = watch.wait_for(lambda s: fields(s, "HEARTBEAT"), 30, "HEARTBEAT status")
        assert beat["type"] == 11 and beat["autopilot"] == 3  # MAV_TYPE_SURFACE_BOAT, ArduPilot
        assert beat["custom_mode"] == MANUAL and not int(beat["base_mode"]) & ARMED_FLAG
        fix = watch.wait_for(lambda s: fields(s, "GLOBAL_POSITION_INT"), 30, "GLOBAL_POSITION_INT status")
        north = (fix["lat"] / 1e7 - ORIGIN[0]) * M_PER_DEG_LAT
        east = (fix["lon"] / 1e7 - ORIGIN[1]) * M_PER_DEG_LAT * math.cos(math.radians(ORIGIN[0]))
        assert math.hypot(north - START_NE[0], east - START_NE[1]) < 0.1  # where the simulator put it
        watch.stop()

        # 2. commanding: GUIDED and armed, acknowledged, and the heartbeat then says so
        observe = mavproxy(port, "mode GUIDED; arm throttle; repeat add 0.5 status HEARTBEAT")
        observe.wait_for(lambda s: s if "DO_SET_MODE: ACCEPTED" in s else None, 30, "mode ACK")
        observe.wait_for(lambda s: s if "COMPONENT_ARM_DISARM: ACCEPTED" in s else None, 30, "arm ACK")
        after = observe.wait_for(guided_and_armed, 30, "GUIDED armed heartbeat")
        assert after["type"] == 11
        sim.wait_for(lambda s: s if "boat 1: Throttle armed" in s else None, 10, "the simulator's own arming log")
    finally:
        for child in (observe, watch, sim):
            if child is not None:
                child.stop()
