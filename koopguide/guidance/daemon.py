"""GuidanceDaemon: the asyncio service that steers a vehicle along a learned field over MAVLink (I/O only).

    mavlink.Link -> VehicleEvents (typed events, vehicle clock) -> Supervisor (pure state machine:
    checks, estimators, guidance law, states) -> Decision -> SET_POSITION_TARGET_LOCAL_NED, mode/arm/stream
    requests out;  status -> zenoh (StatusBus)

One event loop owns everything: the MAVLink connection, the timers and the status publisher; all the
decisions are the supervisor's (docs/architecture.md). A fresh position fix triggers a command at once
when one is due (so latency is the time to compute, not the time to the next tick); a timer in vehicle
time covers late or missing fixes, and watches the service's own output (no setpoint for two command
periods while guiding: fault, zero velocity). A restart of the vehicle's clock re-arms the schedule.

Conventions: positions and velocities in local NED [m, m/s]; vehicle time [s] from the vehicle's stamps.
"""

from __future__ import annotations

import asyncio
import gc
import logging
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from koopguide.base import config as config_io
from koopguide.base.modelfile import ModelFileError
from koopguide.bus.status import Status
from koopguide.guidance import events as ev
from koopguide.guidance.estimation.clock import VehicleClock
from koopguide.guidance.field_grid import FieldGrids
from koopguide.guidance.latency import LatencyWindow
from koopguide.guidance.law.command import GuidanceLaw, GuidanceState
from koopguide.guidance.link import open_link
from koopguide.guidance.neighbours import neighbour_event
from koopguide.guidance.operator import OperatorControl, load_token
from koopguide.guidance.recorder import MissionRecorder
from koopguide.guidance.settings import ExitMode, GuidanceConfig
from koopguide.guidance.status_report import service_status
from koopguide.guidance.supervisor import Supervisor
from koopguide.guidance.vehicle_events import VehicleEvents
from koopguide.mavlink import rover
from koopguide.mavlink.link import Link
from koopguide.model.certificate import certificate_ok
from koopguide.model.field import load_field

log = logging.getLogger(__name__)

SLACK = 0.25  # of a period: the timer commands this late when no fix triggered the due command
SHUTDOWN_WAIT_S = 2.0  # wall seconds to see the exit mode confirmed
NEIGHBOUR_POLL_S = 0.02  # how often the other vehicles' statuses are drained [s]


class GuidanceDaemon:
    """Build with :meth:`create`; ``await run()`` until :meth:`stop`; then it has shut down cleanly."""

    def __init__(self, cfg: GuidanceConfig, model_path: Path, law: GuidanceLaw, token: str | None = None) -> None:
        self.cfg = cfg
        self.model_path = model_path
        self.law = law
        self.field_grids = FieldGrids(model_path, cfg)  # the field queryable's grids, off the loop
        self.target = (cfg.mavlink.target_system, cfg.mavlink.target_component)
        self.period = 1.0 / cfg.command.rate_hz  # vehicle seconds between setpoints
        self.clock = VehicleClock(window_s=cfg.limits.clock_window_s, confirm=cfg.limits.clock_confirm)
        self.events = VehicleEvents(self.clock)
        self.supervisor = Supervisor(cfg, law)
        self.latency = LatencyWindow()
        self.link: Link | None = None
        self.bus: Any = None
        self.operator = OperatorControl(cfg.vehicle_id, token)  # the operator's hold (None token: disabled)
        self.recorder: MissionRecorder | None = None  # --log FILE.mcap
        self.next_due = -math.inf  # vehicle time the next command is due
        self.last_cmd = np.zeros(2)  # last velocity sent [m/s]
        self.max_cmd_speed = 0.0  # largest speed ever sent [m/s]
        self.setpoints_sent = 0
        self.mode_before_exit: str | None = None  # the vehicle's mode when shutdown began
        self._stop = asyncio.Event()
        self._seq = 0
        self._boot = time.monotonic()

    # ------------------------------------------------------------------------------ public view
    @property
    def state(self) -> GuidanceState:
        return self.supervisor.state

    @property
    def reason(self) -> str:
        return self.supervisor.reason

    @property
    def degraded(self) -> bool:
        return self.supervisor.degraded and self.supervisor.state is GuidanceState.GUIDING

    @property
    def arrived(self) -> bool:
        """Whether the boat has arrived at least once (the first arrival's vehicle time: ``arrived_t``)."""
        return self.supervisor.arrived_t is not None

    @property
    def transitions(self) -> list[tuple[float, str]]:
        return self.supervisor.transitions

    @property
    def rejected_inputs(self) -> dict[str, int]:
        """Inputs rejected by the sanity limits so far, by kind."""
        return dict(self.supervisor.vehicle.gate.counts)

    def position_age(self) -> float | None:
        return self.supervisor.vehicle.position_age(self.clock.now())

    def estimate(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The estimated position and velocity now (NED m, m/s), None before the first fix."""
        return self.supervisor.vehicle.estimate(self.clock.now())

    def drain_latencies(self) -> list[float]:
        """The fix-to-setpoint latencies [ms] measured since the last drain."""
        return self.latency.drain()

    # ------------------------------------------------------------------------------ lifecycle
    @classmethod
    async def create(
        cls, cfg: GuidanceConfig, model_path: Path, zenoh_config: Any | None = None, log_path: Path | None = None
    ) -> GuidanceDaemon:
        """Refuse a bad model, config or token file (ValueError) before opening anything; then open the
        mission log (``log_path``), MAVLink and zenoh."""
        field = load_field(model_path)
        certified, why = certificate_ok(field)
        if not certified:
            if not cfg.allow_uncertified:
                raise ModelFileError(
                    f"{model_path}: {why}; refusing to guide with it (allow_uncertified: true to override)"
                )
            log.warning("UNCERTIFIED MODEL %s: %s; guiding anyway (allow_uncertified)", model_path, why)
        law = GuidanceLaw.from_config(field, cfg)
        await asyncio.to_thread(lambda: law.along_table)  # built before the loop runs (the progress watchdog's)
        token_file = cfg.status.control_token_file
        daemon = cls(cfg, Path(model_path), law, None if token_file is None else load_token(token_file))
        log.info(
            "model %s: domain max field speed %.4g units/step -> %.3f m/s (gain %.4g)",
            model_path,
            law.v_max,
            cfg.command.max_speed_mps,
            law.gain,
        )
        if log_path is not None:
            daemon.recorder = MissionRecorder.create(Path(log_path), cfg, Path(model_path), daemon.supervisor)
        try:
            daemon.link = await open_link(cfg.mavlink, daemon._on_message)
            if zenoh_config is not None:
                from koopguide.bus.status_bus import StatusBus

                daemon.bus = await StatusBus.create(
                    cfg.vehicle_id,
                    zenoh_config,
                    daemon.sample_field,
                    daemon.config_snapshot,
                    daemon._on_control,
                    listen_to_others=cfg.fleet.enabled,
                )
        except BaseException:
            await daemon.close()
            raise
        daemon._cycle()  # waiting for the vehicle's heartbeat
        return daemon

    def stop(self) -> None:
        """Ask :meth:`run` to shut down (zero velocity, exit mode, close). Safe from signal handlers."""
        self._stop.set()

    async def run(self) -> None:
        """Until stop(); the objects made before sit out the collector's passes (gc.freeze, docs/architecture.md)."""
        gc.freeze()
        loops = (self._control_loop(), self._heartbeat_loop(), self._status_loop(), self._neighbour_loop())
        tasks = [asyncio.create_task(loop) for loop in loops]
        try:
            await self._stop.wait()
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            try:
                await self._shutdown()
            finally:
                await self.close()
                gc.unfreeze()

    async def close(self) -> None:
        try:
            if self.link is not None:
                await self.link.close()
            if self.bus is not None:
                await self.bus.close()
        finally:
            self.field_grids.close()
            if self.recorder is not None:
                self.recorder.close()

    async def _shutdown(self) -> None:
        """Zero velocity (at the current heading), then the exit mode (only if still in GUIDED)."""
        sup = self.supervisor
        self.mode_before_exit = rover.mode_name(sup.mode)
        sent = self._send_zero()
        if sup.mode != rover.GUIDED or not sup.link_up(time.monotonic()):
            log.info(
                "shutdown: %s; vehicle mode %s left as it is",
                "zero velocity sent" if sent else "link down, nothing sent",
                rover.mode_name(sup.mode),
            )
            return
        mode = rover.LOITER if self.cfg.failsafe.on_exit is ExitMode.LOITER else rover.HOLD
        deadline = time.monotonic() + SHUTDOWN_WAIT_S
        while time.monotonic() < deadline and sup.mode != mode:
            self._send_zero()
            self._send(rover.set_mode(self.target, mode))
            await asyncio.sleep(0.1)
        log.info("shutdown: zero velocity sent; vehicle mode %s", rover.mode_name(sup.mode))

    # ------------------------------------------------------------------------------ inbound
    def _on_message(self, msg: Any, arrived: float) -> None:
        """Decode, feed the supervisor; a fresh fix due for a command triggers it at once."""
        for event in self.events.decode(msg, time.monotonic()):
            if isinstance(event, ev.ClockRestart):
                self.next_due = -math.inf  # re-arm the command schedule in the new vehicle time
            if isinstance(event, ev.PositionFix):
                if self.supervisor.on_position(event):
                    self._after_fix(event, arrived)
            else:
                self.supervisor.handle(event)
        self._log_notes()

    def _after_fix(self, fix: ev.PositionFix, arrived: float) -> None:
        # A fix within half a fix interval of the due time triggers the command (so it goes out at once).
        interval = self.supervisor.vehicle.fix_interval
        if self.clock.now() >= self.next_due - min(SLACK * self.period, 0.5 * interval):
            self._cycle(arrived)
        # After the command, off the fix-to-setpoint path (a filterpy update costs ~70 us): the current
        # changes over tens of seconds, so the command loses nothing by using the estimate one fix old.
        self.supervisor.update_current(fix.t_s)
        if self.recorder is not None:  # the log too, after the command
            self.recorder.after_fix(fix)

    def _on_control(self, payload: bytes) -> None:
        """An operator's request from zenoh (on the event loop): verified, then the supervisor's."""
        event = self.operator.receive(payload, time.time(), time.monotonic())
        if event is not None:
            self.supervisor.handle(event)
            self._cycle()  # at once: a hold's zero velocity goes out now, not at the next command
        self._log_notes()

    # ------------------------------------------------------------------------------ decisions
    def _tick(self) -> ev.Tick:
        return ev.Tick(wall_s=time.monotonic(), t_s=self.clock.now())

    def _cycle(self, fix_arrived: float | None = None) -> None:
        """One decision and its setpoint and requests; ``fix_arrived`` (perf_counter) times the latency."""
        tick = self._tick()
        self.next_due = tick.t_s + self.period
        sent = self._apply(self.supervisor.decide(tick))
        if sent and fix_arrived is not None:
            self.latency.add((time.perf_counter() - fix_arrived) * 1000.0)

    def _apply(self, decision: ev.Decision) -> bool:
        """Send the decision's setpoint (True when one went out) and requests."""
        sent = decision.velocity_ned is not None and self._send_velocity(decision.velocity_ned, decision.yaw_rad)
        for request in decision.requests:
            self._send(self._request_message(request))
        self._log_notes()
        return sent

    def _request_message(self, request: ev.Request) -> Any:
        if isinstance(request, ev.SetMode):
            return rover.set_mode(self.target, request.mode)
        if isinstance(request, ev.Arm):
            return rover.arm(self.target)
        return rover.message_interval(self.target, request.message_id, request.rate_hz)

    def _log_notes(self) -> None:
        for note in self.events.take_notes() + self.supervisor.take_notes():
            log.log(note.level, "%s", note.text)

    # ------------------------------------------------------------------------------ outbound
    def _send(self, msg: Any) -> bool:
        return self.link is not None and self.link.send(msg)

    def _send_zero(self) -> bool:
        velocity, yaw = self.supervisor.zero_setpoint()
        return self._send_velocity(velocity, yaw)

    def _send_velocity(self, v: tuple[float, float] | np.ndarray, yaw: float | None = None) -> bool:
        vn, ve = float(v[0]), float(v[1])
        if not (math.isfinite(vn) and math.isfinite(ve)):  # the last line of defence: never a NaN on the wire
            vn = ve = 0.0
        ms = int((time.monotonic() - self._boot) * 1000)
        if self._send(rover.velocity_setpoint(self.target, ms, (vn, ve), yaw)):
            self.last_cmd = np.array((vn, ve))
            self.setpoints_sent += 1
            self.max_cmd_speed = max(self.max_cmd_speed, math.hypot(vn, ve))
            now = self.clock.now()
            self.supervisor.setpoint_sent(now)
            if self.recorder is not None:
                self.recorder.setpoint(now, (vn, ve), yaw)
            return True
        return False

    # ------------------------------------------------------------------------------ loops
    async def _control_loop(self) -> None:
        """Commands when no fresh fix triggered one (start-up, stale positions, a slow link), and the
        watchdog of the service's own output."""
        while True:
            if not self.clock.started:
                self._cycle()
                await asyncio.sleep(0.05)
                continue
            if self.clock.now() >= self.next_due + SLACK * self.period:
                self._cycle()
            fault = self.supervisor.check_output(self._tick())
            if fault is not None:
                self._apply(fault)
            wait = self.clock.wall_seconds(self.next_due + SLACK * self.period - self.clock.now())
            await asyncio.sleep(min(max(wait, 0.0005), 0.1))

    async def _heartbeat_loop(self) -> None:
        period = 1.0 / self.cfg.mavlink.heartbeat_hz
        while True:
            self._send(rover.heartbeat())
            await asyncio.sleep(period)

    async def _status_loop(self) -> None:
        period = 1.0 / self.cfg.status.rate_hz
        while True:
            if self.bus is not None or self.recorder is not None:
                self._seq += 1
                status = self.status()
                if self.bus is not None:
                    self.bus.publish(status)
                if self.recorder is not None:
                    await self.recorder.status(status, self.law.sample_grid)
            await asyncio.sleep(period)

    async def _neighbour_loop(self) -> None:
        """The other vehicles' statuses (zenoh ring channel, drained here on the loop) to the supervisor."""
        while self.bus is not None and self.cfg.fleet.enabled:
            for other in self.bus.take_others():
                event = neighbour_event(
                    other,
                    time.time(),
                    time.monotonic(),
                    self.clock.now(),
                    self.clock.rate,
                    self.cfg.fleet.neighbour_timeout_s,
                )
                if event is not None:
                    self.supervisor.handle(event)
            await asyncio.sleep(NEIGHBOUR_POLL_S)

    # ------------------------------------------------------------------------------ status
    def status(self) -> dict[str, Any]:
        """The status as the JSON object that is published (:meth:`status_document`)."""
        return self.status_document().to_dict()

    def status_document(self) -> Status:
        """The status (:class:`koopguide.bus.status.Status`, docs/zenoh.md): NED metres, m/s, seconds."""
        sup = self.supervisor
        status = service_status(
            self.cfg,
            sup,
            self.law,
            self.clock.now(),
            self._seq,
            self.last_cmd,
            self.latency.percentiles(),
            str(self.model_path),
            self.position_age(),
        )
        self._log_notes()  # the reacquire check may have noted why the boat is guided again
        link = self.link.stats if self.link is not None else None
        status.extras.update({
            "rejected_inputs": self.rejected_inputs,
            "control_ack": self.operator.ack,
            "control_refused": self.operator.refused,
            "link": {"up": sup.link_up(time.monotonic()), **link.status_counters()} if link else None,
        })  # fmt: skip
        return status

    async def sample_field(self, params: dict[str, str]) -> bytes:
        """The field on a grid in NED for the ``field`` queryable (JSON bytes); ``n`` = grid points per axis."""
        return await self.field_grids.answer(
            params, self.cfg.status.field_grid, self.supervisor.goal_placed, self.law.frame
        )

    def config_snapshot(self) -> dict[str, Any]:
        return {
            "config": config_io.to_plain(self.cfg),
            "model": str(self.model_path),
            "max_field_speed_units_per_step": self.law.v_max,
            "speed_gain": self.law.gain,
            "goal_ned": self.law.goal_ned.tolist() if self.supervisor.goal_placed else None,
        }
