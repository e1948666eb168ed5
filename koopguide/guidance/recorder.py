"""The service's mission log (``koopguide run --log FILE.mcap``): what the daemon did, as MCAP.

Every write happens after the setpoint it follows has gone out, never between a fix and its command:
:meth:`MissionRecorder.after_fix` runs after the command (and after the current estimate's update),
setpoints are queued by :meth:`MissionRecorder.setpoint` (a list append) and written by :meth:`flush`,
which the daemon calls after each fix's command, from its status loop and at shutdown. A chunk that
fills is compressed on the event loop (bus.missionlog.CHUNK_BYTES: a few ms, once per ~64 KiB).

Conventions: local NED [m], [m/s]; ``t`` the vehicle clock [s]; records as in koopguide.bus.missionlog.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from pathlib import Path
from typing import Any

from koopguide.bus.missionlog import MissionLog
from koopguide.guidance.events import PositionFix
from koopguide.guidance.settings import GuidanceConfig
from koopguide.guidance.supervisor import Supervisor

#: Grid points per axis of the field logged once the goal is placed (the replay's streamlines).
FIELD_GRID = 30


class MissionRecorder:
    """One mission log, fed by the daemon; :meth:`close` finishes the file."""

    def __init__(self, log: MissionLog, supervisor: Supervisor) -> None:
        self.log = log
        self.supervisor = supervisor
        self._setpoints: list[tuple[float, tuple[float, float], float | None]] = []
        self._transitions = 0  # supervisor.transitions already logged
        self.field_logged = False

    @classmethod
    def create(cls, path: Path, cfg: GuidanceConfig, model: Path, supervisor: Supervisor) -> MissionRecorder:
        """Open ``path`` (replaced); an unwritable path is an OSError naming it, before any link opens."""
        log = MissionLog.create(path, cfg.vehicle_id, model, arrival_radius_m=cfg.arrival.radius_m)
        return cls(log, supervisor)

    def setpoint(self, t: float, velocity_ned: Any, yaw_rad: float | None) -> None:
        """A setpoint went out at vehicle time ``t``: queued, written by the next :meth:`flush`."""
        self._setpoints.append((t, (float(velocity_ned[0]), float(velocity_ned[1])), yaw_rad))

    def after_fix(self, fix: PositionFix) -> None:
        """An accepted fix and the estimate after it; then the queued setpoints and state changes."""
        self.log.log_fix(fix.t_s, fix.position_ned, fix.velocity_ned)
        vehicle = self.supervisor.vehicle
        estimate = vehicle.estimate(fix.t_s)
        if estimate is not None:
            current = vehicle.current.current_ned if vehicle.current.updates else None
            self.log.log_estimate(fix.t_s, estimate[0], estimate[1], current)
        self.flush()

    def flush(self) -> None:
        """Write the queued setpoints and the state changes since the last flush."""
        setpoints, self._setpoints = self._setpoints, []
        for t, velocity, yaw in setpoints:
            self.log.log_setpoint(t, velocity, yaw)
        sup = self.supervisor
        changes = sup.transitions[self._transitions :]
        self._transitions = len(sup.transitions)
        for k, (t, state) in enumerate(changes):  # the reason is known for the latest state only
            self.log.log_state(t, state, sup.reason if k == len(changes) - 1 and state == sup.state.value else None)

    async def status(self, status: dict[str, Any], sample_grid: Callable[[int], dict[str, Any]]) -> None:
        """A published status, after the queued records; the field grid once the goal is placed
        (``sample_grid(FIELD_GRID)``, computed on a worker thread as the field queryable does)."""
        self.flush()
        self.log.log_status(status)
        if not self.field_logged and self.supervisor.goal_placed:
            self.log.log_field(await asyncio.to_thread(sample_grid, FIELD_GRID))
            self.field_logged = True

    def close(self) -> None:
        """Write what is queued and finish the file (idempotent)."""
        try:
            self.flush()
        finally:
            self.log.close()
