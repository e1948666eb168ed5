"""Sensors: what the autopilot and the telemetry see of a boat, with noise, rate, latency and dropouts.

Conventions: positions (N, E) in local NED [m], velocities (V_N, V_E) in NED [m/s], heading psi in
[-pi, pi) from north [rad], yaw rate [rad/s], times in simulated seconds. A position fix is taken
every 1/rate_hz from the true state, loses a fix with ``dropout_probability``, gets white noise, and
becomes available ``latency_s`` later. Heading and yaw rate are sampled when the controller runs.
Each boat's sensors draw from their own random generator, at simulated-time instants only, so a run
is reproducible for a given seed at any speed-up.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass

import numpy as np

from sitl.config import SensorConfig


@dataclass(frozen=True)
class Truth:
    """The true kinematic state of a boat at time t."""

    t: float  # simulated time [s]
    n: float  # north [m]
    e: float  # east [m]
    psi: float  # heading [rad]
    r: float  # yaw rate [rad/s]
    vn: float  # velocity over ground, north [m/s]
    ve: float  # velocity over ground, east [m/s]


@dataclass(frozen=True)
class PositionFix:
    t: float  # time the fix was measured [s]
    n: float  # [m]
    e: float  # [m]
    vn: float  # [m/s]
    ve: float  # [m/s]


def wrap_pi(angle: float) -> float:
    """Angle wrapped to [-pi, pi) [rad]."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


class Sensors:
    def __init__(self, cfg: SensorConfig, rng: np.random.Generator):
        self._cfg = cfg
        self._rng = rng
        self._period = 1.0 / cfg.position.rate_hz
        self._next_fix_t = 0.0
        self._in_flight: collections.deque[tuple[float, PositionFix]] = collections.deque()
        self.fix: PositionFix | None = None  # latest available position fix
        self.psi = 0.0  # latest heading measurement [rad]
        self.r = 0.0  # latest yaw-rate measurement [rad/s]
        self.fixes_taken = 0
        self.fixes_dropped = 0

    def update(self, truth: Truth) -> None:
        """Take any fix due at truth.t and release fixes whose latency has passed."""
        pos = self._cfg.position
        if truth.t + 1e-9 >= self._next_fix_t:
            self._next_fix_t += self._period
            if self._next_fix_t <= truth.t:  # resynchronise after a long step
                self._next_fix_t = truth.t + self._period
            self.fixes_taken += 1
            noise = self._rng.standard_normal(4)
            dropped = pos.dropout_probability > 0 and float(self._rng.random()) < pos.dropout_probability
            if dropped:
                self.fixes_dropped += 1
            else:
                fix = PositionFix(
                    t=truth.t,
                    n=truth.n + pos.noise_std_m * float(noise[0]),
                    e=truth.e + pos.noise_std_m * float(noise[1]),
                    vn=truth.vn + pos.velocity_noise_std_mps * float(noise[2]),
                    ve=truth.ve + pos.velocity_noise_std_mps * float(noise[3]),
                )
                self._in_flight.append((truth.t + pos.latency_s, fix))
        while self._in_flight and self._in_flight[0][0] <= truth.t + 1e-9:
            self.fix = self._in_flight.popleft()[1]

    def sample_attitude(self, truth: Truth) -> None:
        """Measure heading and yaw rate now (compass/IMU-like, white noise)."""
        h = self._cfg.heading
        noise = self._rng.standard_normal(2)
        self.psi = wrap_pi(truth.psi + math.radians(h.noise_std_deg) * float(noise[0]))
        self.r = truth.r + math.radians(h.rate_noise_std_degps) * float(noise[1])

    def position_healthy(self, t: float) -> bool:
        """A recent fix exists (younger than ``unhealthy_after_s``)."""
        return self.fix is not None and t - self.fix.t <= self._cfg.position.unhealthy_after_s
