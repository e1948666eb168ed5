"""The helm: from the ground velocity the guidance wants to the setpoint that gets this boat there (pure).

Following the field, a boat that turns in place gets the law's velocity-only setpoint (crabbed into the current and
slowed to turn, law/command.py). Near a point (within the capture radius, keeping station, pursuing the goal
directly), and everywhere for a boat seen to need way through the water to turn, it gets a heading-and-speed
setpoint, ahead or astern (law/maneuver.py): that is what lets a skid-steer boat back onto a goal behind it instead
of circling it, and a rudder boat keep the way its rudder needs. How the boat turns, and how far it runs on when
told to stop, are learned from its telemetry (estimation/turning.py, estimation/speed_lag.py), first asked by the turn
probe (turn_probe.py); a boat seen to go where it is sent whatever its heading is sent velocities. What it knows of
the boat it reads from telemetry (boat_reading.py). In water the current estimator has seen to be sheared a boat that
needs way holds the still-water line near the goal: the current at the boat is no guide to the goal's there. It
arrives there off that line too, once its way would stop it within the arrival radius, and its capture search makes
for that and keeps it so (law/capture.py). See docs/guidance.md "Any boat".

Conventions: NED velocities ``(2,)`` [m/s], headings [rad] from north, turn rates [rad/s], vehicle seconds.
"""

from __future__ import annotations

import math

import numpy as np

from koopguide.guidance.boat_reading import BoatReading
from koopguide.guidance.law.command import (
    CRAB_MIN_SPEED_MPS,
    GuidanceLaw,
    GuidanceState,
    Setpoint,
    along_current,
)
from koopguide.guidance.law.line_approach import DEFAULT_RADIUS_M, LineApproach
from koopguide.guidance.law.maneuver import Maneuver, ManeuverPlanner, unit
from koopguide.guidance.settings import GuidanceConfig
from koopguide.guidance.turn_probe import Command, TurnProbe

LINE_CURRENT_SIGMAS = 2.0  # a current estimate this many of its standard deviations strong sets the holding line
LINE_DOING = "making for the line it can hold the goal on"  # near the goal, a boat that needs way, off its line
DRIFT_DOING = "drifting onto the goal on the current's line"  # near it, a boat that turns in place (law/maneuver.py)
LINE_RADII = 2.0  # a boat that needs way makes for its holding line from this many turning radii out
LINE_LEAVE = 1.25  # ... and goes back to following the field only beyond this many times that distance
HEADING_GAP_S = 1.0  # through an attitude gap this long a boat that needs way keeps its last command [s]
# how the boat came on station, for the arrival's log line (:meth:`Helm.on_station`; "": the usual way)
OFF_LINE_HOW = " (sheared water, off its line: its way would stop it within the arrival radius)"


class Helm(BoatReading):
    """Call :meth:`observe` once per command with the boat's state, then :meth:`near` or :meth:`follow`."""

    def __init__(self, cfg: GuidanceConfig, law: GuidanceLaw) -> None:
        super().__init__(cfg, law)
        command = cfg.command
        self.planner = ManeuverPlanner(
            command.max_speed_mps, command.turn_speed_mps, math.radians(cfg.arrival.facing_deg)
        )
        gain, settle = cfg.arrival.station_gain, 0.5 * cfg.arrival.radius_m
        self.line = LineApproach(
            command.max_speed_mps, gain, settle, command.turn_speed_mps, command.approach_speed_mps
        )
        self.doing = "following the field"  # what the last command did (for the status's reason)
        # other boats are heard (fleet): following the field and a boat that needs way go velocity-only, as the
        # separation filter expects; a boat that turns in place keeps its ahead-or-astern maneuver near a point
        self.in_company = False
        self.arrived = False  # the service has declared arrival (set by the supervisor each command)
        self.station_how = ""  # how the last on_station found the boat on station ("": the usual way)
        self._kept: tuple[float, Command] | None = None  # (vehicle time, the last command made with a heading)
        self.reset()

    def reset(self) -> None:
        """A restarted vehicle (maybe another boat): forget how it turns (and, at the start, set it up)."""
        super().reset()
        self.turn_probe = TurnProbe(self.cfg.command, self.law.outside_area)  # how it turns and stops, asked first
        self.planner.reset()
        self.line.reset()
        self.line.capture.forget()  # the circle it was seen to turn on in the capture's manoeuvres
        self._kept = None

    def probe(self, t: float, heading_rad: float | None, p_ned: np.ndarray | None = None) -> Command | None:
        """The turn probe's setpoint at the start of guiding (guidance/turn_probe.py), None once it is done."""
        water = None if self.current_ned is None else self.water_mps  # its way through the water, where known
        command = self.turn_probe.command(t, heading_rad, p_ned, self.ability, self.ground_ned, water)
        if command is not None:
            self.asked_heading, self.doing = self.turn_probe.heading, self.turn_probe.doing
        return command

    def lookahead_m(self) -> float | None:
        """The pursuit look-ahead for this boat: for a boat that needs way, at least twice its turning radius (pure
        pursuit asks for the curvature 2 sin(alpha) / L, so L >= 2 R never asks for a circle tighter than R: Coulter
        (1992), "Implementation of the pure pursuit path tracking algorithm"); None: as configured."""
        radius = self.ability.radius_m
        needs = self.ability.needs_way and radius is not None and not self.in_company
        return max(self.cfg.command.lookahead_m, 2.0 * radius) if needs else None

    def on_station(self, heading_rad: float | None, offset_ned: np.ndarray | None = None) -> bool:
        """Whether the boat can stay where it is, ``offset_ned`` [m] from the goal (boat - goal; None: not known here).
        A boat that needs way only once it holds its line (on it, facing along it: law/line_approach.py) and, in water
        not seen to be sheared, would come to rest within the arrival radius (:meth:`coasts_within`); crossing the
        arrival radius at way, off the line, is not arriving. In sheared water, where its line is the still-water one
        and the current at the goal turns under it, also once its way would stop it within the arrival radius
        (:meth:`stops_within`): there no line is held, as a boat that turns in place holds none. Nor is it before the
        turn probe has told whether the boat turns in place (a rudder boat that started by the goal would otherwise be
        held as one that pivots: it shuttled ahead and astern 0.3-0.45 m off for a minute). In company the distance
        alone decides; without a heading too, unless the boat is known to need way: then a tick whose attitude is stale
        tells nothing about its line (such ticks are 1 in 2000, yet 72 of 2632 traced rudder arrivals came on one,
        crossing the goal at way with the bow up to 48 deg off the line: half of those in uniform currents then held
        over 0.2 m p95). A boat that turns in place, in a current (not sheared water: there the current at the boat
        turns as it goes), once its hull lies within ``facing_deg`` of the current's line, either end: one across it is
        carried off while it turns (7 deg/s: 0.2-0.4 m in 0.03 m/s). A current within one spread of nothing gives no
        line (a hull that slips more spreads the estimate: 0.015 m/s about a 0.03 m/s current, where the rudder boat's
        two spreads left a skid-steer one arriving across it)."""
        self.station_how = ""
        if self.in_company:
            return True
        a = self.ability
        if heading_rad is None:
            return not a.needs_way
        if not (a.pivot_seen or a.needs_way or self.cfg.command.probe_turn_s <= 0.0):
            return False
        if a.needs_way:
            if self.line.holding:
                return self.sheared or offset_ned is None or self.coasts_within(offset_ned)
            if self.sheared and offset_ned is not None and self.stops_within(offset_ned, heading_rad):
                self.station_how = OFF_LINE_HOW
            return bool(self.station_how)
        c = self._line_current(self._current(self.current_ned), 1.0)  # clear of its spread: a line to hold to
        return self.sheared or along_current(heading_rad, c, self.cfg.arrival.facing_deg)

    def coasts_within(self, offset_ned: np.ndarray) -> bool:
        """Whether the boat holding its line, ``offset_ned`` [m] from the goal (boat - goal), comes to rest over ground
        within the arrival radius, its ground velocity dying away over its stopping time (a kinematic rudder boat of a
        2 s lag, declared arrived crossing the goal at 0.16-0.2 m/s, ran on 0.22-0.31 m: stop 47). At the area's edge
        (no ground velocity) the hold decides. Not asked in sheared water, where the current under the boat, which no
        command stops, is most of its ground velocity (the rudder boat then missed a double gyre start)."""
        return self.ground_ned is None or self._rests_within(offset_ned, self.ground_ned)

    def stops_within(self, offset_ned: np.ndarray, heading_rad: float) -> bool:
        """Whether the boat, ``offset_ned`` [m] from the goal (boat - goal) and heading ``heading_rad`` [rad], would
        come to rest within the arrival radius: its way through the water dies away over its stopping time
        (estimation/speed_lag.py), so it runs on ``u tau`` [m] along its heading (astern: back along it; the current it
        drifts on is no part of that: no command stops it). A rudder boat in sheared water passed within the radius
        of the goal in 13 of its 14 misses of 252 (vortex and double gyre, seeds 50-52), lining its bow up on a
        still-water line the current turned it off for a minute and more. Taking the run-on as going anywhere
        (``d + |u| tau``) left it missing those it ran on toward the goal (stop 46)."""
        return self._rests_within(offset_ned, self.water_mps * unit(heading_rad))

    def _rests_within(self, offset_ned: np.ndarray, velocity_ned: np.ndarray) -> bool:
        """Whether a boat ``offset_ned`` [m] from the goal whose ``velocity_ned`` [m/s] dies away over its stopping time
        (estimation/speed_lag.py: it runs on ``velocity tau``) comes to rest within the arrival radius."""
        rest = np.asarray(offset_ned, dtype=float) + self.lags.stopping.lag_s * np.asarray(velocity_ned, dtype=float)
        return float(np.hypot(*rest)) <= self.cfg.arrival.radius_m

    def line_radius_m(self) -> float:
        """Within this distance of the goal a boat that needs way makes for the line it will hold (twice its
        turning radius: it has room to turn onto the line), and at least within the capture radius; once it does,
        ``LINE_LEAVE`` times as far (without the hysteresis a boat about that distance out, whose approach path
        begins with a leg astern, crossed it to and fro: every crossing dropped the path and the next one planned
        another, and a rudder boat that slips more than the simulator's (Y_v -3 kg/s) backed and filled 2 m out
        for 18 s, Zshape demo start 3 in a current toward the west, stop 35), nor while its planned approach takes it
        further (a kinematic rudder boat of a 0.6 m circle, planned a leg astern 1.1 m out, left it 1.5 m out and
        followed the field back for 9 s, stop 50)."""
        radius = self.ability.radius_m if self.ability.radius_m is not None else DEFAULT_RADIUS_M
        making = LINE_LEAVE if self.line.axis_rad is not None else 1.0  # making for the line already
        way = max(making * LINE_RADII * radius, self.line.path.reach_m(self.law.goal_ned))
        return max(self.cfg.arrival.capture_radius_m, way if self.ability.needs_way else 0.0)

    def near(
        self,
        p_ned: np.ndarray,
        wanted_ned: np.ndarray,
        heading_rad: float | None,
        current_ned: np.ndarray | None,
        distance_m: float,
        bias_ned: np.ndarray | None = None,
        holding: bool = False,
    ) -> Command:
        """Toward the goal ``distance_m`` away at ground velocity ``wanted_ned``: heading and speed, ahead or
        astern (a boat that needs way: along the line it will hold, law/line_approach.py, its speed from the
        distance plus the station keeper's integral term ``bias_ned`` [m/s]). ``holding``: keeping station (a boat
        that turns in place keeps its hull on the current's line, law/maneuver.py)."""
        if (kept := self._keeping(heading_rad)) is not None:
            return kept
        if heading_rad is None or (self.in_company and self.ability.needs_way):
            # no attitude: all that can be sent is a velocity; among other boats the separation filter shapes a boat
            # that needs way's velocities (law/separation.py reads them as Rover does). A boat that turns in place goes
            # ahead or astern even in company: pivoting 180 deg to a point just behind it takes ~25 s at 7 deg/s.
            current = self._current(current_ned)
            return self._velocity(self.law.steer(wanted_ned, heading_rad, current, CRAB_MIN_SPEED_MPS))
        if self.ability.needs_way:
            return self._on_line(p_ned, heading_rad, current_ned, bias_ned)
        self.line.reset()
        m = self.planner.plan(
            wanted_ned,
            heading_rad,
            self._current(current_ned),
            self.ability,
            distance_m,
            slow_to_turn=self.cfg.command.turn_slowdown,
            holding=holding,
            allow_astern=self.lags.sternway.able,
            t=self.t,
        )
        self.doing = DRIFT_DOING if self.planner.drifting and not holding else self.doing
        return self._maneuver(m)

    def follow(
        self,
        p_ned: np.ndarray,
        sp: Setpoint,
        heading_rad: float | None,
        current_ned: np.ndarray | None,
        distance_m: float,
    ) -> Command:
        """Following the field: the law's setpoint ``sp``, or heading and speed for a boat that needs way."""
        if self.ability.needs_way and heading_rad is not None and sp.ground_ned is not None and not self.in_company:
            if distance_m <= self.line_radius_m():
                self.doing = LINE_DOING  # within two turning radii: a planned approach onto the line, not the field
                return self._on_line(p_ned, heading_rad, current_ned)
            self.line.reset()
            m = self.planner.plan(
                sp.ground_ned,
                heading_rad,
                self._current(current_ned),
                self.ability,
                slow_to_turn=False,
                allow_astern=self.lags.sternway.able,
            )
            return self._maneuver(m)
        self.planner.reset()
        self.line.reset()
        return self._velocity(np.asarray(sp.velocity_ned, dtype=float))

    def command(
        self,
        p_ned: np.ndarray,
        sp: Setpoint,
        heading_rad: float | None,
        current_ned: np.ndarray | None,
        distance_m: float,
    ) -> Command:
        """The law's decision ``sp`` (guiding, hold, fault) as a setpoint: within the capture radius as near a
        point, beyond it as following the field (after the turn probe, :meth:`probe`); a zero or non-guiding
        decision goes as it is."""
        within = sp.state is GuidanceState.ARRIVED and not self.on_station(heading_rad)
        if not within and (sp.state is not GuidanceState.GUIDING or sp.ground_ned is None):
            return np.asarray(sp.velocity_ned, dtype=float), None
        if (probe := self.probe(self.t, heading_rad, p_ned) if self.t is not None else None) is not None:
            return probe
        if (kept := self._keeping(heading_rad)) is not None:  # what it does goes on
            return kept
        self.doing = "following the field"
        if within:
            # within the arrival radius, not yet holding its line (the supervisor has not arrived): still on the way; a
            # boat that turns in place turns onto the current's line as it keeps station
            self.doing = LINE_DOING
            wanted = self.law.station_velocity(p_ned, self._current(current_ned))
            return self.near(p_ned, wanted, heading_rad, current_ned, distance_m, holding=True)
        if distance_m <= self.cfg.arrival.capture_radius_m:
            cmd = self.near(p_ned, sp.ground_ned, heading_rad, current_ned, distance_m)
            self.doing = LINE_DOING if self.ability.needs_way and not self.on_station(heading_rad) else self.doing
            return cmd
        return self.follow(p_ned, sp, heading_rad, current_ned, distance_m)

    def yaw_for(self, velocity: tuple[float, float], yaw: float | None, heading_rad: float | None) -> float | None:
        """The yaw to send with ``velocity`` [rad]: the helm's own (``yaw``); else the velocity's direction with
        ``command.with_yaw``; a zero velocity goes at the current heading with ``failsafe.zero_with_yaw``
        (velocity-only zero is "heading north at speed 0" to Rover, and a skid-steer boat would pivot north)."""
        if yaw is not None:
            return yaw
        if math.hypot(*velocity) > 1e-9:
            return math.atan2(velocity[1], velocity[0]) if self.cfg.command.with_yaw else None
        return heading_rad if self.cfg.failsafe.zero_with_yaw else None

    def _on_line(
        self, p_ned: np.ndarray, heading_rad: float, current_ned: np.ndarray | None, bias_ned: np.ndarray | None = None
    ) -> Command:
        # the line follows a current only once the estimate is clear of its own spread (early on its direction swings
        # with every turn, and so would the line), and until it is within one spread of nothing
        c = self._line_current(self._current(current_ned), 1.0 if self.line.in_current else LINE_CURRENT_SIGMAS)
        # in sheared water the current at the boat is no guide to the goal's (the campaign's double gyre turns it 90 deg
        # within 0.3 m of the goal): a line along the estimate swung 5-15 deg/s, and the boat chasing it lined up too
        # late or never (86.7% arrived in 180 runs); the still-water line, kept once chosen, 94.4%. The capture search
        # drifts its model boat on the estimate at the boat (within 0.5 m of the goal, near the goal's) except while
        # shear is seen there and then (the gyre's current by the goal turns round every 10 s: drifting on it anyway,
        # seeds 31-32 arrived 65 and 62 of 72 times, against 69 without)
        drift, c = (None if self.shearing else c), (None if self.sheared else c)
        self.line.aim(p_ned, self.law.goal_ned, heading_rad, c, drift, self.t if self.arrived else None)
        self.line.stop_s = self.lags.stopping.lag_s
        self.line.capture.lags_s = (self.lags.ahead.lag_s, self.lags.astern.lag_s)
        self.line.capture.circle_speed_mps = self.ability.radius_speed_mps
        self.line.astern_able = self.lags.sternway.able
        self.line.cycle.holds_at_rest = self.line.capture.holds_at_rest = self.lags.rest.holds
        # in sheared water it arrives off its line at rest (stops_within): the capture search makes for that, and
        # keeps it there (once arrived, lining it up took it 0.3 m p95 off in the median double gyre run, stop 45)
        self.line.capture.point_only = self.sheared
        m = self.line.command(
            p_ned,
            self.law.goal_ned,
            heading_rad,
            self.ability.radius_m,
            current_ned=c,
            speed_mps=self.speed_mps,
            water_mps=self.water_mps,
            bias_ned=bias_ned,
            outside=self.law.outside_area,
            t=self.t,
            arrived=self.arrived,
        )
        return self._maneuver(m)

    def _maneuver(self, m: Maneuver) -> Command:
        """Ahead (a positive speed over ground along the heading) goes as velocity only, which Rover reads the same way
        (heading: its direction, speed: its norm), as any vehicle that follows velocities; astern or 0 needs the yaw."""
        self.asked_heading = m.heading_rad
        command = m.velocity_ned, (None if m.speed_mps > 0.0 else m.heading_rad)
        self._kept = None if self.t is None else (self.t, command)
        return command

    def _keeping(self, heading_rad: float | None) -> Command | None:
        """On a tick without a heading (its attitude late), for up to ``HEADING_GAP_S``: the command with a heading a
        boat that needs way was last given, its manoeuvre kept, so long as it was the last to go out (not a hold or
        another state's command since) and the boat is not in company (there it goes by velocity). Sent the field's
        velocity instead, it dropped its capture search and planned approach; at the campaign's 10x speed, 2-16 ticks
        of a sheared rudder run found the attitude 0.5 s old, each just after a capture search (stop 55)."""
        if heading_rad is not None or self._kept is None or self.t is None:
            return None
        if self.in_company or not self.ability.needs_way:
            return None
        t, command = self._kept
        last = self.sent_ned is not None and np.allclose(self.sent_ned, command[0], rtol=0.0, atol=1e-9)
        return command if last and 0.0 <= self.t - t <= HEADING_GAP_S else None

    def _velocity(self, v: np.ndarray) -> Command:
        self._kept = None
        self.asked_heading = math.atan2(v[1], v[0]) if float(np.hypot(*v)) > 1e-9 else self.asked_heading
        return v, None
