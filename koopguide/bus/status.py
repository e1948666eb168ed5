"""The status a guidance service publishes on zenoh key ``koopguide/<vehicle-id>/status`` (pure, no I/O).

The one source of the status fields is the :class:`Status` dataclass below: its fields, in publication
order, with their types, units and meanings (the field ``metadata``). The service builds a ``Status``;
:func:`encode_status` serialises it (or a mapping with the same keys) after checking it; subscribers
(``koopguide monitor``, the dashboard, your own) parse with :func:`decode_status`; the table in
docs/zenoh.md is generated from it (``python -m koopguide.bus.status``) and checked by a test.

One status is one compact JSON object (UTF-8). Positions are local NED metres ``[N, E]``, velocities
NED metres per second ``[vN, vE]``; every number is finite (JSON has no spelling for NaN or infinity).
Any key beyond the fields is an optional extra (``Status.extras``): passed through unchanged, it only has
to be finite JSON. Errors are :class:`StatusFormatError`, naming the key and the value seen.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

#: The service's states, as published in ``state``.
STATES: tuple[str, ...] = ("idle", "waiting", "guiding", "arrived", "hold", "fault")

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


def encode_status(status: Status | Mapping[str, Any]) -> bytes:
    """Validate ``status`` and serialise it as compact UTF-8 JSON."""
    if isinstance(status, Status):
        status = status.to_dict()
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
    for f in _FIELDS:  # numbers of the float keys come back as floats, whatever JSON spelling they had
        value, kind = status[f.name], f.metadata["kind"]
        if value is None:
            continue
        if kind.startswith("float"):
            status[f.name] = float(value)
        elif kind.startswith("["):
            status[f.name] = [float(v) for v in value]
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


def _spec(kind: str, unit: str, doc: str, check: Callable[[str, Any], None]) -> dict[str, Any]:
    return {"kind": kind, "unit": unit, "doc": doc, "check": check}


@dataclass(frozen=True)
class Status:
    """One status, the fields in publication order (``metadata``: JSON type, unit, meaning, check)."""

    t: float = field(metadata=_spec("float", "s", "Unix wall time of publication", _float))
    seq: int = field(metadata=_spec("int", "", "publication counter of this service, from 1, +1 per status", _seq))
    vehicle_id: str = field(
        metadata=_spec("str", "", "the vehicle id, also the key segment: 1-64 of `A-Z a-z 0-9 _ -`", _vehicle_id)
    )
    state: str = field(
        metadata=_spec(
            "str",
            "",
            '`idle`, `waiting`, `guiding`, `arrived`, `hold` or `fault` ([guidance.md](guidance.md), "States")',
            _state,
        )
    )
    reason: str | None = field(
        metadata=_spec(
            "str or null",
            "",
            "why the service is in this state, one line (the same text as in its log)",
            _optional(_string),
        )
    )
    degraded: bool = field(
        metadata=_spec(
            "bool",
            "",
            "guiding with a fallback strategy (e.g. direct pursuit "
            "after the progress watchdog fired); `reason` says why",
            _bool,
        )
    )
    mode: str | None = field(
        metadata=_spec(
            "str or null",
            "",
            'the autopilot\'s mode name, e.g. `"GUIDED"` '
            '(`"MODE_9"` for a number not in the Rover table); null before a '
            "heartbeat",
            _optional(_string),
        )
    )
    armed: bool | None = field(
        metadata=_spec("bool or null", "", "the autopilot's armed flag; null before a heartbeat", _optional(_bool))
    )
    position_ned: list[float] | None = field(
        metadata=_spec("[N, E] or null", "m", "the estimated position; null before the first fix", _optional(_pair))
    )
    velocity_ned: list[float] | None = field(
        metadata=_spec("[vN, vE] or null", "m/s", "the estimated velocity", _optional(_pair))
    )
    goal_ned: list[float] | None = field(
        metadata=_spec(
            "[N, E] or null",
            "m",
            "where the model's goal lands; null until a geodetic goal is placed",
            _optional(_pair),
        )
    )
    distance_to_goal_m: float | None = field(
        metadata=_spec("float >= 0 or null", "m", "distance from `position_ned` to the goal", _optional(_non_negative))
    )
    cmd_velocity_ned: list[float] = field(
        metadata=_spec("[vN, vE]", "m/s", "the velocity setpoint last sent (zeros when holding)", _pair)
    )
    speed_limit_mps: float = field(
        metadata=_spec("float >= 0", "m/s", "`command.max_speed_mps`, the largest speed ever commanded", _non_negative)
    )
    position_age_s: float | None = field(
        metadata=_spec("float or null", "s", "vehicle time since the newest accepted position fix", _optional(_float))
    )
    loop_latency_ms: dict[str, float | None] = field(
        metadata=_spec(
            '`{"p50", "p99"}`', "ms", "percentiles of the fix-to-setpoint latency; null before any", _latency
        )
    )
    model: str = field(metadata=_spec("str", "", "the model file, as given to `--model`", _string))
    extras: dict[str, Any] = field(default_factory=dict, metadata={"extra": True})

    def to_dict(self) -> dict[str, Any]:
        """The JSON object: the fields in order, then the extras."""
        out = {f.name: getattr(self, f.name) for f in _FIELDS}
        out.update(self.extras)
        return out


_FIELDS: tuple[dataclasses.Field, ...] = tuple(f for f in dataclasses.fields(Status) if not f.metadata.get("extra"))
#: Every status carries these keys, in this order.
STATUS_FIELDS: tuple[str, ...] = tuple(f.name for f in _FIELDS)
_CHECKS: dict[str, Callable[[str, Any], None]] = {f.name: f.metadata["check"] for f in _FIELDS}


def markdown_table() -> str:
    """The fields as the markdown table of docs/zenoh.md."""
    rows = ["| key | type | unit | meaning |", "| --- | --- | --- | --- |"]
    rows += [f"| `{f.name}` | {f.metadata['kind']} | {f.metadata['unit']} | {f.metadata['doc']} |" for f in _FIELDS]
    return "\n".join(rows)


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


if __name__ == "__main__":  # python -m koopguide.bus.status: the table for docs/zenoh.md
    sys.stdout.write(markdown_table() + "\n")
