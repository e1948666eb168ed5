"""The simulation clock and scheduler: boats, flow, MAVLink links and the recorder, in simulated time.

Simulated time advances in fixed physics steps of 1/physics_rate_hz. Everything else - controller
runs, sensor fixes, every MAVLink stream, the recorder - is scheduled on simulated time, so a run is
the same at any speed-up. The wall clock only paces it: at ``speedup`` X, simulated time t is due at
wall time t / X after start; ``speedup`` 0 runs as fast as the CPU allows. Incoming messages act at
the simulated time they are received.

Programmatic use (the guidance service's end-to-end tests use this):

    cfg = sitl.config.load(overrides={"count": 2, "speedup": 20.0,
                                      "mavlink": {"endpoints": ["tcpin:127.0.0.1:0"]}})
    async with await Simulation.create(cfg) as sim:
        print(sim.addresses())          # {1: ['tcpin:127.0.0.1:40123'], 2: [...]}
        await sim.run(duration_s=60.0)  # or run() until sim.stop()

or, from blocking code, ``with SimulationThread(cfg) as handle: ...`` (see below).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import math
import threading
import time
from collections.abc import Callable
from types import TracebackType
from typing import Any, TypeVar

import numpy as np

from koopguide.mavlink.endpoint import Endpoint
from koopguide.mavlink.signing import SigningKey
from sitl import inbound
from sitl.boat import Boat
from sitl.config import SitlConfig
from sitl.flow import Flow
from sitl.mavlink_endpoint import Link, open_link
from sitl.recorder import Recorder
from sitl.telemetry import StreamSchedule, TelemetryWriter, default_intervals
from sitl.vehicles import VehicleParams
from sitl.world import Tank

log = logging.getLogger(__name__)
T = TypeVar("T")

MAX_STEPS_PER_SLICE = 200  # physics steps between two chances for the event loop to do I/O
ROW_SPACING_M = 0.6  # distance between boats placed automatically [m]


def start_poses(cfg: SitlConfig, tank: Tank) -> list[tuple[float, float, float]]:
    """Configured poses, or a row across the tank centre (along east), all heading north."""
    if cfg.start_poses:
        return list(cfg.start_poses)
    n_mid = 0.5 * (cfg.world.north_m[0] + cfg.world.north_m[1])
    e_mid = 0.5 * (cfg.world.east_m[0] + cfg.world.east_m[1])
    spacing = ROW_SPACING_M
    if cfg.count > 1 and tank.enabled:
        spacing = min(spacing, (tank.e_max - tank.e_min) / (cfg.count - 1))
    return [(n_mid, e_mid + (k - 0.5 * (cfg.count - 1)) * spacing, 0.0) for k in range(cfg.count)]


class Simulation:
    """N boats in one body of water, each reachable over its MAVLink links."""

    def __init__(self, cfg: SitlConfig, recorder: Recorder):
        self.cfg = cfg
        self.dt = 1.0 / cfg.physics_rate_hz
        self.control_every = max(1, round(cfg.physics_rate_hz / cfg.autopilot.control_rate_hz))
        self.record_every = max(1, round(cfg.physics_rate_hz / cfg.recorder.rate_hz))
        seeds = np.random.SeedSequence(cfg.seed).spawn(cfg.count + 1)
        self.flow = Flow(cfg.flow, np.random.default_rng(seeds[0]))
        kinds = cfg.vehicles or (cfg.vehicle,) * cfg.count
        params = {kind: VehicleParams.from_config(cfg.vessel, kind) for kind in set(kinds)}
        self.tank = Tank(cfg.world, margin_m=0.5 * cfg.vessel.hull.length_m)
        self.boats = [
            Boat(k + 1, cfg, params[kind], self.flow, self.tank, pose, np.random.default_rng(seeds[k + 1]))
            for k, (pose, kind) in enumerate(zip(start_poses(cfg, self.tank), kinds, strict=True))
        ]
        self.recorder = recorder
        self.links: list[Link] = []
        self.signing_key: SigningKey | None = None
        self.channels: dict[tuple[int, int], inbound.Channel] = {}  # (id(link), sysid) -> channel
        self.unix_time_at_boot_s = cfg.unix_time_at_boot_s if cfg.unix_time_at_boot_s is not None else time.time()
        self.steps = 0
        self._stop = asyncio.Event()
        self.wall_time_running_s = 0.0  # wall time spent inside run() [s]
        self.behind_max_s = 0.0  # the most simulated time run() was ever due but not yet simulated [s]
        self._closed = False

    @classmethod
    async def create(cls, cfg: SitlConfig, records: list[dict[str, Any]] | None = None) -> Simulation:
        """Build the boats and open every MAVLink link; ``records`` also collects ground truth in memory."""
        recorder = Recorder(cfg.recorder.path, records)
        sim = cls(cfg, recorder)
        try:
            endpoints = [Endpoint.parse(text) for text in cfg.mavlink.endpoints]
            if cfg.mavlink.signing_key is not None:
                sim.signing_key = SigningKey.load(cfg.mavlink.signing_key)
            stride = cfg.mavlink.port_stride
            if stride == 0:
                for endpoint in endpoints:
                    await sim._open(endpoint, sim.boats)
            else:
                for k, boat in enumerate(sim.boats):
                    for endpoint in endpoints:
                        await sim._open(endpoint.with_port_offset(k * stride), [boat])
        except BaseException:
            await sim.close()
            raise
        return sim

    async def _open(self, endpoint: Endpoint, boats: list[Boat]) -> None:
        systems = tuple(b.sysid for b in boats)
        link = await open_link(endpoint, systems, self.signing_key, len(self.links), self._on_message)
        self.links.append(link)
        intervals = default_intervals(self.cfg.mavlink.streams)
        for boat in boats:
            writer = TelemetryWriter(boat, link.encoders[boat.sysid], self.cfg.origin, self.unix_time_at_boot_s)
            schedule = StreamSchedule(intervals, 1.0 / self.cfg.mavlink.heartbeat_hz, self.t)
            self.channels[(id(link), boat.sysid)] = inbound.Channel(
                boat, link, writer, schedule, self.cfg.origin, self._publish
            )

    # ---- queries ----------------------------------------------------------------------------------
    @property
    def t(self) -> float:
        """Simulated time [s]."""
        return self.steps * self.dt

    def addresses(self) -> dict[int, list[str]]:
        """System id -> the endpoints that reach it, with the ports actually bound (port 0 resolved)."""
        out: dict[int, list[str]] = {b.sysid: [] for b in self.boats}
        for link in self.links:
            ep = link.endpoint
            address = str(ep.with_port(link.local_address[1]) if ep.listens else ep)
            for sysid in link.encoders:
                out[sysid].append(address)
        return out

    def boat(self, sysid: int) -> Boat:
        return self.boats[sysid - 1]

    # ---- stepping ---------------------------------------------------------------------------------
    def step(self) -> None:
        """Advance everything by one physics step and send what is due."""
        t = self.t
        for boat in self.boats:
            boat.physics_step(t, self.dt)
        self.flow.advance(self.dt)
        self.steps += 1
        if self.steps % self.control_every == 0:
            for boat in self.boats:
                boat.control_step(self.control_every * self.dt)
        self._publish()
        for channel in self.channels.values():
            channel.send_due()
        if self.recorder.active and self.steps % self.record_every == 0:
            for boat in self.boats:
                self.recorder.state(boat)

    def _publish(self) -> None:
        """Send queued STATUSTEXTs and home changes on every link of each boat; log wall contacts."""
        for boat in self.boats:
            ap = boat.autopilot
            for event in boat.wall_events:
                log.warning(
                    "boat %d: wall contact (%s) at N %.2f E %.2f m, t = %.2f s",
                    boat.sysid,
                    "+".join(event.contact.walls),
                    event.contact.north_m,
                    event.contact.east_m,
                    event.t,
                )
                self.recorder.wall(event)
            boat.wall_events.clear()
            if not ap.statustexts and not ap.home_changed:
                continue
            channels = [c for (_, sysid), c in self.channels.items() if sysid == boat.sysid]
            for severity, text in ap.statustexts:
                log.info("boat %d: %s", boat.sysid, text)
                self.recorder.statustext(self.t, boat.sysid, int(severity), text)
                for channel in channels:
                    channel.writer.statustext(int(severity), text)
            ap.statustexts.clear()
            if ap.home_changed:
                for channel in channels:
                    channel.writer.home_position()
                ap.home_changed = False

    def _on_message(self, link: Link, msg: Any, arrived: float) -> None:
        for sysid in link.encoders:
            inbound.handle(self.channels[(id(link), sysid)], msg)
        # replies and STATUSTEXTs caused by the message leave now, not at the next step
        self._publish()

    # ---- running ----------------------------------------------------------------------------------
    def reset_pace(self) -> None:
        """Forget how far behind the pace run() fell so far (``behind_max_s``): measure from here."""
        self.behind_max_s = 0.0

    def stop(self) -> None:
        """Ask run() to return after the current slice (call from the loop's thread)."""
        self._stop.set()

    async def run(self, duration_s: float | None = None) -> None:
        """Run until stop(), or until ``duration_s`` more simulated seconds (default: config duration)."""
        if duration_s is None:
            duration_s = self.cfg.duration_s
        end_step = math.inf if duration_s is None else self.steps + round(duration_s / self.dt)
        speedup = self.cfg.speedup
        loop = asyncio.get_running_loop()
        wall0 = loop.time()
        step0 = self.steps
        self._stop.clear()
        try:
            while not self._stop.is_set() and self.steps < end_step:
                if speedup > 0:
                    due = step0 + math.floor((loop.time() - wall0) * speedup / self.dt + 1e-9)
                    # a late wake-up (a busy machine): the steps due are run in a burst, with no I/O
                    # between them; how far behind the pace this got tells whether a run was paced
                    self.behind_max_s = max(self.behind_max_s, (due - self.steps) * self.dt)
                    budget = min(due - self.steps, MAX_STEPS_PER_SLICE, end_step - self.steps)
                else:
                    budget = min(MAX_STEPS_PER_SLICE, end_step - self.steps)
                for _ in range(int(budget)):
                    self.step()
                if speedup > 0:
                    next_wall = wall0 + (self.steps + 1 - step0) * self.dt / speedup
                    await asyncio.sleep(max(0.0, next_wall - loop.time()))
                else:
                    await asyncio.sleep(0)
        finally:
            self.wall_time_running_s += loop.time() - wall0

    async def close(self) -> None:
        """Close every link and the recorder (idempotent); link counters stay readable."""
        if self._closed:
            return
        self._closed = True
        for link in self.links:
            await link.close()
        self.recorder.close()

    async def __aenter__(self) -> Simulation:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()


class SimulationThread:
    """A Simulation running on its own event loop in a background thread, for blocking callers.

    with SimulationThread(cfg) as sim:           # links are open when __enter__ returns
        sim.addresses()                          # as Simulation.addresses()
        sim.call(lambda s: s.boat(1).state)      # run a function on the simulator's thread
    """

    def __init__(self, cfg: SitlConfig, records: list[dict[str, Any]] | None = None):
        self.cfg = cfg
        self.records = records
        self._loop: asyncio.AbstractEventLoop | None = None
        self._sim: Simulation | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._main, name="sitl", daemon=True)

    def _main(self) -> None:
        asyncio.run(self._serve())

    async def _serve(self) -> None:
        self._loop = asyncio.get_running_loop()
        try:
            self._sim = await Simulation.create(self.cfg, self.records)
        except BaseException as exc:
            self._error = exc
            self._ready.set()
            return
        self._ready.set()
        try:
            await self._sim.run()
        finally:
            await self._sim.close()

    def __enter__(self) -> SimulationThread:
        self._thread.start()
        self._ready.wait()
        if self._error is not None:
            self._thread.join()
            raise self._error
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def close(self) -> None:
        if self._loop is not None and self._sim is not None and self._thread.is_alive():
            self._loop.call_soon_threadsafe(self._sim.stop)
        self._thread.join(timeout=10)

    def call(self, fn: Callable[[Simulation], T], timeout: float = 10.0) -> T:
        """Run ``fn(simulation)`` on the simulator's thread and return its result."""
        assert self._loop is not None and self._sim is not None
        future: concurrent.futures.Future[T] = concurrent.futures.Future()
        sim = self._sim

        def run() -> None:
            try:
                future.set_result(fn(sim))
            except Exception as exc:  # handed to the caller's thread, re-raised there
                future.set_exception(exc)

        self._loop.call_soon_threadsafe(run)
        return future.result(timeout)

    def addresses(self) -> dict[int, list[str]]:
        return self.call(lambda s: s.addresses())

    @property
    def t(self) -> float:
        """Simulated time now [s]."""
        return self.call(lambda s: s.t)

    @property
    def behind_max_s(self) -> float:
        """Simulation.behind_max_s: the furthest the simulator fell behind its pace so far [s]."""
        return self.call(lambda s: s.behind_max_s)
