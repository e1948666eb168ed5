"""A mission's record as an MCAP file (the ``mcap`` package; the log format Foxglove and ROS read).

:class:`MissionLog` writes; :func:`read_mission` reads back. Every message is JSON (message encoding
``json``) with a JSON Schema (schema encoding ``jsonschema``), on these topics:

``/fix``       an accepted position fix: ``t`` vehicle time [s], ``position_ned`` [N, E] m, ``velocity_ned`` m/s
``/estimate``  the filter after a fix: ``t``, ``position_ned``, ``velocity_ned``, ``current_ned`` [N, E] m/s or null
``/setpoint``  a velocity setpoint sent: ``t``, ``velocity_ned`` m/s, ``yaw_rad`` (rad from north) or null
``/state``     a state change: ``t``, ``state`` (idle|waiting|guiding|arrived|hold|fault), ``reason`` or null
``/status``    a zenoh status as published (docs/zenoh.md; the required keys are the schema's)
``/field``     the field on a grid, as the ``field`` queryable replies (docs/zenoh.md), for the replay

Each message's log time is the host's unix time [ns] when it was logged; ``t`` in the payload is the
vehicle clock. File metadata ``koopguide`` holds ``vehicle_id``, ``model`` and any extras given to
:meth:`MissionLog.create` (e.g. ``arrival_radius_m``), all as strings.

Conventions: local NED metres and metres per second; every number finite (a NaN or infinity is refused
with a ValueError naming the topic, since JSON has no spelling for it).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.writer import Writer

from koopguide.bus.status import STATES, STATUS_FIELDS

PAIR = {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2}
PAIR_OR_NULL = {"anyOf": [PAIR, {"type": "null"}]}
TIME = {"type": "number", "description": "vehicle time [s]"}
SCHEMAS: dict[str, dict[str, Any]] = {
    "/fix": {
        "title": "koopguide.Fix",
        "type": "object",
        "required": ["t", "position_ned", "velocity_ned"],
        "properties": {"t": TIME, "position_ned": PAIR, "velocity_ned": PAIR},
    },
    "/estimate": {
        "title": "koopguide.Estimate",
        "type": "object",
        "required": ["t", "position_ned", "velocity_ned", "current_ned"],
        "properties": {"t": TIME, "position_ned": PAIR, "velocity_ned": PAIR, "current_ned": PAIR_OR_NULL},
    },
    "/setpoint": {
        "title": "koopguide.Setpoint",
        "type": "object",
        "required": ["t", "velocity_ned", "yaw_rad"],
        "properties": {"t": TIME, "velocity_ned": PAIR, "yaw_rad": {"anyOf": [{"type": "number"}, {"type": "null"}]}},
    },
    "/state": {
        "title": "koopguide.StateChange",
        "type": "object",
        "required": ["t", "state", "reason"],
        "properties": {
            "t": TIME,
            "state": {"enum": list(STATES)},
            "reason": {"anyOf": [{"type": "string"}, {"type": "null"}]},
        },
    },
    "/status": {
        "title": "koopguide.Status",
        "type": "object",
        "required": list(STATUS_FIELDS),
        "description": "docs/zenoh.md, 'The status'",
    },
    "/field": {
        "title": "koopguide.FieldGrid",
        "type": "object",
        "required": ["n", "position_ned", "velocity_ned"],
        "properties": {
            "n": {"type": "integer"},
            "goal_ned": PAIR_OR_NULL,
            "position_ned": {"type": "array", "items": PAIR},
            "velocity_ned": {"type": "array", "items": PAIR},
        },
    },
}


#: Bytes per compressed chunk. A log call that fills a chunk compresses it (zstd) there and then, on the
#: caller's thread: measured on the loaded 2-core machine, such a call took up to ~6 ms at 64 KiB and
#: up to ~26 ms at mcap's default 1 MiB (a plain call: ~4 us). Log after the setpoint has gone out.
CHUNK_BYTES = 64 * 1024


class MissionLogError(ValueError):
    """A mission log that cannot be read (not MCAP, truncated, wrong payloads); names the file."""


def _pair(v: Any) -> list[float]:
    return [float(v[0]), float(v[1])]


class MissionLog:
    """An MCAP file being written. Build with :meth:`create`; :meth:`close` (or ``with``) finishes it."""

    def __init__(self, stream: IO[bytes], writer: Writer, channels: dict[str, int], path: Path) -> None:
        self.path = path
        self._stream = stream
        self._writer = writer
        self._channels = channels
        self._sequence = 0
        self.messages = 0

    @classmethod
    def create(cls, path: str | Path, vehicle_id: str, model: str | Path, **extras: Any) -> MissionLog:
        """Open ``path`` for writing (replacing it) and write the header, schemas and metadata."""
        path = Path(path)
        stream = path.open("wb")
        try:
            writer = Writer(stream, chunk_size=CHUNK_BYTES)
            writer.start(profile="", library="koopguide")
            channels = {}
            for topic, schema in SCHEMAS.items():
                schema_id = writer.register_schema(schema["title"], "jsonschema", json.dumps(schema).encode())
                channels[topic] = writer.register_channel(topic, "json", schema_id)
            meta = {"vehicle_id": str(vehicle_id), "model": str(model), **{k: str(v) for k, v in extras.items()}}
            writer.add_metadata("koopguide", meta)
        except BaseException:
            stream.close()
            raise
        return cls(stream, writer, channels, path)

    # ------------------------------------------------------------------------------ records
    def log_fix(self, t: float, position_ned: Any, velocity_ned: Any) -> None:
        self._put("/fix", {"t": float(t), "position_ned": _pair(position_ned), "velocity_ned": _pair(velocity_ned)})

    def log_estimate(self, t: float, position_ned: Any, velocity_ned: Any, current_ned: Any | None = None) -> None:
        self._put(
            "/estimate",
            {
                "t": float(t),
                "position_ned": _pair(position_ned),
                "velocity_ned": _pair(velocity_ned),
                "current_ned": None if current_ned is None else _pair(current_ned),
            },
        )

    def log_setpoint(self, t: float, velocity_ned: Any, yaw_rad: float | None = None) -> None:
        self._put(
            "/setpoint",
            {
                "t": float(t),
                "velocity_ned": _pair(velocity_ned),
                "yaw_rad": None if yaw_rad is None else float(yaw_rad),
            },
        )

    def log_state(self, t: float, state: str, reason: str | None = None) -> None:
        if state not in STATES:
            raise ValueError(f"mission log /state: state must be one of {', '.join(STATES)}, got {state!r}")
        self._put("/state", {"t": float(t), "state": state, "reason": reason})

    def log_status(self, status: dict[str, Any]) -> None:
        self._put("/status", status)

    def log_field(self, grid: dict[str, Any]) -> None:
        """The field queryable's reply (``GuidanceLaw.sample_grid(n)``), once, for the replay's streamlines."""
        self._put("/field", grid)

    def _put(self, topic: str, body: dict[str, Any]) -> None:
        try:
            data = json.dumps(body, separators=(",", ":"), allow_nan=False).encode()
        except ValueError as exc:
            raise ValueError(f"mission log {topic}: {exc} in {body!r}"[:300]) from None
        now = time.time_ns()
        self._sequence += 1
        self._writer.add_message(
            self._channels[topic], log_time=now, data=data, publish_time=now, sequence=self._sequence
        )
        self.messages += 1

    def close(self) -> None:
        """Write the summary and close the file (idempotent)."""
        if self._stream.closed:
            return
        try:
            self._writer.finish()
        finally:
            self._stream.close()

    def __enter__(self) -> MissionLog:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()


# ------------------------------------------------------------------------------------ reading
@dataclass
class MissionRecord:
    """A log read back. Arrays (rows in log order): ``fixes`` (F, 5) t, N, E, vN, vE; ``estimates``
    (E, 7) t, N, E, vN, vE, cN, cE (NaN without a current estimate); ``setpoints`` (S, 3) t, vN, vE.
    Units: vehicle s, m, m/s."""

    metadata: dict[str, str]
    fixes: np.ndarray
    estimates: np.ndarray
    setpoints: np.ndarray
    states: list[tuple[float, str, str | None]] = field(default_factory=list)
    statuses: list[dict[str, Any]] = field(default_factory=list)
    field_grid: dict[str, Any] | None = None


def read_mission(path: str | Path) -> MissionRecord:
    """Read a mission log; a file that is not a readable koopguide MCAP log is a MissionLogError."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: mission log not found")
    rows: dict[str, list] = {topic: [] for topic in SCHEMAS}
    metadata: dict[str, str] = {}
    try:
        with path.open("rb") as stream:
            reader = make_reader(stream)
            for record in reader.iter_metadata():
                if record.name == "koopguide":
                    metadata = dict(record.metadata)
            for _schema, channel, message in reader.iter_messages(topics=list(SCHEMAS)):
                if channel.message_encoding != "json":
                    raise MissionLogError(f"{path}: topic {channel.topic} is {channel.message_encoding!r}, not json")
                rows[channel.topic].append(json.loads(message.data))
    except (McapError, json.JSONDecodeError, EOFError) as exc:
        raise MissionLogError(f"{path}: not a readable MCAP mission log ({type(exc).__name__}: {exc})") from None
    except ValueError as exc:  # the mcap reader's own checks (bad magic, short records)
        if isinstance(exc, MissionLogError):
            raise
        raise MissionLogError(f"{path}: not a readable MCAP mission log ({exc})") from None
    try:
        fixes = np.array([[r["t"], *r["position_ned"], *r["velocity_ned"]] for r in rows["/fix"]], dtype=float).reshape(
            -1, 5
        )
        estimates = np.array(
            [
                [r["t"], *r["position_ned"], *r["velocity_ned"], *(r["current_ned"] or (math.nan, math.nan))]
                for r in rows["/estimate"]
            ],
            dtype=float,
        ).reshape(-1, 7)
        setpoints = np.array([[r["t"], *r["velocity_ned"]] for r in rows["/setpoint"]], dtype=float).reshape(-1, 3)
        states = [(float(r["t"]), str(r["state"]), r["reason"]) for r in rows["/state"]]
    except (KeyError, TypeError, ValueError) as exc:
        raise MissionLogError(f"{path}: a message does not match its schema ({type(exc).__name__}: {exc})") from None
    return MissionRecord(
        metadata, fixes, estimates, setpoints, states, rows["/status"], rows["/field"][-1] if rows["/field"] else None
    )
