"""What the helm reads of its boat from telemetry (pure): its way through the water, how it turns (estimation/
turning.py) and stops (estimation/speed_lag.py), the current estimate it is steered on, whether the water has shown
shear, and what was last asked of it. The helm (helm.py) builds its commands on this reading.

Conventions: NED velocities ``(2,)`` [m/s], headings [rad] from north, turn rates [rad/s], vehicle seconds.
"""

from __future__ import annotations

import math

import numpy as np

from koopguide.guidance.estimation.speed_lag import BoatLags
from koopguide.guidance.estimation.turning import TurnAbility
from koopguide.guidance.law.approach_path import STOP_GAIN
from koopguide.guidance.law.area import at_edge, off_edge
from koopguide.guidance.law.capture import SPEED_LAG_S
from koopguide.guidance.law.command import CURRENT_MIN_MPS, GuidanceLaw
from koopguide.guidance.law.maneuver import unit, wrap_pi
from koopguide.guidance.settings import GuidanceConfig

SHEARED_WEIGHT = 0.5  # the current estimator's shear weight beyond which the water is sheared (estimation/current.py)


class BoatReading:
    """Call :meth:`observe` once per command with the boat's state, and :meth:`sent` with what went out."""

    def __init__(self, cfg: GuidanceConfig, law: GuidanceLaw) -> None:
        self.cfg, self.law = cfg, law
        self.speed_mps = 0.0  # the boat's ground speed at the last observation [m/s]
        self.water_mps = 0.0  # ... and its speed through the water along its heading (negative: astern) [m/s]
        self.ground_ned: np.ndarray | None = None  # ... its ground velocity (None at the area's edge) [m/s]
        self.t: float | None = None  # vehicle time of the last observation [s]
        self.current_ned: np.ndarray | None = None  # the current estimate [m/s]
        self.current_std = 0.0  # the current estimate's spread [m/s]
        self.sheared = False  # the water has shown shear (latched: a property of the water, not of the boat)
        self.shearing = False  # ... and shows it now
        self.asked_heading: float | None = None  # the heading the last setpoint asked for [rad]
        self.sent_ned: np.ndarray | None = None  # the velocity last sent [m/s] (None: none went out)
        self.asked_mps: float | None = None  # speed over ground along the heading last sent (<0: astern; :meth:`sent`)
        self.ability: TurnAbility
        self.lags: BoatLags
        BoatReading.reset(self)  # how it turns and stops (not self.reset: a subclass's reset needs its own parts)

    def reset(self) -> None:
        """A restarted vehicle (maybe another boat): forget how it turns and stops."""
        self.ability = TurnAbility()
        self.lags = BoatLags(1.0 / STOP_GAIN, SPEED_LAG_S)  # how its way follows speed 0, ahead and astern
        self.asked_heading = None

    def observe(
        self,
        t: float,
        heading_rad: float | None,
        turn_rate_radps: float | None,
        velocity_ned: np.ndarray | None,
        current_ned: np.ndarray | None,
        current_std_mps: float = 0.0,
        shear_weight: float = 0.0,
        at_edge: bool = False,
        off_edge: bool = False,
    ) -> None:
        """The boat's heading, turn rate, ground velocity and the estimated current (and its spread, and how much
        shear its estimator sees: ``CurrentEstimator.shear_weight``) at vehicle time ``t``. ``at_edge``: the boat
        is at the area's edge (:meth:`at_edge`), where a wall may turn or stop it: how it turns and stops is not
        learned there (a rudder boat of a 2.4 m circle set onto a tank's wall turned on it as if on a 0.8 m one,
        and the approach planned on that circle backed and filled by the wall for a minute, stop 35); ``off_edge``: not
        what holds it at speed 0 (:meth:`edge_state`)."""
        self.t, self.current_ned, self.current_std = t, current_ned, current_std_mps
        self.shearing = shear_weight > SHEARED_WEIGHT  # the estimator sees shear now
        self.sheared = self.sheared or self.shearing
        if velocity_ned is not None:
            self.speed_mps = float(np.hypot(*velocity_ned))
        if heading_rad is None or turn_rate_radps is None or velocity_ned is None:
            return
        water = np.asarray(velocity_ned, dtype=float) - (0.0 if current_ned is None else np.asarray(current_ned))
        u = float(water[0] * math.cos(heading_rad) + water[1] * math.sin(heading_rad))
        self.water_mps = u
        self.ground_ned = None if at_edge else np.asarray(velocity_ned, dtype=float)  # a wall sets a boat sideways
        c = 0.0 if current_ned is None else float(np.asarray(current_ned) @ unit(heading_rad))
        asked = None if self.asked_heading is None else wrap_pi(self.asked_heading - heading_rad)
        pivots = None if self.ability.needs_way else asked  # a boat that turns in place may be turning first
        at_rest = off_edge and self.asked_mps == 0.0 and self.lags.sternway.able  # a wall can't hold it off the current
        self.lags.update(t, None if at_edge and not at_rest else self.asked_mps, c, u, pivots, not self.sheared)
        if at_edge or self.ability.moves_sideways:  # a boat that goes where it is sent turns as it will
            return
        self.ability.update(t, asked, u, turn_rate_radps, way_known=current_ned is not None)

    def at_edge(self, p_ned: np.ndarray) -> bool:
        """Whether ``p_ned`` [m] lies at the area's edge or beyond it, where a wall may set, stop or turn a boat
        (law/area.py ``at_edge``)."""
        return at_edge(self.law.outside_area, p_ned)

    def edge_state(self, p_ned: np.ndarray, current_ned: np.ndarray | None) -> tuple[bool, bool]:
        """(:meth:`at_edge`; and carried clear of the edge by ``current_ned``, law/area.py ``off_edge``)."""
        edge = self.at_edge(p_ned)
        return edge, edge and off_edge(self.law.outside_area, p_ned, current_ned)

    def sent(self, velocity: tuple[float, float] | None, yaw: float | None = None) -> None:
        """The setpoint that went out this tick, ``velocity`` [m/s] (None: none) and its ``yaw`` [rad] (None: velocity
        only, which Rover drives ahead along it): what :attr:`lags` learn the boat's way from."""
        if velocity is None:
            self.asked_mps = self.sent_ned = None
            return
        v = self.sent_ned = np.asarray(velocity, dtype=float)
        self.asked_mps = float(np.hypot(*v)) if yaw is None else float(v @ unit(yaw))

    def water_sent(self) -> tuple[np.ndarray, float] | None:
        """The boat's velocity through the water [m/s] and the spread of its way along the heading, where known: a boat
        that goes where it is sent (as sent; none sent: at rest); one stopped in sheared water (0, its way dying away:
        ``BoatLags.way_left_mps``, stop 54). None otherwise: its slip measures the current."""
        if self.ability.moves_sideways:
            return (np.zeros(2) if self.sent_ned is None else self.sent_ned), 0.0
        way = self.lags.way_left_mps if self.sheared else None
        return None if way is None else (np.zeros(2), way)

    def _line_current(self, c: np.ndarray | None, sigmas: float) -> np.ndarray | None:
        """The current estimate ``c`` when it is clear of ``sigmas`` of its spread (and of ``CURRENT_MIN_MPS``)."""
        return c if c is not None and float(np.hypot(*c)) >= max(CURRENT_MIN_MPS, sigmas * self.current_std) else None

    def _current(self, current_ned: np.ndarray | None) -> np.ndarray | None:
        return current_ned if self.cfg.command.current_compensation else None
