"""The autopilot's parameters under their ArduPilot Rover names, each with the range it accepts.

PARAM_SET of a value outside its range, or of NaN/inf, changes nothing (the reply is the PARAM_VALUE
in force, as ArduPilot answers). The same ranges check the configuration at load. Ranges follow
ArduPilot's documented ``@Range`` where that makes sense for a 0.4 m boat, widened for the gains (this
simulator's defaults are tuned for its miniature hull, not for ArduPilot's defaults), and narrowed
where a value would make the controller divide by zero or drive astern (WP_SPEED >= 0,
ATC_STR_RAT_MAX > 0).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import TYPE_CHECKING

from koopguide.base.config import ConfigError

if TYPE_CHECKING:
    from sitl.config import AutopilotParams


@dataclass(frozen=True)
class ParamSpec:
    field: str  # AutopilotParams field
    low: float  # smallest accepted value (inclusive unless low_open) [the parameter's unit]
    high: float  # largest accepted value (inclusive) [the parameter's unit]
    low_open: bool = False  # the low end itself is not accepted
    integer: bool = False  # only whole numbers (an enumeration)

    def accepts(self, value: float) -> bool:
        if not math.isfinite(value) or value > self.high:
            return False
        if value < self.low or (self.low_open and value == self.low):
            return False
        return not self.integer or value == round(value)

    def describe(self) -> str:
        bracket = "(" if self.low_open else "["
        kind = "whole numbers in " if self.integer else ""
        return f"{kind}{bracket}{self.low:g}, {self.high:g}]"


# ArduPilot name -> field and range; the order is the PARAM_VALUE index.
PARAMS = {
    "GUID_TIMEOUT": ParamSpec("guid_timeout_s", 0.1, 5.0),  # [s]
    "WP_SPEED": ParamSpec("wp_speed_mps", 0.0, 100.0),  # [m/s]
    "CRUISE_SPEED": ParamSpec("cruise_speed_mps", 0.0, 100.0),  # [m/s]; 0 = no feed-forward
    "CRUISE_THROTTLE": ParamSpec("cruise_throttle_pct", 0.0, 100.0),  # [%]
    "ATC_SPEED_P": ParamSpec("speed_p", 0.0, 100.0),  # [1/(m/s)]
    "ATC_SPEED_I": ParamSpec("speed_i", 0.0, 100.0),  # [1/m]
    "ATC_STR_RAT_FF": ParamSpec("steer_rate_ff", 0.0, 100.0),  # [1/(rad/s)]
    "ATC_STR_RAT_P": ParamSpec("steer_rate_p", 0.0, 100.0),  # [1/(rad/s)]
    "ATC_STR_RAT_I": ParamSpec("steer_rate_i", 0.0, 100.0),  # [1/rad]
    "ATC_STR_RAT_MAX": ParamSpec("steer_rate_max_degps", 0.0, 1000.0, low_open=True),  # [deg/s]
    "ATC_STR_ANG_P": ParamSpec("steer_angle_p", 0.0, 100.0),  # [1/s]
    "WP_PIVOT_ANGLE": ParamSpec("pivot_angle_deg", 0.0, 360.0),  # [deg]; 0 = no pivot turns
    "WP_PIVOT_RATE": ParamSpec("pivot_rate_degps", 0.0, 1000.0, low_open=True),  # [deg/s]
    "WP_RADIUS": ParamSpec("wp_radius_m", 0.0, 1000.0),  # [m]
    "LOIT_RADIUS": ParamSpec("loiter_radius_m", 0.0, 20.0),  # [m]
    "LOIT_SPEED_GAIN": ParamSpec("loiter_speed_gain", 0.0, 5.0),  # [1/s]
    "LOIT_TYPE": ParamSpec("loiter_type", 0.0, 2.0, integer=True),  # [-] 0 both ways, 1 forward, 2 reverse
    "ATC_DECEL_MAX": ParamSpec("decel_max_mps2", 0.0, 10.0, low_open=True),  # [m/s^2]
}


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


def check_config_params(params: AutopilotParams) -> None:
    """Raise ConfigError naming the first configured parameter outside its range."""
    for name, spec in PARAMS.items():
        value = getattr(params, spec.field)
        if not spec.accepts(value):
            raise ConfigError(f"autopilot.params.{spec.field} ({name}): must be {spec.describe()}, got {value!r}")
