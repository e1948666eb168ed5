"""The simulator's configuration follows the project's one convention: every numeric key declares its
interval in its type, YAML numbers are read the YAML 1.2 way, relations between keys are checked in
``__post_init__``, and no value at any key can make a traceback - only a one-line ConfigError naming the
key (property-based). The autopilot parameters' intervals are the ones PARAM_SET checks at run time."""

from __future__ import annotations

import dataclasses
import math
import typing
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from koopguide.base import config
from koopguide.base.config import ConfigError
from sitl import config as sitl_config
from sitl.config import AutopilotParams, SitlConfig
from sitl.parameters import PARAMS, ParamStore
from tests.support.config_paths import leaf_paths, nested

SITL_DEFAULTS = config.load_yaml(config.default_config_path("sitl"))


def load_text(tmp_path: Path, text: str) -> SitlConfig:
    user = tmp_path / "user.yaml"
    user.write_text(text)
    return sitl_config.load(user)


def test_every_numeric_key_declares_its_range():
    assert config.numeric_without_range(SitlConfig) == []


def test_the_shipped_defaults_are_valid():
    cfg = sitl_config.load()
    assert cfg.physics_rate_hz == 100.0 and cfg.count == 1
    assert cfg.vessel.hull.linear_damping_surge_kgps < 0 and cfg.vessel.rudder.position_m < 0


def test_yaml_numbers_are_read_the_yaml_1_2_way(tmp_path: Path):
    cfg = load_text(
        tmp_path,
        "unix_time_at_boot_s: 1.7e9\nduration_s: 1e3\nvessel:\n  hull:\n    mass_kg: 2E0\n"
        "    linear_damping_sway_kgps: -5e0\nflow:\n  gusts:\n    std_mps: 2e-2\n",
    )
    assert cfg.unix_time_at_boot_s == pytest.approx(1.7e9)
    assert cfg.duration_s == pytest.approx(1000.0)
    assert cfg.vessel.hull.mass_kg == pytest.approx(2.0)
    assert cfg.vessel.hull.linear_damping_sway_kgps == pytest.approx(-5.0)
    assert cfg.flow.gusts.std_mps == pytest.approx(0.02)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        # every check the former validate() made, by key
        ("count: 0\n", "count: 0 is out of range"),
        ("count: 251\n", "count: 251 is out of range (expected a number in [1, 250])"),
        ("count: 1e7\n", "count: expected an integer, got 10000000.0"),
        ("speedup: -1\n", "speedup: -1.0 is out of range"),
        ("physics_rate_hz: 50\n", "physics_rate_hz: 50.0 is out of range (expected a number in [100, 1000])"),
        ("vessel:\n  hull:\n    mass_kg: 0\n", "vessel.hull.mass_kg: 0.0 is out of range"),
        ("vessel:\n  hull:\n    yaw_inertia_kgm2: -0.01\n", "vessel.hull.yaw_inertia_kgm2: -0.01 is out of range"),
        ("vessel:\n  thrusters:\n    max_rate_rps: 0\n", "vessel.thrusters.max_rate_rps: 0.0 is out of range"),
        ("vessel:\n  thrusters:\n    time_constant_s: 0\n", "vessel.thrusters.time_constant_s: 0.0 is out of range"),
        ("vessel:\n  rudder:\n    time_constant_s: 0\n", "vessel.rudder.time_constant_s: 0.0 is out of range"),
        ("vessel:\n  rudder:\n    lift_slope_kgpm: 0\n", "vessel.rudder.lift_slope_kgpm: 0.0 is out of range"),
        ("vessel:\n  rudder:\n    max_angle_deg: 61\n", "vessel.rudder.max_angle_deg: 61.0 is out of range"),
        ("vessel:\n  rudder:\n    max_angle_deg: 0\n", "vessel.rudder.max_angle_deg: 0.0 is out of range"),
        ("vessel:\n  rudder:\n    position_m: 0\n", "vessel.rudder.position_m: 0.0 is out of range"),
        ("vessel:\n  lateral_thrusters:\n    max_thrust_n: 0\n", "vessel.lateral_thrusters.max_thrust_n: 0.0 is out"),
        ("vessel:\n  lateral_thrusters:\n    lever_m: 0\n", "vessel.lateral_thrusters.lever_m: 0.0 is out of range"),
        ("sensors:\n  position:\n    rate_hz: 0\n", "sensors.position.rate_hz: 0.0 is out of range"),
        ("sensors:\n  position:\n    dropout_probability: 1\n", "sensors.position.dropout_probability: 1.0 is out"),
        ("autopilot:\n  control_rate_hz: 0\n", "autopilot.control_rate_hz: 0.0 is out of range"),
        ("mavlink:\n  heartbeat_hz: 0\n", "mavlink.heartbeat_hz: 0.0 is out of range"),
        ("recorder:\n  rate_hz: 0\n", "recorder.rate_hz: 0.0 is out of range"),
        ("flow:\n  double_gyre:\n    scale_m: 0\n", "flow.double_gyre.scale_m: 0.0 is out of range"),
        ("flow:\n  vortex:\n    core_radius_m: 0\n", "flow.vortex.core_radius_m: 0.0 is out of range"),
        ("flow:\n  kinds: [none, uniform]\n", "flow.kinds: 'none' cannot be combined"),
        ("world:\n  north_m: [3.0, 1.0]\n", "world.north_m: [3.0, 1.0] is out of range (expected [min, max]"),
        ("mavlink:\n  endpoints: []\n", "mavlink.endpoints: at least one endpoint is needed"),
        ("count: 2\nstart_poses: [[1.0, 1.0, 0.0]]\n", "start_poses: 1 poses given for count = 2 boats"),
        ("count: 2\nvehicles: [rudder]\n", "vehicles: 1 kinds given for count = 2 boats"),
        ("autopilot:\n  params:\n    guid_timeout_s: 0.05\n", "autopilot.params.guid_timeout_s: 0.05 is out of range"),
        ("autopilot:\n  params:\n    loiter_type: 1.5\n", "autopilot.params.loiter_type: expected an integer"),
        ("autopilot:\n  params:\n    loiter_type: 3\n", "autopilot.params.loiter_type: 3 is out of range"),
        ("autopilot:\n  params:\n    steer_rate_max_degps: 0\n", "steer_rate_max_degps: 0.0 is out of range"),
        # sign conventions and absurd numbers
        ("vessel:\n  hull:\n    linear_damping_surge_kgps: 0.75\n", "linear_damping_surge_kgps: 0.75 is out of range"),
        ("vessel:\n  hull:\n    added_mass_sway_kg: 1.5\n", "vessel.hull.added_mass_sway_kg: 1.5 is out of range"),
        ("flow:\n  uniform:\n    drift_time_constant_s: 0\n", "drift_time_constant_s: 0.0 is out of range"),
        ("flow:\n  uniform:\n    speed_mps: 1.0e300\n", "flow.uniform.speed_mps: 1e+300 is out of range"),
        ("flow:\n  gusts:\n    std_mps: .nan\n", "flow.gusts.std_mps: nan is out of range"),
        ("seed: -1\n", "seed: -1 is out of range"),
        ("start_poses: [[1.0, .inf, 0.0]]\n", "start_poses[0][1]: inf is out of range"),
        ("origin:\n  latitude_deg: 91\n", "origin.latitude_deg: 91.0 is out of range"),
        ("duration_s: 0\n", "duration_s: 0.0 is out of range"),
        # relations across sections
        ("autopilot:\n  control_rate_hz: 200\n", "autopilot.control_rate_hz: 200.0 is out of range (expected <= phys"),
        ("recorder:\n  rate_hz: 500\nphysics_rate_hz: 400\n", "recorder.rate_hz: 500.0 is out of range"),
        ("world:\n  east_m: [0.0, 0.3]\n", "world.east_m: [0, 0.3] spans 0.3 m, not more than the hull"),
    ],
)
def test_bad_values_are_one_line_errors_naming_the_key(tmp_path: Path, text: str, message: str):
    with pytest.raises(ConfigError) as caught:
        load_text(tmp_path, text)
    assert message in str(caught.value)
    assert "\n" not in str(caught.value)


def test_a_small_tank_is_fine_without_walls(tmp_path: Path):
    cfg = load_text(tmp_path, "world:\n  walls: false\n  east_m: [0.0, 0.3]\n")
    assert cfg.world.east_m == (0.0, 0.3)


# ------------------------------------------------------------------------- autopilot parameters
def test_parameters_come_from_the_config_fields_in_the_param_value_order():
    assert [spec.field for spec in PARAMS.values()] == [f.name for f in dataclasses.fields(AutopilotParams)]
    assert list(PARAMS)[:4] == ["GUID_TIMEOUT", "WP_SPEED", "CRUISE_SPEED", "CRUISE_THROTTLE"]
    assert list(PARAMS)[-3:] == ["LOIT_SPEED_GAIN", "LOIT_TYPE", "ATC_DECEL_MAX"]
    assert len(PARAMS) == len(dataclasses.fields(AutopilotParams)) == 18
    hints = typing.get_type_hints(AutopilotParams, include_extras=True)
    for f in dataclasses.fields(AutopilotParams):
        # an enumeration is an int in the config, and only whole numbers over PARAM_SET
        assert f.metadata["integer"] == (typing.get_args(hints[f.name])[0] is int), f.name
    store = ParamStore(sitl_config.load().autopilot.params)
    assert store.names == tuple(PARAMS)
    assert store.get("WP_SPEED") == pytest.approx(0.4) and store.get("LOIT_TYPE") == 0.0


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    name=st.sampled_from(list(PARAMS)),
    value=st.floats(allow_nan=True, allow_infinity=True) | st.integers(min_value=-5, max_value=1005).map(float),
)
def test_param_set_accepts_exactly_what_the_config_accepts(name: str, value: float):
    spec = PARAMS[name]
    config_value: Any = int(value) if spec.integer and value.is_integer() else value
    try:
        sitl_config.load(overrides={"autopilot": {"params": {spec.field: config_value}}})
    except ConfigError as exc:
        assert f"autopilot.params.{spec.field}" in str(exc)
        assert not spec.accepts(value)
    else:
        assert spec.accepts(value) and math.isfinite(value)


# --------------------------------------------------------------------------------- properties
ANY_VALUE = st.recursive(
    st.none() | st.booleans() | st.integers(min_value=-(10**30), max_value=10**30) | st.floats() | st.text(max_size=12),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner, max_size=3),
    max_leaves=6,
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(path=st.sampled_from(leaf_paths(SITL_DEFAULTS)), value=ANY_VALUE)
def test_no_value_at_any_key_makes_a_traceback(path: tuple[str, ...], value: Any):
    try:
        cfg = sitl_config.load(overrides=nested(path, value))
    except ConfigError as exc:
        text = str(exc)
        assert text and "\n" not in text
        assert ".".join(path) in text, (path, text)
    else:
        assert isinstance(cfg, SitlConfig)


@settings(max_examples=100, deadline=None)
@given(
    path=st.sampled_from(leaf_paths(SITL_DEFAULTS)),
    value=st.floats(min_value=-1e6, max_value=1e6) | st.integers(min_value=-1000, max_value=1000),
)
def test_a_number_anywhere_loads_or_names_its_key(path: tuple[str, ...], value: float):
    # numbers are the likely mistakes: they reach the range and relation checks, not only the type checks
    try:
        cfg = sitl_config.load(overrides=nested(path, value))
    except ConfigError as exc:
        assert ".".join(path) in str(exc) and "\n" not in str(exc)
    else:
        assert isinstance(cfg, SitlConfig)
