"""The status a guidance daemon publishes on zenoh key ``koopguide/<vehicle-id>/status`` (pure, no I/O).

One status is one compact JSON object (UTF-8). Frames and units: positions are local NED metres
``[N, E]``, velocities NED metres per second ``[vN, vE]``; every number is finite (NaN and infinity are
refused, JSON has no spelling for them). Required keys, in publication order:

``t``                  float   unix wall time of publication [s]
``seq``                int     publication counter of this daemon, from 1, +1 per status
``vehicle_id``         str     the vehicle's id, also the key segment: 1-64 of ``A-Z a-z 0-9 _ -``
``state``              str     one of :data:`STATES`: idle, waiting, guiding, arrived, hold, fault
``mode``               str | None   the autopilot's flight mode, e.g. ``"GUIDED"``; None before a heartbeat
``armed``              bool | None  the autopilot's armed flag; None before a heartbeat
``position_ned``       [N, E] | None    estimated position [m]; None before the first fix
``velocity_ned``       [vN, vE] | None  estimated velocity [m/s]
``goal_ned``           [N, E] | None    where the model's goal lands [m]
``distance_to_goal_m`` float | None     |position - goal| [m], >= 0
``cmd_velocity_ned``   [vN, vE]         the velocity setpoint last sent [m/s] (zeros when holding)
``speed_limit_mps``    float            the largest commanded speed allowed [m/s], >= 0
``position_age_s``     float | None     age of the newest position the estimate rests on [s]
``loop_latency_ms``    {"p50": float | None, "p99": float | None}  guidance loop latency percentiles [ms]
``model``              str              the model file the daemon guides with

Any other key is an optional extra (the daemon sends ``vehicle_time_s``, ``reason``
and ``link``): it is passed through unchanged and only has to be finite JSON.

:func:`encode_status` validates then serialises; :func:`decode_status` parses then validates. Both raise
:class:`StatusFormatError` naming the offending key and the value seen.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Mapping
from typing import Any

#: The daemon's states, as published in ``state``.
STATES: tuple[str, ...] = ("idle", "waiting", "guiding", "arrived", "hold", "fault")

#: Every status carries these keys (see the module docstring for types and units).
STATUS_FIELDS: tuple[str, ...] = (
    "t",
    "seq",
    "vehicle_id",
    "state",
    "mode",
    "armed",
    "position_ned",
    "velocity_ned",
    "goal_ned",
    "distance_to_goal_m",
    "cmd_velocity_ned",
    "speed_limit_mps",
    "position_age_s",
    "loop_latency_ms",
    "model",
)

#: A vehicle id is one zenoh key segment: no ``/ * $ # ?`` and nothing that needs escaping.
VEHICLE_ID_PATTERN = re.compile(r"^[A-Za-z0-9_-]{1,64}$")


class StatusFormatError(ValueError):
    """A status (dict or payload) breaks the schema; the message names the key and the value seen."""


def validate_vehicle_id(vehicle_id: object) -> str:
    """Return ``vehicle_id`` if it is 1-64 characters of ``A-Z a-z 0-9 _ -``, else raise ValueError."""
    if not isinstance(vehicle_id, str) or not VEHICLE_ID_PATTERN.match(vehicle_id):
        raise ValueError(
            f"vehicle id {vehicle_id!r} is not 1-64 characters of A-Z a-z 0-9 _ - "
            f"(it is a zenoh key segment, so / * $ # ? and spaces are not allowed)"
        )
    return vehicle_id


def encode_status(status: Mapping[str, Any]) -> bytes:
    """Validate ``status`` and serialise it as compact UTF-8 JSON."""
    validate_status(status)
    try:
        text = json.dumps(dict(status), separators=(",", ":"), allow_nan=False)
    except (TypeError, ValueError) as exc:  # an extra that is not finite JSON
        raise StatusFormatError(f"status {_offending_extra(status)}cannot be encoded as JSON: {exc}") from None
    return text.encode("utf-8")


def decode_status(payload: bytes | bytearray | memoryview) -> dict[str, Any]:
    """Parse and validate one status payload; numbers of the float keys come back as floats."""
    try:
        text = bytes(payload).decode("utf-8")
    except UnicodeDecodeError as exc:
        raise StatusFormatError(f"status payload is not UTF-8: {exc}") from None
    try:
        status = json.loads(text, parse_constant=_refuse_constant)
    except json.JSONDecodeError as exc:
        raise StatusFormatError(f"status payload is not JSON ({exc}): {_preview(text)}") from None
    if not isinstance(status, dict):
        raise StatusFormatError(f"status payload must be a JSON object, got {type(status).__name__}: {_preview(text)}")
    validate_status(status)
    for key in ("t", "distance_to_goal_m", "speed_limit_mps", "position_age_s"):
        if status[key] is not None:
            status[key] = float(status[key])
    for key in ("position_ned", "velocity_ned", "goal_ned", "cmd_velocity_ned"):
        if status[key] is not None:
            status[key] = [float(v) for v in status[key]]
    status["loop_latency_ms"] = {
        k: (None if v is None else float(v)) if k in ("p50", "p99") else v for k, v in status["loop_latency_ms"].items()
    }
    return status


def validate_status(status: Mapping[str, Any]) -> None:
    """Raise :class:`StatusFormatError` unless ``status`` has every required key, well typed and finite."""
    if not isinstance(status, Mapping):
        raise StatusFormatError(f"a status must be a mapping, got {_seen(status)}")
    missing = [key for key in STATUS_FIELDS if key not in status]
    if missing:
        raise StatusFormatError(f"status is missing required key(s) {', '.join(missing)}")
    for key, check in _CHECKS.items():
        check(key, status[key])


# ------------------------------------------------------------------------------ field checks
def _seen(value: Any) -> str:
    text = repr(value)
    if len(text) > 80:
        text = text[:77] + "..."
    return f"{text} ({type(value).__name__})"


def _fail(key: str, expected: str, value: Any) -> None:
    raise StatusFormatError(f"status key {key!r} must be {expected}, got {_seen(value)}")


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _number(key: str, value: Any, *, minimum: float | None = None) -> None:
    if not _is_number(value):
        _fail(key, "a number", value)
    if not math.isfinite(value):
        _fail(key, "finite (NaN and infinity cannot be sent as JSON)", value)
    if minimum is not None and value < minimum:
        _fail(key, f">= {minimum:g}", value)


def _optional(check: Callable[[str, Any], None]) -> Callable[[str, Any], None]:
    def optional_check(key: str, value: Any) -> None:
        if value is not None:
            check(key, value)

    return optional_check


def _float(key: str, value: Any) -> None:
    _number(key, value)


def _non_negative(key: str, value: Any) -> None:
    _number(key, value, minimum=0.0)


def _seq(key: str, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        _fail(key, "an integer >= 0", value)


def _string(key: str, value: Any) -> None:
    if not isinstance(value, str):
        _fail(key, "a string", value)


def _vehicle_id(key: str, value: Any) -> None:
    if not isinstance(value, str) or not VEHICLE_ID_PATTERN.match(value):
        _fail(key, "1-64 characters of A-Z a-z 0-9 _ -", value)


def _state(key: str, value: Any) -> None:
    if value not in STATES or not isinstance(value, str):
        _fail(key, f"one of {', '.join(STATES)}", value)


def _bool(key: str, value: Any) -> None:
    if not isinstance(value, bool):
        _fail(key, "true or false", value)


def _pair(key: str, value: Any) -> None:
    if not isinstance(value, list | tuple) or len(value) != 2:
        _fail(key, "a list of 2 numbers [N, E]", value)
    for i, component in enumerate(value):
        _number(f"{key}[{i}]", component)


def _latency(key: str, value: Any) -> None:
    if not isinstance(value, Mapping):
        _fail(key, 'an object {"p50": ms | null, "p99": ms | null}', value)
    for part in ("p50", "p99"):
        if part not in value:
            raise StatusFormatError(f"status key {key!r} is missing {part!r}: got {_seen(value)}")
        if value[part] is not None:
            _number(f"{key}.{part}", value[part], minimum=0.0)


_CHECKS: dict[str, Callable[[str, Any], None]] = {
    "t": _float,
    "seq": _seq,
    "vehicle_id": _vehicle_id,
    "state": _state,
    "mode": _optional(_string),
    "armed": _optional(_bool),
    "position_ned": _optional(_pair),
    "velocity_ned": _optional(_pair),
    "goal_ned": _optional(_pair),
    "distance_to_goal_m": _optional(_non_negative),
    "cmd_velocity_ned": _pair,
    "speed_limit_mps": _non_negative,
    "position_age_s": _optional(_float),
    "loop_latency_ms": _latency,
    "model": _string,
}
assert tuple(_CHECKS) == STATUS_FIELDS  # one check per documented key, in the documented order


def _refuse_constant(name: str) -> None:
    raise StatusFormatError(f"status payload contains {name}, which is not a finite number")


def _offending_extra(status: Mapping[str, Any]) -> str:
    """``"key 'x' "`` for the first extra that is not finite JSON, to point at it in the message."""
    for key, value in status.items():
        if key in _CHECKS:
            continue
        try:
            json.dumps(value, allow_nan=False)
        except (TypeError, ValueError):
            return f"key {key!r} ({_seen(value)}) "
    return ""


def _preview(text: str) -> str:
    return repr(text if len(text) <= 60 else text[:57] + "...")
