"""One simulated boat: its state, thrusters, sensors and autopilot, stepped in simulated time.

The state vector follows sitl.vessel (eta = [N, E, psi] in local NED, nu_r = [u_r, v_r, r] relative to
the water, then the actuator states of the boat's kind, sitl.vehicles). The boat integrates its own
equations of motion with RK4 through the shared flow, stays inside the tank, and runs its autopilot at
the control rate. It does no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sitl.autopilot import Autopilot, Navigation, Severity
from sitl.config import SitlConfig
from sitl.flow import Flow
from sitl.integrate import rk4_step
from sitl.sensors import Sensors, Truth, wrap_pi
from sitl.vehicles import VehicleParams, actuator_demands, derivative, initial_actuators, thrusts
from sitl.vessel import State, ground_velocity
from sitl.world import WALL_RELEASE_M, Tank, WallContact


@dataclass(frozen=True)
class WallEvent:
    t: float  # simulated time of first contact [s]
    sysid: int
    contact: WallContact


class Boat:
    def __init__(
        self,
        sysid: int,
        cfg: SitlConfig,
        params: VehicleParams,
        flow: Flow,
        tank: Tank,
        pose: tuple[float, float, float],
        rng: np.random.Generator,
    ):
        self.sysid = sysid
        self.params = params
        self.flow = flow
        self.tank = tank
        n, e, heading_deg = pose
        if not tank.contains(n, e):
            raise ValueError(
                f"start pose of boat {sysid}: ({n}, {e}) m is outside the tank walls "
                f"(north {tank.n_min:.2f}..{tank.n_max:.2f}, east {tank.e_min:.2f}..{tank.e_max:.2f} m)"
            )
        self.state: State = (n, e, wrap_pi(math.radians(heading_deg)), 0.0, 0.0, 0.0, *initial_actuators(params))
        self.sensors = Sensors(cfg.sensors, rng)
        self.autopilot = Autopilot(cfg.autopilot, home=(n, e), kind=params.kind)
        self.wall: WallContact | None = None
        self.wall_events: list[WallEvent] = []
        self.t = 0.0
        self.sensors.update(self.truth())
        self.sensors.sample_attitude(self.truth())

    # ---- simulation ---------------------------------------------------------------------------
    def physics_step(self, t: float, dt: float) -> None:
        """Advance the boat from t to t + dt [s] (RK4; the actuator commands are held)."""
        p = self.params
        demands = actuator_demands(self.autopilot.commands, p)
        velocity = self.flow.velocity

        def x_dot(tt: float, x: State) -> State:
            vc_n, vc_e = velocity(x[0], x[1], tt)
            return derivative(x, demands, vc_n, vc_e, p)

        x = rk4_step(x_dot, t, self.state, dt)
        self.t = t + dt
        if not self.tank.contains(x[0], x[1]):
            x = self._stop_at_wall(x)
        elif self.wall is not None and self.tank.contains(x[0], x[1], WALL_RELEASE_M):
            self.wall = None
        self.state = (x[0], x[1], wrap_pi(x[2]), *x[3:])  # type: ignore[assignment]
        self.sensors.update(self.truth())

    def control_step(self, dt: float) -> None:
        """Sample heading and run the autopilot for a control period dt [s]."""
        self.sensors.sample_attitude(self.truth())
        self.autopilot.update(self.navigation(), dt)

    def _stop_at_wall(self, x: tuple[float, ...]) -> tuple[float, ...]:
        vc_n, vc_e = self.flow.velocity(x[0], x[1], self.t)
        vn, ve = ground_velocity(x, vc_n, vc_e)  # type: ignore[arg-type]
        n, e, vn, ve, contact = self.tank.confine(x[0], x[1], vn, ve)
        assert contact is not None
        # back to the water-relative body velocity: nu_r = R(psi)^T (V - V_c)
        c, s = math.cos(x[2]), math.sin(x[2])
        dn, de = vn - vc_n, ve - vc_e
        if self.wall is None or set(contact.walls) - set(self.wall.walls):
            event = WallEvent(self.t, self.sysid, contact)
            self.wall_events.append(event)
            self.autopilot.say(Severity.WARNING, f"Wall contact: {'+'.join(contact.walls)} wall at N {n:.2f} E {e:.2f}")
        self.wall = contact
        return (n, e, x[2], c * dn + s * de, -s * dn + c * de, *x[5:])

    # ---- views ----------------------------------------------------------------------------------
    def truth(self) -> Truth:
        x = self.state
        vc_n, vc_e = self.flow.velocity(x[0], x[1], self.t)
        vn, ve = ground_velocity(x, vc_n, vc_e)
        return Truth(self.t, x[0], x[1], x[2], x[5], vn, ve)

    def navigation(self) -> Navigation:
        """The autopilot's view: latest position fix, heading and yaw-rate measurements."""
        fix = self.sensors.fix
        t = self.t
        if fix is None:
            return Navigation(t, 0.0, 0.0, 0.0, 0.0, self.sensors.psi, self.sensors.r, False)
        return Navigation(
            t,
            fix.n,
            fix.e,
            fix.vn,
            fix.ve,
            self.sensors.psi,
            self.sensors.r,
            self.sensors.position_healthy(t),
        )

    def thrusts(self) -> tuple[float, ...]:
        """Current thrust of each propeller [N], in sitl.vehicles.thrusts order."""
        return thrusts(self.state, self.params)

    def flow_here(self) -> tuple[float, float]:
        """Water velocity at the boat (V_N, V_E) [m/s]."""
        return self.flow.velocity(self.state[0], self.state[1], self.t)
