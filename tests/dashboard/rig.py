"""A whole two-boat rig for the dashboard tests, every part a real process on loopback:

``koopguide sitl --count 2`` (started by :attr:`Rig.start_simulator`), two ``koopguide run`` services (system ids
1 and 2, vehicle ids boat1 and boat2, goals 2.5 m apart), and ``koopguide dashboard --listen
127.0.0.1:0``, all on one zenoh group: the shipped default configuration moved to a free port
(multicast scouting stays off). Conventions: local NED metres.
"""

from __future__ import annotations

import contextlib
import os
import re
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml

from koopguide.base import data
from koopguide.bus.zenoh_config import DEFAULT_ZENOH_CONFIG_FILE, WELL_KNOWN_PORT
from koopguide.guidance import settings
from koopguide.guidance.law.frames import ModelFrame
from koopguide.harness.mission import demo_start_pose, free_udp_port
from koopguide.model.field import load_field
from koopguide.model.learn import trainer
from koopguide.model.learn.export import save
from tests.support.models import small_config
from tests.support.processes import stop_process

REPO = Path(__file__).resolve().parents[2]
KOOPGUIDE = [sys.executable, "-m", "koopguide"]
#: Where each boat's model goal lands [N, E] m, and which Zshape demonstration it starts from.
BOATS = {"boat1": ((0.0, 0.0), 0), "boat2": ((0.0, 2.5), 3)}
SPEEDUP = 3.0
STATUS_HZ = 10.0


def train_small_model(path: Path) -> Path:
    """Zshape with the tests' short budget (a few seconds); a real trained field, just coarser."""
    demos = data.load_lasa("Zshape")
    cfg = small_config()
    save(path, trainer.train(demos, cfg, seed=0), demos, cfg)
    return path


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def zenoh_config_file(folder: Path) -> Path:
    """The shipped default zenoh configuration, rendezvous moved to a free port."""
    text = DEFAULT_ZENOH_CONFIG_FILE.read_text()
    assert f":{WELL_KNOWN_PORT}" in text
    path = folder / "zenoh.json5"
    path.write_text(text.replace(f":{WELL_KNOWN_PORT}", f":{free_tcp_port()}"))
    return path


@dataclass
class Process:
    """A child process whose output is collected on a thread (so its pipe never fills)."""

    name: str
    popen: subprocess.Popen
    lines: list[str] = field(default_factory=list)

    @classmethod
    def start(cls, name: str, argv: list[str]) -> Process:
        env = {**os.environ, "PYTHONPATH": str(REPO), "PYTHONUNBUFFERED": "1"}
        popen = subprocess.Popen(argv, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        proc = cls(name, popen)
        threading.Thread(target=proc._read, daemon=True, name=f"output of {name}").start()
        return proc

    def _read(self) -> None:
        for line in self.popen.stdout:
            self.lines.append(line.rstrip("\n"))

    def wait_for(self, pattern: str, timeout: float) -> re.Match:
        deadline = time.monotonic() + timeout
        regex = re.compile(pattern)
        while time.monotonic() < deadline:
            for line in list(self.lines):
                if match := regex.search(line):
                    return match
            if self.popen.poll() is not None:
                break
            time.sleep(0.05)
        raise AssertionError(
            f"{self.name}: no line matching {pattern!r} within {timeout} s; output:\n" + "\n".join(self.lines[-40:])
        )

    def stop(self) -> int:
        return stop_process(self.popen)


@dataclass
class Rig:
    url: str
    zenoh_config: Path
    processes: list[Process]
    goals: dict[str, tuple[float, float]]
    start_simulator: Callable[[], None]  # the boats start once the page is watching


def boat_setup(model: Path, folder: Path) -> tuple[dict, dict[str, int]]:
    """The simulator's config (start poses at the demo starts, a tank around both fields) and the
    UDP port each service listens on."""
    field_ = load_field(model)
    starts = data.load_lasa("Zshape").trajectories
    base = settings.load(None, {})
    poses, corners = [], []
    for goal, start in BOATS.values():
        frame = ModelFrame.place(field_.goal, replace(base.frame, goal_ned=goal))
        poses.append(list(demo_start_pose(field_, frame, starts[start][0])))
        lo, hi = field_.bounds
        corners.append(frame.to_ned(np.array([lo, hi, [lo[0], hi[1]], [hi[0], lo[1]]])))
    box = np.vstack([*corners, np.array(poses)[:, :2]])
    world = {
        "walls": True,
        "north_m": [float(box[:, 0].min() - 1.0), float(box[:, 0].max() + 1.0)],
        "east_m": [float(box[:, 1].min() - 1.0), float(box[:, 1].max() + 1.0)],
    }
    sim = {
        "count": 2,
        "start_poses": poses,
        "speedup": SPEEDUP,
        "world": world,
        "flow": {"kinds": ["uniform"], "uniform": {"speed_mps": 0.02, "direction_deg": 0.0}},
        "seed": 0,
    }
    (folder / "sitl.yaml").write_text(yaml.safe_dump(sim))
    return sim, mavlink_ports()


def mavlink_ports() -> dict[str, int]:
    """UDP ports for the services: ``P`` and ``P + 10``, since the simulator serves boat k (0-based) on
    each endpoint's port + 10 k (docs/simulator.md, ``port_stride``)."""
    for _ in range(50):
        base = free_udp_port()
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            try:
                probe.bind(("127.0.0.1", base + 10))
            except OSError:
                continue
        return {vid: base + 10 * k for k, vid in enumerate(BOATS)}
    raise AssertionError("no pair of free UDP ports P, P + 10 found")


@contextlib.contextmanager
def running_rig(model: Path, folder: Path, dashboard_args: tuple[str, ...] = ()) -> Iterator[Rig]:
    zenoh_config = zenoh_config_file(folder)
    _, ports = boat_setup(model, folder)
    processes: list[Process] = []
    try:
        for sysid, (vid, (goal, _)) in enumerate(BOATS.items(), start=1):
            service_cfg = folder / f"{vid}.yaml"
            service_cfg.write_text(
                yaml.safe_dump(
                    {
                        "vehicle_id": vid,
                        "arm": True,
                        "mavlink": {"endpoint": f"udp:127.0.0.1:{ports[vid]}", "target_system": sysid},
                        "frame": {"goal_ned": list(goal)},
                        "status": {"rate_hz": STATUS_HZ},
                    }
                )
            )
            processes.append(
                Process.start(
                    vid,
                    [
                        *KOOPGUIDE,
                        "run",
                        "--model",
                        str(model),
                        "--config",
                        str(service_cfg),
                        "--zenoh-config",
                        str(zenoh_config),
                    ],
                )
            )
        dashboard = Process.start(
            "dashboard",
            [*KOOPGUIDE, "dashboard", "--zenoh-config", str(zenoh_config), "--listen", "127.0.0.1:0", *dashboard_args],
        )
        processes.append(dashboard)
        url = dashboard.wait_for(r"(http://127\.0\.0\.1:\d+/)", timeout=30).group(1)
        for proc in processes[:-1]:  # the boats would drift in the current until their service steers
            proc.wait_for("state waiting", timeout=40)

        def start_simulator() -> None:
            links = [f"--mavlink=udpout:127.0.0.1:{ports['boat1']}"]  # boat 2 on that port + 10
            processes.append(
                Process.start("sitl", [*KOOPGUIDE, "sitl", "--config", str(folder / "sitl.yaml"), *links, "--quiet"])
            )

        yield Rig(url, zenoh_config, processes, {vid: goal for vid, (goal, _) in BOATS.items()}, start_simulator)
    finally:
        for proc in reversed(processes):
            proc.stop()
