"""What the guidance supervisor hears and what it answers: typed events in, a decision with requests out.

The vehicle facade (:mod:`koopguide.guidance.vehicle_events`) turns MAVLink messages into these events;
the asyncio service feeds them to the :class:`~koopguide.guidance.supervisor.Supervisor` and turns its
:class:`Decision` into messages. Every event carries ``wall_s``, the service's monotonic clock when it
arrived [s]; stamped ones carry ``t_s``, the vehicle's own time [s since its boot]. Positions are local
NED [m], velocities NED [m/s], headings [rad] from north, turn rates [rad/s].
"""

from __future__ import annotations

from dataclasses import dataclass

from koopguide.guidance.law.command import GuidanceState


@dataclass(frozen=True)
class Heartbeat:
    wall_s: float  # arrival [s, service monotonic clock]
    mode: int  # the autopilot's custom mode number (Rover: GUIDED 15, LOITER 5, HOLD 4...)
    armed: bool


@dataclass(frozen=True)
class PositionFix:
    wall_s: float  # arrival [s]
    t_s: float  # vehicle time of the fix [s]
    position_ned: tuple[float, float]  # (N, E) [m]
    velocity_ned: tuple[float, float]  # (vN, vE) [m/s]


@dataclass(frozen=True)
class Attitude:
    wall_s: float  # arrival [s]
    t_s: float  # vehicle time [s]
    heading_rad: float  # yaw [rad] from north
    turn_rate_radps: float  # yaw rate [rad/s]


@dataclass(frozen=True)
class GlobalFix:
    wall_s: float  # arrival [s]
    t_s: float  # vehicle time [s]
    lat_deg: float
    lon_deg: float


@dataclass(frozen=True)
class ClockRestart:
    """The vehicle's clock restarted: back (a reboot) or a confirmed jump forward."""

    wall_s: float  # arrival [s]
    t_s: float  # the new vehicle time [s]
    previous_s: float  # the vehicle time before [s]
    rebooted: bool  # True: time went back


@dataclass(frozen=True)
class InputRejected:
    """An input outside its bounds, dropped by the facade (e.g. a stamp off the vehicle clock)."""

    wall_s: float  # arrival [s]
    kind: str  # what was wrong: "timestamp", "position", ...
    detail: str  # one line naming the message and the values seen


@dataclass(frozen=True)
class OperatorHold:
    """An operator's verified request (koopguide.bus.control): hold (zero velocity) or resume guiding."""

    wall_s: float  # arrival [s]
    active: bool  # True: hold until resumed; False: resume
    source: str  # who asked, e.g. "dashboard@host" (one line, at most 64 characters)


@dataclass(frozen=True)
class Tick:
    """Time for a decision: the vehicle time now and the wall time now."""

    wall_s: float  # [s, service monotonic clock]
    t_s: float  # vehicle time now [s]


@dataclass(frozen=True)
class NeighbourStatus:
    """Another vehicle's status heard on zenoh (koopguide/<id>/status), for the separation filter."""

    wall_s: float  # arrival [s, service monotonic clock]
    t_s: float  # when it was published, on this vehicle's clock [s] (its age scaled by the clock's rate)
    vehicle_id: str
    position_ned: tuple[float, float]  # (N, E) [m] when it was published
    velocity_ned: tuple[float, float]  # (vN, vE) [m/s]
    age_s: float  # how old it was on arrival (publication to arrival, wall clocks) [s]


Event = (
    Heartbeat
    | PositionFix
    | Attitude
    | GlobalFix
    | ClockRestart
    | InputRejected
    | OperatorHold
    | Tick
    | NeighbourStatus
)


@dataclass(frozen=True)
class SetMode:
    mode: int  # custom mode number to ask for


@dataclass(frozen=True)
class Arm:
    pass


@dataclass(frozen=True)
class MessageInterval:
    message_id: int  # MAVLink message id
    rate_hz: float  # requested rate [Hz]


Request = SetMode | Arm | MessageInterval


@dataclass(frozen=True)
class Decision:
    """The supervisor's answer: a setpoint to send (or none), the state, and requests to the vehicle."""

    velocity_ned: tuple[float, float] | None  # setpoint (vN, vE) [m/s]; None: send no setpoint
    yaw_rad: float | None  # with the setpoint: yaw [rad] from north (type mask 2535); None: velocity only (3559)
    state: GuidanceState
    reason: str  # why this state, one line
    degraded: bool  # guiding with the fallback strategy (direct pursuit)
    requests: tuple[Request, ...] = ()


@dataclass(frozen=True)
class Note:
    """A line for the service's log (the supervisor does no I/O; the service logs these)."""

    level: int  # logging level
    text: str
