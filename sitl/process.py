"""Start the simulator as a subprocess (``python -m sitl``) and know where its boats are.

For tests and tools that want the simulator in another process (its own GIL, a real process
boundary):

    with SimulatorProcess({"count": 2, "speedup": 20.0, "flow": {"kinds": ["uniform"]},
                           "start_poses": [[1.0, 1.0, 0.0], [1.0, 2.0, 0.0]],
                           "mavlink": {"endpoints": ["tcpin:127.0.0.1:0"]}}) as sim:
        sim.addresses   # {1: ['tcpin:127.0.0.1:40123'], 2: ['tcpin:127.0.0.1:40125']}

The overrides are written to a temporary YAML file passed as ``--config``, so every key of
config/sitl.yaml can be set. Leaving the block sends SIGTERM and waits for a clean exit.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import TracebackType
from typing import Any

import yaml

from sitl import config as sitl_config

READY_LINE = "sitl: ready"


class SimulatorProcess:
    def __init__(self, overrides: dict[str, Any] | None = None, start_timeout_s: float = 30.0):
        self.overrides = overrides or {}
        self.start_timeout_s = start_timeout_s
        self.addresses: dict[int, list[str]] = {}
        self.output: list[str] = []  # stdout lines after "ready", available after exit
        self.returncode: int | None = None
        self._proc: subprocess.Popen[str] | None = None
        self._dir = tempfile.TemporaryDirectory(prefix="sitl-")

    def __enter__(self) -> SimulatorProcess:
        sitl_config.load(overrides=self.overrides)  # fail here, with the key named, not in the child
        path = Path(self._dir.name) / "sitl.yaml"
        path.write_text(yaml.safe_dump(self.overrides), encoding="utf-8")
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "sitl", "--config", str(path), "--quiet"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        deadline = time.monotonic() + self.start_timeout_s
        assert self._proc.stdout is not None
        while True:
            line = self._proc.stdout.readline().strip()
            if line == READY_LINE:
                return self
            if not line and self._proc.poll() is not None:
                err = self._proc.stderr.read() if self._proc.stderr else ""
                self._dir.cleanup()
                raise RuntimeError(f"simulator exited with {self._proc.returncode} before ready: {err.strip()}")
            if line.startswith("sitl: boat "):
                _, _, sysid, _, address = line.split(" ", 4)
                self.addresses.setdefault(int(sysid), []).append(address)
            if time.monotonic() > deadline:
                self.close()
                raise TimeoutError(f"simulator not ready within {self.start_timeout_s} s")

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    @property
    def pid(self) -> int | None:
        """The simulator's process id (None before it started)."""
        return self._proc.pid if self._proc is not None else None

    def poll(self) -> int | None:
        """The simulator's exit code if it has exited, else None (also None before it started)."""
        return self._proc.poll() if self._proc is not None else None

    def close(self) -> None:
        """SIGTERM, wait for the clean exit (kill after 10 s), keep its last output."""
        proc = self._proc
        if proc is not None and proc.returncode is None:
            proc.terminate()
            try:
                out, _ = proc.communicate(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                out, _ = proc.communicate()
            self.output = out.splitlines()
            self.returncode = proc.returncode
        self._dir.cleanup()
