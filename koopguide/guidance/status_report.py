"""The service's status document from the supervisor's state (pure: no I/O, time passed in).

Conventions: positions local NED [m], velocities [m/s], times vehicle seconds; numbers rounded for JSON.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from koopguide.bus.status import Status
from koopguide.guidance.law.command import GuidanceLaw, GuidanceState
from koopguide.guidance.settings import GuidanceConfig
from koopguide.guidance.supervisor import Supervisor
from koopguide.mavlink import rover


def rounded(v: np.ndarray, digits: int = 4) -> list[float]:
    return [round(float(x), digits) for x in v]


def service_status(
    cfg: GuidanceConfig,
    sup: Supervisor,
    law: GuidanceLaw,
    now: float,
    seq: int,
    last_cmd: np.ndarray,
    latency_ms: dict[str, Any],
    model: str,
    position_age_s: float | None,
) -> Status:
    """The status at vehicle time ``now``; the service adds its own extras (inputs, control, link)."""
    position = velocity = distance = None
    estimate = sup.vehicle.estimate(now)
    if estimate is not None:
        p, v = estimate
        position, velocity = rounded(p), rounded(v)
        distance = round(law.distance_to_goal(p), 4)
        sup.reacquire_if_drifted(distance, now)  # never "arrived" farther than reacquire_radius_m
    current = sup.vehicle.current
    return Status(
        t=time.time(), seq=seq, vehicle_id=cfg.vehicle_id, state=sup.state.value, reason=sup.reason,
        degraded=sup.degraded and sup.state is GuidanceState.GUIDING, mode=rover.mode_name(sup.mode), armed=sup.armed,
        position_ned=position, velocity_ned=velocity, goal_ned=rounded(law.goal_ned) if sup.goal_placed else None,
        distance_to_goal_m=distance, cmd_velocity_ned=rounded(last_cmd), speed_limit_mps=cfg.command.max_speed_mps,
        position_age_s=None if position_age_s is None else round(position_age_s, 4), loop_latency_ms=latency_ms,
        model=model, extras={
            "vehicle_time_s": round(now, 3),
            "separation_active": sup.separation_active,
            "current_ned": rounded(current.current_ned) if current.updates else None,
        },
    )  # fmt: skip
