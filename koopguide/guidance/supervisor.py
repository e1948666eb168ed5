"""The guidance supervisor: a pure state machine from typed events to decisions (no I/O, no clocks).

    events (heartbeat, position fix, attitude, global fix, clock restart, rejected input, tick)
      -> InputGate / TeleportGuard -> KalmanTracker, CurrentEstimator -> GuidanceLaw / StationKeeper
      -> Decision (setpoint, state, reason, degraded, requests: set mode, arm, message intervals)

States (docs/guidance.md): waiting (no heartbeat, no position, not in GUIDED, disarmed) -> guiding -> arrived; hold
(stale position, teleporting positions, outside the domain or geofence); fault (the field failed, or setpoints stopped
going out). ``arrived`` is left for ``guiding`` when the boat may drift beyond ``arrival.reacquire_radius_m``;
``degraded`` marks guiding by direct pursuit of the goal after the progress watchdog saw no progress along the field
for ``failsafe.stall_s``. Every decision has a reason. Time is passed in: ``t_s`` the vehicle's clock [s], ``wall_s``
the service's monotonic clock [s] (heartbeat timeouts, request retries, log rate). Conventions: local NED [m], [m/s];
headings [rad] from north.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from koopguide.guidance import events as ev
from koopguide.guidance.estimation.progress import ProgressWatchdog
from koopguide.guidance.helm import Helm
from koopguide.guidance.law.command import GuidanceLaw, GuidanceState, along_current
from koopguide.guidance.law.maneuver import within_speed
from koopguide.guidance.law.station import StationKeeper
from koopguide.guidance.neighbours import Neighbours
from koopguide.guidance.requests import RequestSchedule
from koopguide.guidance.settings import ArrivalAction, GuidanceConfig
from koopguide.guidance.vehicle_state import VehicleState
from koopguide.mavlink import rover

HONEST_LEAD_S = 0.25  # leave arrived on where the boat will be this long after a fix [s], or stale_after_s if longer
HONEST_SIGMAS = 2.0  # ... and when it may be beyond the reacquire radius by this many of the estimate's spreads
OUTPUT_GAP_PERIODS = 2.0  # no setpoint for this many command periods while guiding/arrived: fault
ZERO = (0.0, 0.0)
S = GuidanceState

Velocity = tuple[float, float]  # (vN, vE) [m/s]
Requests = list[ev.Request] | tuple[ev.Request, ...]


class Supervisor:
    """Feed events with :meth:`handle`; a ``Tick`` returns the decision. Read ``take_notes()`` to log."""

    def __init__(self, cfg: GuidanceConfig, law: GuidanceLaw) -> None:
        self.cfg, self.law = cfg, law
        self.period = 1.0 / cfg.command.rate_hz  # vehicle seconds between setpoints
        self.vehicle = VehicleState(cfg)  # checked estimates: position, velocity, heading, current
        self.station = StationKeeper.from_config(cfg)  # PI feedback onto the goal (station keeping, pursuit)
        self.progress = ProgressWatchdog(cfg.failsafe.stall_s, cfg.failsafe.stall_progress_m)
        self.helm = Helm(cfg, law)  # wanted ground velocity -> setpoint for this boat (how it turns is learned)
        self.heartbeat_wall: float | None = None  # the vehicle's last heartbeat (service clock) [s]
        self.mode, self.armed = None, None  # the vehicle's as last heard (None: not yet)
        # the state machine
        self.state, self.reason, self.degraded = S.IDLE, "not started", False
        self.arrived = False  # within the arrival radius and not since drifted beyond the reacquire radius
        self.back_reason = ""  # why guiding again after an arrival (until the next one)
        self.arrived_t: float | None = None  # vehicle time of the first arrival [s]
        self.settled = False  # handed over to LOITER/HOLD after arrival
        self.reclaim = False  # drifted off after the hand-over: take GUIDED back
        self.engaged = False  # GUIDED confirmed once; afterwards a mode change is the pilot's
        self.goal_placed = cfg.frame.goal_latlon is None
        self.last_sent_t: float | None = None  # vehicle time of the last setpoint that went out
        self.output_fault = False
        self.link_was_up = False
        self.schedule = RequestSchedule(cfg)  # mode, arm and telemetry requests, and their retries
        self.transitions: list[tuple[float, str]] = []  # (vehicle time, state) on each change
        self.restarts = 0  # vehicle clock restarts seen (reboots and jumps)
        self.operator_hold: str | None = None  # who holds the boat (an operator's request); None: not held
        self._notes: list[ev.Note] = []
        self._wall = -math.inf  # the service clock of the decision being made [s]
        self.neighbours = Neighbours(cfg.vehicle_id, cfg.fleet, cfg.command.max_speed_mps)  # other boats heard
        self.separation_active = False  # the last setpoint was changed to keep min_separation_m
        self.closest_neighbour_m: float | None = None  # [m] at the last setpoint

    # ------------------------------------------------------------------------------ events
    def handle(self, event: ev.Event) -> ev.Decision | None:
        """Fold in one event; a :class:`~koopguide.guidance.events.Tick` returns the decision for that moment."""
        if isinstance(event, ev.Tick):
            return self.decide(event)
        if isinstance(event, ev.PositionFix):
            self.on_position(event)
        elif isinstance(event, ev.Heartbeat):
            self.on_heartbeat(event)
        elif isinstance(event, ev.Attitude):
            self.vehicle.on_attitude(event)
        elif isinstance(event, ev.GlobalFix):
            self.vehicle.on_global(event)
            self._place_geodetic_goal()
        elif isinstance(event, ev.ClockRestart):
            self.on_clock_restart(event)
        elif isinstance(event, ev.InputRejected):
            self.vehicle.gate.reject(event.kind, event.detail, event.wall_s)
        elif isinstance(event, ev.OperatorHold):
            self.on_operator(event)
        elif isinstance(event, ev.NeighbourStatus):
            self.neighbours.hear(event)
        return None

    def on_heartbeat(self, hb: ev.Heartbeat) -> None:
        first = not self.link_up(hb.wall_s)
        gap = None if self.heartbeat_wall is None else hb.wall_s - self.heartbeat_wall
        if first or (gap is not None and gap > self.cfg.failsafe.heartbeat_gap_s):
            self.schedule.streams_due = True  # (re)request telemetry: the vehicle may have rebooted
            if not first:
                self._note(logging.WARNING, f"vehicle heartbeat gap of {gap:.1f} s; requesting telemetry again")
        self.heartbeat_wall, self.mode, self.armed = hb.wall_s, hb.mode, hb.armed
        if first:
            armed = "armed" if hb.armed else "disarmed"
            self._note(logging.INFO, f"vehicle heartbeat: mode {rover.mode_name(hb.mode)}, {armed}")
        if hb.mode == rover.GUIDED:
            self.reclaim = False
            if not self.engaged:
                self.engaged = True
                self._note(logging.INFO, "vehicle in GUIDED")
        self.link_was_up = True

    def on_position(self, fix: ev.PositionFix) -> bool:
        """Fold in a fix; False when it was rejected (out of bounds, out of order, a teleport)."""
        if not self.vehicle.on_position(fix):
            return False
        self._place_geodetic_goal()
        if self.arrived:  # status honesty: leave arrived on the fix that shows the drift, not a tick later
            ahead = self.vehicle.tracker.predict(fix.t_s + max(HONEST_LEAD_S, self.cfg.failsafe.stale_after_s))[0]
            self.reacquire_if_drifted(self.law.distance_to_goal(ahead), fix.t_s)
        return True

    def update_current(self, t: float) -> None:
        """After the command: the fix at ``t`` into the current (all of it while disarmed; less the velocity sent to a
        boat that goes where it is sent, whose slip is its motion), unless at the edge (a wall's slip)."""
        if not self.helm.at_edge(self.vehicle.tracker.predict(t)[0]):
            drifting = self.armed is False
            self.vehicle.update_current(t, drifting, None if drifting else self.helm.water_sent())

    def on_clock_restart(self, restart: ev.ClockRestart) -> None:
        what = "went back (a reboot)" if restart.rebooted else "jumped forward"
        self._note(
            logging.WARNING,
            f"vehicle clock {what} from {restart.previous_s:.3f} s to {restart.t_s:.3f} s: "
            "estimates reset, command schedule re-armed, telemetry requested again",
        )
        self.restarts += 1
        self._restart_estimates(forget_fixes=True)
        self.last_sent_t, self.output_fault = None, False
        self.schedule.streams_due = True
        if restart.rebooted:
            self.engaged = False  # a rebooted vehicle's mode is not the pilot's choice: take GUIDED again

    def on_operator(self, request: ev.OperatorHold) -> None:
        """An operator's hold (zero velocity, state hold) or resume (guide again, progress watched afresh)."""
        if request.active:
            self._note(logging.WARNING, f"operator hold from {request.source}")
            self.operator_hold = request.source
        elif self.operator_hold is not None:
            self._note(logging.INFO, f"operator resume from {request.source} (held by {self.operator_hold})")
            self.operator_hold = None
            self.progress.reset()

    def setpoint_sent(self, t: float) -> None:
        """The service put a setpoint on the wire at vehicle time ``t``."""
        self.last_sent_t = t
        self.output_fault = False

    # ------------------------------------------------------------------------------ decisions
    def link_up(self, wall: float) -> bool:
        return self.heartbeat_wall is not None and wall - self.heartbeat_wall <= self.cfg.mavlink.link_timeout_s

    def check_output(self, tick: ev.Tick) -> ev.Decision | None:
        """The watchdog of the service's own output: guiding or arrived in GUIDED, yet no setpoint for
        OUTPUT_GAP_PERIODS command periods, is a fault (zero velocity, and the reason)."""
        if self.state not in (S.GUIDING, S.ARRIVED) or self.mode != rover.GUIDED or self.last_sent_t is None:
            return None
        gap = tick.t_s - self.last_sent_t
        if gap <= OUTPUT_GAP_PERIODS * self.period:
            return None
        self.output_fault = True
        return self._out(
            ZERO,
            S.FAULT,
            f"no setpoint sent for {gap:.2f} s (over {OUTPUT_GAP_PERIODS:g} command periods of {self.period:.3f} s)",
            send=True,
            t=tick.t_s,
        )

    def decide(self, tick: ev.Tick) -> ev.Decision:
        now, wall, cfg = tick.t_s, tick.wall_s, self.cfg
        self._wall = wall
        in_guided = self.mode == rover.GUIDED
        if not self.link_up(wall):
            if self.link_was_up:
                self.link_was_up = False
                lost = f"vehicle heartbeat lost for {cfg.mavlink.link_timeout_s:.1f} s; waiting for the link"
                self._note(logging.WARNING, lost)
            return self._out(ZERO, S.WAITING, "no vehicle heartbeat", send=False, t=now)
        requests = self.schedule.streams(self.vehicle.position_age(now), wall)
        if self.operator_hold is not None:  # before everything but the link: no mode change, no arming
            return self._out(ZERO, S.HOLD, f"operator hold ({self.operator_hold})", in_guided, now, requests)
        age = self.vehicle.position_age(now)
        if age is None:
            return self._out(ZERO, S.WAITING, "waiting for LOCAL_POSITION_NED", in_guided, now, requests)
        if age > cfg.failsafe.stale_after_s:
            return self._out(ZERO, S.HOLD, f"no fresh position for {age:.2f} s", in_guided, now, requests)
        if now < self.vehicle.teleport_until:
            return self._out(ZERO, S.HOLD, self.vehicle.teleport_reason, in_guided, now, requests)
        if not self.goal_placed:
            return self._out(
                ZERO, S.WAITING, "waiting for GLOBAL_POSITION_INT to place the goal", in_guided, now, requests
            )
        if self.settled:
            return self._handed_over(now, wall, requests)
        if not in_guided:
            if self.engaged and not self.reclaim:
                why = f"vehicle left GUIDED (now {rover.mode_name(self.mode)}); not taking it back"
                return self._out(ZERO, S.WAITING, why, False, now, requests)
            requests += self.schedule.once_per_retry("mode", ev.SetMode(rover.GUIDED), wall)
            return self._out(ZERO, S.WAITING, "switching the vehicle to GUIDED", False, now, requests)
        if not self.armed:
            if cfg.arm:
                requests += self.schedule.once_per_retry("arm", ev.Arm(), wall)
                return self._out(ZERO, S.WAITING, "arming", True, now, requests)
            return self._out(ZERO, S.WAITING, "vehicle disarmed (arm it, or run with --arm)", True, now, requests)
        return self._guide(now, wall, requests)

    def _handed_over(self, now: float, wall: float, requests: list[ev.Request]) -> ev.Decision:
        keep = rover.LOITER if self.cfg.arrival.on_arrival is ArrivalAction.LOITER else rover.HOLD
        in_guided = self.mode == rover.GUIDED
        if self.mode != keep and in_guided:
            requests += self.schedule.once_per_retry("mode", ev.SetMode(keep), wall)
        return self._out(ZERO, S.ARRIVED, f"arrived; {rover.mode_name(keep)} holds the boat", in_guided, now, requests)

    def _guide(self, now: float, wall: float, requests: list[ev.Request]) -> ev.Decision:
        cfg, law, arrival = self.cfg, self.law, self.cfg.arrival
        p, v_est = self.vehicle.tracker.predict(now + cfg.command.lead_s)
        heading = self.vehicle.heading_at(now)
        estimator = self.vehicle.current
        sideways = self.helm.ability.moves_sideways  # its heading tells nothing of how it moves (update_current)
        current = estimator.current_ned if (heading is not None or sideways) and estimator.updates else None
        rate = self.vehicle.attitude[2] if heading is not None and self.vehicle.attitude else None
        edge = self.helm.edge_state(p, current)  # (at the area's edge, carried off it)
        astern, holds = self.helm.lags.sternway.able, self.helm.lags.rest.holds
        self.helm.observe(now, heading, rate, v_est, current, estimator.seen_std_mps, estimator.shear_weight, *edge)
        if astern and not self.helm.lags.sternway.able:  # estimation/speed_lag.py SternwayTrial
            self._note(logging.WARNING, "the boat gathered no sternway when asked astern: guiding it ahead only")
        if self.helm.lags.rest.holds and not holds:  # estimation/speed_lag.py RestHold
            self._note(logging.WARNING, "speed 0 holds the boat's ground against the current: it is modelled so")
        heading = None if sideways else heading
        self.helm.in_company = self.cfg.fleet.enabled and bool(self.neighbours.latest)
        distance, error = law.distance_to_goal(p), law.goal_ned - p
        if self.arrived:
            self.reacquire_if_drifted(distance, now)
        elif distance <= arrival.radius_m and self.helm.on_station(heading, -error):
            self.arrived, self.degraded, self.back_reason = True, False, ""
            self.arrived_t = now if self.arrived_t is None else self.arrived_t
            how = self.helm.station_how
            self._note(logging.INFO, f"arrived: {distance:.3f} m from the goal at vehicle time {now:.1f} s{how}")
        self.helm.arrived = self.arrived
        # drifted off, within the capture radius: station keeping (reported as guiding), not the approach's speed floor
        drifted_near = bool(self.back_reason) and distance <= arrival.capture_radius_m and not self.degraded
        state = S.GUIDING
        if self.arrived or drifted_near:
            wanted = self.station.update(now, error, law.station_velocity(p, current))  # P (capped) + I
            v, yaw = self.helm.near(p, wanted, heading, current, distance, self.station.integral, holding=True)
            if drifted_near and self.progress.update(now, p, wanted, distance):
                return self._start_pursuit(now, wall, distance, requests)
            if drifted_near:
                reason = f"{self.back_reason}keeping station onto the goal, {distance:.2f} m away"
            elif arrival.on_arrival is not ArrivalAction.STATION_KEEP and self._settle(distance, heading, current, now):
                return self._handed_over(now, wall, requests)
            else:
                state = S.ARRIVED
                reason = f"{distance:.2f} m from the goal (within reacquire_radius_m {arrival.reacquire_radius_m:g})"
                reason += "; keeping station"
        elif self.degraded:
            wanted = self.station.update(now, error, integrate=False)  # the way to go is no bias
            speed = float(np.hypot(*wanted))
            if 1e-12 < speed < cfg.command.min_speed_mps:  # direct pursuit makes progress
                wanted = wanted * (cfg.command.min_speed_mps / speed)
            # within the arrival radius, not on station yet (across the current): onto its line, as keeping station
            holding = distance <= arrival.radius_m
            v, yaw = self.helm.near(p, wanted, heading, current, distance, self.station.integral, holding=holding)
            why = " (no progress in direct pursuit either)" if self.progress.update(now, p, wanted, distance) else ""
            reason = f"direct pursuit of the goal, {distance:.2f} m away: no progress along the field for "
            reason += f"{cfg.failsafe.stall_s:g} s{why}"
        else:
            sp = law.decide(p, False, heading, current, self.helm.lookahead_m())
            along = law.distance_along_field(p) if sp.state is S.GUIDING else None
            if sp.state is S.GUIDING and self.progress.update(now, p, sp.ground_ned, distance, along):
                return self._start_pursuit(now, wall, distance, requests)
            v, yaw = self.helm.command(p, sp, heading, current, distance)
            state, reason = (
                S.GUIDING if sp.state is S.ARRIVED else sp.state,  # within the radius, not on station: on the way
                sp.reason or f"{self.back_reason}{self.helm.doing}, {distance:.2f} m from the goal",
            )
        return self._out(tuple(v), state, reason, True, now, requests, yaw)

    def _start_pursuit(self, now: float, wall: float, distance: float, requests: list[ev.Request]) -> ev.Decision:
        self.degraded = True
        self.progress.reset()
        why = f"no progress along the field for {self.cfg.failsafe.stall_s:g} s, {distance:.2f} m from the goal"
        self._note(logging.WARNING, f"{why}: switching to direct pursuit")
        return self._guide(now, wall, requests)

    def _settle(self, distance: float, heading: float | None, current: np.ndarray | None, now: float) -> bool:
        """loiter/hold on arrival: steer on onto the goal, facing along the current, then hand over (LOITER holds
        the point where it is switched on; a boat turns too slowly to face the current once LOITER has it)."""
        arrival = self.cfg.arrival
        done = distance <= arrival.settle_radius_m and along_current(heading, current, arrival.facing_deg)
        if not (done or now - self.arrived_t >= arrival.settle_timeout_s):
            return False
        self.settled, after, mode = True, now - self.arrived_t, arrival.on_arrival.value.upper()
        self._note(logging.INFO, f"settled {distance:.3f} m from the goal after {after:.1f} s; switching to {mode}")
        return True

    def reacquire_if_drifted(self, distance: float, now: float) -> None:
        """Leave arrived for guiding if ``distance`` [m] plus the estimate's spread may exceed reacquire_radius_m."""
        limit = self.cfg.arrival.reacquire_radius_m
        reach = distance + HONEST_SIGMAS * self.vehicle.tracker.position_std_m()  # as far as it may be [m]
        if not self.arrived or reach <= limit:
            return
        spread = f" ({reach:.2f} m with the estimate's spread)" if distance <= limit else ""
        reason = f"drifted {distance:.2f} m from the goal{spread}, beyond reacquire_radius_m {limit:g}: guiding back"
        self.back_reason = reason.replace(": guiding back", "; ")
        self._note(logging.WARNING, reason)
        self.arrived, self.reclaim, self.settled, self.degraded = False, self.settled, False, False
        self.progress.reset()  # the station keeper's integral stays: a bias of the boat or the current
        self._set_state(S.GUIDING, reason, now)

    def _restart_estimates(self, forget_fixes: bool = False) -> None:
        self.vehicle.restart(forget_fixes)
        self.helm.reset()
        self.station.reset()
        self.progress.reset()
        self.degraded = False

    # ------------------------------------------------------------------------------ output
    def _out(
        self,
        v: Velocity,
        state: S,
        reason: str,
        send: bool,
        t: float,
        requests: Requests = (),
        yaw: float | None = None,
    ) -> ev.Decision:
        """The decision; ``yaw`` [rad]: a heading-and-speed setpoint (velocity + yaw) from the helm."""
        if self.output_fault and state in (S.GUIDING, S.ARRIVED):
            state, reason = S.FAULT, f"setpoints are not going out ({self.reason})"
        self.separation_active = False
        if send and state in (S.GUIDING, S.ARRIVED) and self.cfg.fleet.enabled and self.neighbours.latest:
            v, reason, yaw = self._keep_separation(v, reason, t, yaw)
        self._set_state(state, reason, t)
        velocity = within_speed(v, self.cfg.command.max_speed_mps) if send else None  # never over, even by an ulp
        guided = yaw if state in (S.GUIDING, S.ARRIVED) else None
        yaw = None if velocity is None else self.helm.yaw_for(velocity, guided, self.vehicle.heading_rad)
        self.helm.sent(velocity, yaw)
        return ev.Decision(velocity, yaw, state, reason, self.degraded and state is S.GUIDING, tuple(requests))

    def _keep_separation(
        self, v: tuple[float, float], reason: str, t: float, yaw: float | None
    ) -> tuple[tuple[float, float], str, float | None]:
        """(velocity, reason, yaw) filtered to keep fleet.min_separation_m from the boats heard (neighbours.py)."""
        estimate = self.vehicle.estimate(t)
        if estimate is None:
            return v, reason, yaw
        out = self.neighbours.keep_separation(
            estimate[0], v, t, self._wall, self.vehicle.heading_at(t), estimate[1], yaw
        )
        self.separation_active, self.closest_neighbour_m = out.active, out.closest_m
        return out.velocity_ned, f"{reason}; {out.note}" if out.active else reason, out.yaw_rad

    def zero_setpoint(self) -> tuple[tuple[float, float], float | None]:
        """Zero velocity, and the yaw that goes with it (the current heading, when so configured and known)."""
        return ZERO, self.helm.yaw_for(ZERO, None, self.vehicle.heading_rad)

    def _set_state(self, state: S, reason: str, t: float) -> None:
        if state is not self.state:
            level = logging.WARNING if state in (S.HOLD, S.FAULT) else logging.INFO
            self._note(level, f"state {state.value}: {reason}")
            self.transitions.append((t, state.value))
        self.state, self.reason = state, reason

    def _place_geodetic_goal(self) -> None:
        goal = self.cfg.frame.goal_latlon
        goal_ned = None if self.goal_placed or goal is None else self.vehicle.geodetic_to_local(goal)
        if goal_ned is not None:
            self.law.place_goal(goal_ned)
            self.goal_placed = True
            self._note(logging.INFO, f"geodetic goal {goal[0]:.7f}, {goal[1]:.7f} placed at NED {goal_ned} m")

    def _note(self, level: int, text: str) -> None:
        self._notes.append(ev.Note(level, text))

    def take_notes(self) -> list[ev.Note]:
        """The log lines since the last call (the supervisor's and the input gate's)."""
        notes, self._notes = self._notes + self.vehicle.take_notes(), []
        return notes
