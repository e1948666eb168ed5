"""The autopilot's parameters under their ArduPilot Rover names, each with the range it accepts.

The one source is :class:`sitl.config.AutopilotParams`: each field's type declares its interval and its
metadata the ArduPilot name (and whether it is an enumeration, whole numbers only); :data:`PARAMS` is
built from those fields, in their order (the PARAM_VALUE index). So the configuration, checked while
loading, and PARAM_SET, checked here at run time, accept exactly the same values. PARAM_SET of a value
outside its range, or of NaN/inf, changes nothing (the reply is the PARAM_VALUE in force, as ArduPilot
answers).
"""

from __future__ import annotations

import dataclasses
import struct
import typing
from dataclasses import dataclass

from koopguide.base.config import Range
from sitl.config import AutopilotParams


@dataclass(frozen=True)
class ParamSpec:
    field: str  # AutopilotParams field
    interval: Range  # accepted values [the parameter's unit]
    integer: bool = False  # only whole numbers (an enumeration)

    def accepts(self, value: float) -> bool:
        """``value`` is finite, in the interval, and whole if the parameter is an enumeration."""
        return self.interval.contains(value) and (not self.integer or value == round(value))

    def describe(self) -> str:
        """The accepted values, short for a STATUSTEXT: ``[0, 100]``, ``(0, 10]``, ``whole numbers in [0, 2]``."""
        r = self.interval
        kind = "whole numbers in " if self.integer else ""
        return f"{kind}{'(' if r.lo_open else '['}{r.lo:g}, {r.hi:g}{')' if r.hi_open else ']'}"


def _specs() -> dict[str, ParamSpec]:
    hints = typing.get_type_hints(AutopilotParams, include_extras=True)
    specs = {}
    for f in dataclasses.fields(AutopilotParams):
        (interval,) = (m for m in getattr(hints[f.name], "__metadata__", ()) if isinstance(m, Range))
        specs[f.metadata["ardupilot"]] = ParamSpec(f.name, interval, integer=f.metadata["integer"])
    return specs


#: ArduPilot name -> field and range; the order (AutopilotParams' field order) is the PARAM_VALUE index.
PARAMS: dict[str, ParamSpec] = _specs()


def float32(value: float) -> float:
    """The value as a MAVLink REAL32 carries it."""
    return struct.unpack("<f", struct.pack("<f", value))[0]


class ParamStore:
    """The autopilot's live parameters by ArduPilot name, in a fixed order (PARAM_VALUE index)."""

    def __init__(self, params: AutopilotParams):
        self._values = {name: float32(float(getattr(params, spec.field))) for name, spec in PARAMS.items()}
        self.names = tuple(PARAMS)

    def get(self, name: str) -> float:
        return self._values[name]

    def set(self, name: str, value: float) -> bool:
        """Set a known parameter to a value in its range; False (nothing changes) otherwise."""
        spec = PARAMS.get(name)
        if spec is None or not spec.accepts(value):
            return False
        self._values[name] = float32(value)  # stored as float32, as sent
        return True

    def __contains__(self, name: object) -> bool:
        return name in self._values
