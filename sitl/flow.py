"""Flow disturbances: water velocity V_c(N, E, t) in local NED [m/s], composable by summation.

Conventions: positions (N, E) in local NED [m], time t in simulated seconds, velocities returned as
(V_N, V_E) [m/s]. The deterministic fields are pure functions; the stochastic parts (Gauss-Markov
drift of a uniform current, gusts) are Ornstein-Uhlenbeck states advanced once per physics step with
Euler-Maruyama (sqrt(dt) scaling), held constant within a step, and shared by all boats.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sitl.config import DoubleGyreConfig, FlowConfig, FlowKind, VortexConfig


def uniform_velocity(speed_mps: float, direction_deg: float) -> tuple[float, float]:
    """A current of the given speed flowing toward the compass direction [deg] -> (V_N, V_E)."""
    a = math.radians(direction_deg)
    return speed_mps * math.cos(a), speed_mps * math.sin(a)


def lamb_oseen_velocity(n: float, e: float, cfg: VortexConfig) -> tuple[float, float]:
    """Lamb-Oseen vortex: v_theta = Gamma / (2 pi r) (1 - exp(-r^2 / r_c^2)), CCW seen from above."""
    dn = n - cfg.center_ned_m[0]
    de = e - cfg.center_ned_m[1]
    r2 = dn * dn + de * de
    if r2 < 1e-18:
        return 0.0, 0.0
    # v_theta / r; the counter-clockwise tangent (seen from above, north up) at (dn, de) is (de, -dn) / r
    w = cfg.circulation_m2ps / (2.0 * math.pi * r2) * (1.0 - math.exp(-r2 / cfg.core_radius_m**2))
    return w * de, -w * dn


def double_gyre_velocity(n: float, e: float, t: float, cfg: DoubleGyreConfig) -> tuple[float, float]:
    """Time-varying double gyre on [0, 2s] x [0, s] (x along north, y along east from the origin).

    f(x, t) = a x^2 / s + b x, a = eps sin(omega t), b = 1 - 2a
    u = -pi A sin(pi f / s) cos(pi y / s) - mu x
    v =  pi A cos(pi f / s) sin(pi y / s) df/dx - mu y
    With mu = 0 the field is divergence-free: it derives from the stream function
    A s sin(pi f/s) sin(pi y/s).
    """
    x = n - cfg.origin_ned_m[0]
    y = e - cfg.origin_ned_m[1]
    s = cfg.scale_m
    a = cfg.epsilon * math.sin(cfg.omega_radps * t)
    b = 1.0 - 2.0 * a
    f = a * x * x / s + b * x
    dfdx = 2.0 * a * x / s + b
    k = math.pi / s
    amp = math.pi * cfg.amplitude_mps
    mu = cfg.dissipation_per_s
    u = -amp * math.sin(k * f) * math.cos(k * y) - mu * x
    v = amp * math.cos(k * f) * math.sin(k * y) * dfdx - mu * y
    return u, v


@dataclass
class OrnsteinUhlenbeck2D:
    """A 2-D Gauss-Markov velocity: dV = -V / tau dt + sigma sqrt(2 / tau) dW (stationary std sigma)."""

    std_mps: float  # sigma [m/s]
    time_constant_s: float  # tau [s]
    vn: float = 0.0  # current value, north [m/s]
    ve: float = 0.0  # current value, east [m/s]

    def advance(self, dt: float, rng: np.random.Generator) -> None:
        """One Euler-Maruyama step of dt [s]."""
        if self.std_mps <= 0.0:
            return
        decay = dt / self.time_constant_s
        diffusion = self.std_mps * math.sqrt(2.0 * dt / self.time_constant_s)
        wn, we = rng.standard_normal(2)
        self.vn += -decay * self.vn + diffusion * float(wn)
        self.ve += -decay * self.ve + diffusion * float(we)


class Flow:
    """The configured sum of flow components; ``velocity`` is deterministic given the noise state."""

    def __init__(self, cfg: FlowConfig, rng: np.random.Generator):
        kinds = set(cfg.kinds) - {FlowKind.NONE}
        self.kinds = tuple(k for k in FlowKind if k in kinds)
        self._cfg = cfg
        self._rng = rng
        self._uniform = (
            uniform_velocity(cfg.uniform.speed_mps, cfg.uniform.direction_deg)
            if FlowKind.UNIFORM in kinds
            else (0.0, 0.0)
        )
        self._vortex = FlowKind.VORTEX in kinds
        self._gyre = FlowKind.DOUBLE_GYRE in kinds
        self._noise: list[OrnsteinUhlenbeck2D] = []
        if FlowKind.UNIFORM in kinds and cfg.uniform.drift_std_mps > 0:
            self._noise.append(OrnsteinUhlenbeck2D(cfg.uniform.drift_std_mps, cfg.uniform.drift_time_constant_s))
        if FlowKind.GUSTS in kinds and cfg.gusts.std_mps > 0:
            self._noise.append(OrnsteinUhlenbeck2D(cfg.gusts.std_mps, cfg.gusts.time_constant_s))
        self._offset = (0.0, 0.0)

    @property
    def calm(self) -> bool:
        """True when the water is still everywhere."""
        return not self.kinds

    def velocity(self, n: float, e: float, t: float) -> tuple[float, float]:
        """Water velocity (V_N, V_E) [m/s] at (n, e) [m] and time t [s]."""
        vn = self._uniform[0] + self._offset[0]
        ve = self._uniform[1] + self._offset[1]
        if self._vortex:
            a, b = lamb_oseen_velocity(n, e, self._cfg.vortex)
            vn += a
            ve += b
        if self._gyre:
            a, b = double_gyre_velocity(n, e, t, self._cfg.double_gyre)
            vn += a
            ve += b
        return vn, ve

    def advance(self, dt: float) -> None:
        """Advance the stochastic components by one step of dt [s] (Euler-Maruyama)."""
        if not self._noise:
            return
        vn = ve = 0.0
        for process in self._noise:
            process.advance(dt, self._rng)
            vn += process.vn
            ve += process.ve
        self._offset = (vn, ve)
