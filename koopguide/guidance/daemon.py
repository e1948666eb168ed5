"""GuidanceDaemon: the asyncio service that steers a vehicle along a learned field over MAVLink.

    MAVLink in -> VehicleClock + KalmanTracker -> GuidanceLaw (frame, field, speed scaling, safety)
    -> SET_POSITION_TARGET_LOCAL_NED out;  status -> zenoh (StatusBus)

One event loop owns everything: the MAVLink connection (koopguide.mavlink Link), the estimator and the state
machine. A fresh position fix triggers a command at once when one is due (so latency is the time to
compute, not the time to the next tick); a timer in vehicle time covers late or missing fixes, so a
stale position turns into a zero-velocity command within one cycle. States (DESIGN.md): waiting ->
guiding -> arrived, with hold (stale fix, outside the domain/geofence) and fault (the field failed).

Conventions: positions and velocities in local NED [m, m/s]; vehicle time [s] from the vehicle's stamps.
"""

from __future__ import annotations

import asyncio
import collections
import logging
import math
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from koopguide.base import config as config_io
from koopguide.base.geodesy import geodetic_to_ned
from koopguide.guidance import vehicle
from koopguide.guidance.estimation.clock import VehicleClock
from koopguide.guidance.estimation.current import CurrentEstimator
from koopguide.guidance.estimation.tracker import KalmanTracker
from koopguide.guidance.law.command import ZERO, GuidanceLaw, GuidanceState, Setpoint, along_current, hold
from koopguide.guidance.link import open_link
from koopguide.guidance.settings import ArrivalAction, ExitMode, GuidanceConfig
from koopguide.mavlink.link import Link
from koopguide.model.field import load_field

log = logging.getLogger(__name__)

ATTITUDE_RATE_HZ = 10.0  # requested ATTITUDE rate (turn slowdown, current estimate) at most
ATTITUDE_PAIR_S = 0.2  # a heading this close in vehicle time to a fix pairs with it for the current estimate
SLACK = 0.25  # of a period: the timer commands this late when no fix triggered the due command
GEODETIC_PAIR_S = 0.25  # local and global fixes this close in vehicle time place a geodetic goal
SHUTDOWN_WAIT_S = 2.0  # wall seconds to see the exit mode confirmed
LATENCY_WINDOW = 2000  # fix-to-setpoint latencies kept for the percentiles


class LatencyWindow:
    """The latest fix-to-setpoint latencies [ms] and their percentiles."""

    def __init__(self, size: int = LATENCY_WINDOW) -> None:
        self.samples: collections.deque[float] = collections.deque(maxlen=size)

    def add(self, ms: float) -> None:
        self.samples.append(ms)

    def percentiles(self) -> dict[str, float | None]:
        if not self.samples:
            return {"p50": None, "p99": None}
        p50, p99 = np.percentile(np.fromiter(self.samples, float), [50, 99])
        return {"p50": round(float(p50), 4), "p99": round(float(p99), 4)}


class GuidanceDaemon:
    """Build with :meth:`create`; ``await run()`` until :meth:`stop`; then it has shut down cleanly."""

    def __init__(self, cfg: GuidanceConfig, model_path: Path, law: GuidanceLaw) -> None:
        self.cfg = cfg
        self.model_path = model_path
        self.law = law
        self.target = (cfg.mavlink.target_system, cfg.mavlink.target_component)
        self.period = 1.0 / cfg.command.rate_hz  # vehicle seconds between setpoints
        self.clock = VehicleClock()
        self.tracker = KalmanTracker(cfg.estimator)
        self.current = CurrentEstimator(cfg.estimator)
        self.view = vehicle.VehicleView()
        self.latency = LatencyWindow()
        self.link: Link | None = None
        self.bus: Any = None
        self.state = GuidanceState.IDLE
        self.reason: str | None = None
        self.arrived = False
        self.arrived_t: float | None = None  # vehicle time of arrival [s]
        self.settled = False  # after arrival: close enough to the goal (or long enough) to hand over to LOITER/HOLD
        self.goal_placed = cfg.frame.goal_latlon is None
        self.engaged = False  # GUIDED confirmed once; afterwards a mode change is the pilot's, not undone
        self.next_due = -math.inf  # vehicle time the next command is due
        self.fix_interval = 0.05  # typical vehicle time between position fixes [s], learned from them
        self.last_cmd = ZERO.copy()  # last velocity sent [m/s]
        self.max_cmd_speed = 0.0  # largest speed ever sent [m/s]
        self.setpoints_sent = 0
        self.mode_before_exit: str | None = None  # the vehicle's mode when shutdown began
        self.transitions: list[tuple[float, str]] = []  # (vehicle time, state) on each change
        self._stop = asyncio.Event()
        self._last_request: dict[str, float] = {}  # what -> wall time last sent
        self._streams_requested_wall: float | None = None
        self._link_was_up = False
        self._seq = 0
        self._boot = time.monotonic()

    # ------------------------------------------------------------------------------ lifecycle
    @classmethod
    async def create(cls, cfg: GuidanceConfig, model_path: Path, zenoh_config: Any | None = None) -> GuidanceDaemon:
        """Refuse a bad model or config (ValueError) before opening anything; then open MAVLink and zenoh."""
        law = GuidanceLaw.from_config(load_field(model_path), cfg)
        daemon = cls(cfg, Path(model_path), law)
        log.info("model %s: domain max field speed %.4g units/step -> %.3f m/s (gain %.4g)", model_path,
                 law.v_max, cfg.command.max_speed_mps, law.gain)
        daemon.link = await open_link(cfg.mavlink, daemon._on_message)
        if zenoh_config is not None:
            from koopguide.bus.status_bus import StatusBus

            daemon.bus = await StatusBus.create(cfg.vehicle_id, zenoh_config, daemon.sample_field,
                                                daemon.config_snapshot)
        daemon._set_state(GuidanceState.WAITING, "waiting for the vehicle's heartbeat")
        return daemon

    def stop(self) -> None:
        """Ask :meth:`run` to shut down (zero velocity, exit mode, close). Safe from signal handlers."""
        self._stop.set()

    async def run(self) -> None:
        tasks = [asyncio.create_task(self._control_loop()), asyncio.create_task(self._heartbeat_loop()),
                 asyncio.create_task(self._status_loop())]
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

    async def close(self) -> None:
        if self.link is not None:
            await self.link.close()
        if self.bus is not None:
            await self.bus.close()

    async def _shutdown(self) -> None:
        """Zero velocity, then the exit mode (only if we are still the one driving, in GUIDED)."""
        self.mode_before_exit = vehicle.mode_name(self.view.mode)
        sent = self._send_velocity(ZERO)
        if self.view.mode != vehicle.GUIDED or not self._link_up():
            log.info("shutdown: %s; vehicle mode %s left as it is",
                     "zero velocity sent" if sent else "link down, nothing sent", vehicle.mode_name(self.view.mode))
            return
        mode = vehicle.LOITER if self.cfg.failsafe.on_exit is ExitMode.LOITER else vehicle.HOLD
        deadline = time.monotonic() + SHUTDOWN_WAIT_S
        while time.monotonic() < deadline and self.view.mode != mode:
            self._send_velocity(ZERO)
            self._send(vehicle.set_mode(self.target, mode))
            await asyncio.sleep(0.1)
        log.info("shutdown: zero velocity sent; vehicle mode %s", vehicle.mode_name(self.view.mode))

    # ------------------------------------------------------------------------------ inbound
    def _on_message(self, msg: Any, arrived: float) -> None:
        stamp = getattr(msg, "time_boot_ms", None)
        if stamp is not None:
            self.clock.observe(stamp / 1000.0)
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            self._on_heartbeat(msg)
        elif kind == "LOCAL_POSITION_NED":
            self._on_fix(msg, arrived)
        elif kind == "ATTITUDE":
            if math.isfinite(msg.yaw) and math.isfinite(msg.yawspeed):
                self.view.attitude = (msg.time_boot_ms / 1000.0, float(msg.yaw), float(msg.yawspeed))
        elif kind == "GLOBAL_POSITION_INT":
            self.view.global_fix = (msg.time_boot_ms / 1000.0, msg.lat / 1e7, msg.lon / 1e7)
            self._place_geodetic_goal()
        elif kind == "COMMAND_ACK":
            if msg.result not in (0, 5):  # ACCEPTED, IN_PROGRESS
                log.warning("vehicle refused command %d (MAV_RESULT %d)", msg.command, msg.result)
        elif kind == "STATUSTEXT":
            log.info("vehicle says: %s", msg.text)

    def _on_heartbeat(self, msg: Any) -> None:
        view = self.view
        first = not self._link_up()
        view.heartbeat_wall = time.monotonic()
        view.mode = int(msg.custom_mode)
        view.armed = bool(msg.base_mode & vehicle.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
        if first:
            log.info("vehicle %d heartbeat: mode %s, %s", self.target[0], vehicle.mode_name(view.mode),
                     "armed" if view.armed else "disarmed")
            self._streams_requested_wall = None  # (re)request telemetry: it may have rebooted
        if view.mode == vehicle.GUIDED and not self.engaged:
            self.engaged = True
            log.info("vehicle in GUIDED")
        self._link_was_up = True

    def _on_fix(self, msg: Any, arrived: float) -> None:
        t = msg.time_boot_ms / 1000.0
        fix = np.array([msg.x, msg.y, msg.vx, msg.vy], dtype=float)
        if not np.all(np.isfinite(fix)):
            log.warning("LOCAL_POSITION_NED with non-finite values %s ignored", fix.tolist())
            return
        result = self.tracker.update(t, fix)
        if result.reset and self.tracker.resets > 1:
            log.warning("position estimate restarted at %s (jump or time gap)", np.round(fix[:2], 3).tolist())
        if not result.accepted:
            return
        if self.view.fix_t is not None and t > self.view.fix_t:  # typical interval between fixes
            self.fix_interval += 0.1 * (min(t - self.view.fix_t, 1.0) - self.fix_interval)
        self.view.fix_t, self.view.fix_ned = t, fix[:2]
        self._place_geodetic_goal()
        # A fix within half a fix interval of the due time triggers the command (so it goes out at once).
        if self.clock.now() >= self.next_due - min(SLACK * self.period, 0.5 * self.fix_interval):
            self._cycle(arrived)
        # After the command, off the fix-to-setpoint path (a filterpy update costs ~70 us): the current
        # changes over tens of seconds, so the command loses nothing by using the estimate one fix old.
        attitude = self.view.attitude
        if attitude is not None and abs(attitude[0] - t) <= ATTITUDE_PAIR_S:
            self.current.update(t, self.tracker.predict(t)[1], attitude[1], attitude[2])

    def _place_geodetic_goal(self) -> None:
        """Place a lat/lon goal in local NED once a local and a global fix of about the same moment exist."""
        goal = self.cfg.frame.goal_latlon
        view = self.view
        if self.goal_placed or goal is None or view.global_fix is None or view.fix_t is None:
            return
        t_global, lat, lon = view.global_fix
        if abs(t_global - view.fix_t) > GEODETIC_PAIR_S:
            return
        offset = np.array(geodetic_to_ned(goal[0], goal[1], lat, lon))
        goal_ned = tuple(float(v) for v in view.fix_ned + offset)
        self.law.frame = replace(self.law.frame, goal_ned=goal_ned)
        self.goal_placed = True
        log.info("geodetic goal %.7f, %.7f placed at NED %s m", goal[0], goal[1], np.round(goal_ned, 3).tolist())

    # ------------------------------------------------------------------------------ decisions
    def _link_up(self) -> bool:
        return self.view.link_up(time.monotonic(), self.cfg.mavlink.link_timeout_s)

    def position_age(self, now: float | None = None) -> float | None:
        if self.view.fix_t is None:
            return None
        return max(0.0, (self.clock.now() if now is None else now) - self.view.fix_t)

    def _cycle(self, fix_arrived: float | None = None) -> None:
        """One decision and (in GUIDED) one setpoint; ``fix_arrived`` (perf_counter) times the latency."""
        now = self.clock.now()
        self.next_due = now + self.period
        setpoint, send = self._decide(now)
        self._set_state(setpoint.state, setpoint.reason)
        if send:
            self._send_velocity(setpoint.velocity_ned, setpoint.yaw_rad if self.cfg.command.with_yaw else None)
            if fix_arrived is not None:
                self.latency.add((time.perf_counter() - fix_arrived) * 1000.0)

    def _decide(self, now: float) -> tuple[Setpoint, bool]:
        """The setpoint now, and whether to send it (only in GUIDED, and not once LOITER/HOLD took over)."""
        view, cfg = self.view, self.cfg
        in_guided = view.mode == vehicle.GUIDED
        if not self._link_up():
            if self._link_was_up:
                self._link_was_up = False
                log.warning("vehicle heartbeat lost for %.1f s; waiting for the link", cfg.mavlink.link_timeout_s)
            return Setpoint(ZERO, GuidanceState.WAITING, "no vehicle heartbeat"), False
        self._request_streams()
        age = self.position_age(now)
        if age is None:
            return Setpoint(ZERO, GuidanceState.WAITING, "waiting for LOCAL_POSITION_NED"), in_guided
        if age > cfg.failsafe.stale_after_s:
            return hold(f"no fresh position for {age:.2f} s"), in_guided
        if not self.goal_placed:
            return Setpoint(ZERO, GuidanceState.WAITING, "waiting for GLOBAL_POSITION_INT to place the goal"), in_guided
        if self.settled:
            keep = vehicle.LOITER if cfg.arrival.on_arrival is ArrivalAction.LOITER else vehicle.HOLD
            if view.mode != keep and in_guided:
                self._request("mode", vehicle.set_mode(self.target, keep))
            return Setpoint(ZERO, GuidanceState.ARRIVED), in_guided
        if not in_guided:
            if self.engaged:
                return Setpoint(ZERO, GuidanceState.WAITING,
                                f"vehicle left GUIDED (now {vehicle.mode_name(view.mode)}); not taking it back"), False
            self._request("mode", vehicle.set_mode(self.target, vehicle.GUIDED))
            return Setpoint(ZERO, GuidanceState.WAITING, "switching the vehicle to GUIDED"), False
        if not view.armed:
            if cfg.arm:
                self._request("arm", vehicle.arm(self.target))
                return Setpoint(ZERO, GuidanceState.WAITING, "arming"), True
            return Setpoint(ZERO, GuidanceState.WAITING, "vehicle disarmed (arm it, or run with --arm)"), True
        p, _ = self.tracker.predict(now + cfg.command.lead_s)
        attitude = view.attitude
        heading = attitude[1] if attitude is not None and now - attitude[0] <= cfg.failsafe.stale_after_s else None
        current = self.current.current_ned if heading is not None and self.current.updates else None
        setpoint = self.law.decide(p, self.arrived, heading, current)
        if setpoint.state is GuidanceState.ARRIVED and not self.arrived:
            self.arrived, self.arrived_t = True, now
            log.info("arrived: %.3f m from the goal at vehicle time %.1f s", self.law.distance_to_goal(p), now)
        if self.arrived and cfg.arrival.on_arrival is not ArrivalAction.STATION_KEEP:
            # Steer on onto the goal, facing along the current, before handing over: LOITER holds the point
            # where it is switched on (backing or driving into the current), and a boat turns too slowly to
            # face the current once LOITER has it.
            distance = self.law.distance_to_goal(p)
            done = distance <= cfg.arrival.settle_radius_m and along_current(heading, current, cfg.arrival.facing_deg)
            if done or now - self.arrived_t >= cfg.arrival.settle_timeout_s:
                self.settled = True
                log.info("settled %.3f m from the goal after %.1f s; switching to %s", distance,
                         now - self.arrived_t, cfg.arrival.on_arrival.value.upper())
                return self._decide(now)
        return setpoint, True

    def _request(self, what: str, msg: Any) -> None:
        """Send a command now, or again after ``command_retry_s`` until its effect is seen."""
        now = time.monotonic()
        if now - self._last_request.get(what, -math.inf) >= self.cfg.mavlink.command_retry_s:
            self._last_request[what] = now
            self._send(msg)

    def _request_streams(self) -> None:
        """Ask for the position messages on (re)connect, and again while none arrive."""
        now = time.monotonic()
        fresh = self.view.fix_t is not None and (self.position_age() or 0.0) < 2.0
        last = self._streams_requested_wall
        if last is not None and (fresh or now - last < self.cfg.mavlink.command_retry_s * 2):
            return
        self._streams_requested_wall = now
        cfg = self.cfg
        rate = cfg.mavlink.position_rate_hz
        self._send(vehicle.message_interval(self.target, vehicle.MSG_LOCAL_POSITION_NED, rate))
        if cfg.command.turn_slowdown or cfg.command.current_compensation:  # the heading changes slowly: 10 Hz is plenty
            self._send(vehicle.message_interval(self.target, vehicle.MSG_ATTITUDE, min(rate, ATTITUDE_RATE_HZ)))
        if cfg.frame.goal_latlon is not None:
            self._send(vehicle.message_interval(self.target, vehicle.MSG_GLOBAL_POSITION_INT, rate))

    # ------------------------------------------------------------------------------ outbound
    def _send(self, msg: Any) -> bool:
        return self.link is not None and self.link.send(msg)

    def _send_velocity(self, v: np.ndarray, yaw: float | None = None) -> bool:
        v = np.asarray(v, dtype=float)
        if not np.all(np.isfinite(v)):  # the last line of defence: never put a NaN on the wire
            v = ZERO
        ms = int((time.monotonic() - self._boot) * 1000)
        if self._send(vehicle.velocity_setpoint(self.target, ms, v, yaw)):
            self.last_cmd = v.copy()
            self.setpoints_sent += 1
            self.max_cmd_speed = max(self.max_cmd_speed, float(np.hypot(*v)))
            return True
        return False

    def _set_state(self, state: GuidanceState, reason: str | None) -> None:
        if state is not self.state:
            level = logging.WARNING if state in (GuidanceState.HOLD, GuidanceState.FAULT) else logging.INFO
            log.log(level, "state %s%s", state.value, f": {reason}" if reason else "")
            self.transitions.append((self.clock.now(), state.value))
        self.state, self.reason = state, reason

    # ------------------------------------------------------------------------------ loops
    async def _control_loop(self) -> None:
        """Commands when no fresh fix triggered one: at start-up, on stale positions, on a slow link."""
        while True:
            if not self.clock.started:
                self._cycle()
                await asyncio.sleep(0.05)
                continue
            if self.clock.now() >= self.next_due + SLACK * self.period:
                self._cycle()
            wait = self.clock.wall_seconds(self.next_due + SLACK * self.period - self.clock.now())
            await asyncio.sleep(min(max(wait, 0.0005), 0.1))

    async def _heartbeat_loop(self) -> None:
        period = 1.0 / self.cfg.mavlink.heartbeat_hz
        while True:
            self._send(vehicle.heartbeat())
            await asyncio.sleep(period)

    async def _status_loop(self) -> None:
        period = 1.0 / self.cfg.status.rate_hz
        while True:
            if self.bus is not None:
                self._seq += 1
                self.bus.publish(self.status())
            await asyncio.sleep(period)

    # ------------------------------------------------------------------------------ status
    def status(self) -> dict[str, Any]:
        """The status document (DESIGN.md "Zenoh status"): NED metres, m/s, seconds."""
        now = self.clock.now()
        position = velocity = distance = None
        if self.view.fix_t is not None:
            # a stale estimate is not run on: it stays where the last fix (plus the stale allowance) put it
            p, v = self.tracker.predict(min(now, self.view.fix_t + self.cfg.failsafe.stale_after_s))
            position, velocity = _rounded(p), _rounded(v)
            distance = round(self.law.distance_to_goal(p), 4)
        age = self.position_age(now)
        link = self.link.stats if self.link is not None else None
        return {
            "t": time.time(),
            "seq": self._seq,
            "vehicle_id": self.cfg.vehicle_id,
            "state": self.state.value,
            "reason": self.reason,
            "degraded": False,
            "mode": vehicle.mode_name(self.view.mode),
            "armed": self.view.armed,
            "position_ned": position,
            "velocity_ned": velocity,
            "goal_ned": _rounded(self.law.goal_ned) if self.goal_placed else None,
            "distance_to_goal_m": distance,
            "cmd_velocity_ned": _rounded(self.last_cmd),
            "speed_limit_mps": self.cfg.command.max_speed_mps,
            "position_age_s": None if age is None else round(age, 4),
            "loop_latency_ms": self.latency.percentiles(),
            "model": str(self.model_path),
            "vehicle_time_s": round(now, 3),
            "current_ned": _rounded(self.current.current_ned) if self.current.updates else None,
            "link": {"up": self._link_up(), "received": link.received, "foreign": link.foreign,
                     "corrupt": link.corrupt, "sent": link.sent, "reconnects": link.reconnects,
                     "unsigned": link.unsigned, "bad_signature": link.bad_signature,
                     "wrong_source": link.wrong_source, "source_changes": link.source_changes} if link else None,
        }

    def sample_field(self, params: dict[str, str]) -> dict[str, Any]:
        """The field on a grid in NED for the ``field`` queryable; ``n`` = grid points per axis."""
        text = params.get("n", str(self.cfg.status.field_grid))
        try:
            n = int(text)
        except ValueError:
            raise ValueError(f"field query: n must be an integer, got {text!r}") from None
        if not 2 <= n <= 200:
            raise ValueError(f"field query: n must be 2 .. 200, got {n}")
        if not self.goal_placed:
            raise ValueError("field query: the geodetic goal is not placed yet (no GLOBAL_POSITION_INT so far)")
        return self.law.sample_grid(n)

    def config_snapshot(self) -> dict[str, Any]:
        return {"config": config_io.to_plain(self.cfg), "model": str(self.model_path),
                "max_field_speed_units_per_step": self.law.v_max, "speed_gain": self.law.gain,
                "goal_ned": self.law.goal_ned.tolist() if self.goal_placed else None}


def _rounded(v: np.ndarray, digits: int = 4) -> list[float]:
    return [round(float(x), digits) for x in v]


