"""The configuration convention: YAML numbers read the YAML 1.2 way, every numeric key ranged, and no
value anywhere can make a traceback - only a one-line ConfigError naming the key (property-based)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from koopguide.base import config
from koopguide.base.config import ConfigError
from koopguide.guidance import settings as guidance_settings
from tests.support.config_paths import leaf_paths, nested

GUIDANCE_DEFAULTS = config.load_yaml(config.default_config_path("guidance"))


def test_yaml_numbers_are_read_the_yaml_1_2_way(tmp_path: Path):
    user = tmp_path / "user.yaml"
    user.write_text("command:\n  max_speed_mps: 2e-1\n  lead_s: 5E-2\n  speed_grid: 100\n")
    cfg = guidance_settings.load(user)
    assert cfg.command.max_speed_mps == pytest.approx(0.2)
    assert cfg.command.lead_s == pytest.approx(0.05)
    assert config.load_yaml(user)["command"]["max_speed_mps"] == pytest.approx(0.2)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("command:\n  max_speed_mps: 1.0e300\n", "command.max_speed_mps: 1e+300 is out of range"),
        ("command:\n  speed_grid: 1e7\n", "command.speed_grid: expected an integer, got 10000000.0"),
        ("command:\n  speed_grid: 100000\n", "command.speed_grid: 100000 is out of range"),
        ("command:\n  rate_hz: .nan\n", "command.rate_hz: nan is out of range"),
        ("estimator:\n  gate_chi2: -.inf\n", "estimator.gate_chi2: -inf is out of range"),
        ("frame:\n  goal_ned: [0, .inf]\n", "frame.goal_ned[1]: inf is out of range"),
        ("status:\n  rate_hz: 0\n", "status.rate_hz: 0.0 is out of range (expected a number in (0, 50])"),
        ("command:\n  max_speed_mps: '0.3'\n", "command.max_speed_mps: expected a number, got '0.3' (str)"),
        (
            "command:\n  approach_speed_mps: 0.1\n",
            "command.approach_speed_mps: 0.1 is out of range (expected at least turn_speed_mps (0.15))",
        ),
    ],
)
def test_absurd_numbers_are_one_line_errors_naming_the_key(tmp_path: Path, text: str, message: str):
    user = tmp_path / "user.yaml"
    user.write_text(text)
    with pytest.raises(ConfigError) as caught:
        guidance_settings.load(user)
    assert message in str(caught.value)
    assert "\n" not in str(caught.value)


def test_every_numeric_key_declares_its_range():
    from koopguide.model.learn.trainer import TrainConfig
    from sitl.config import SitlConfig

    for cls in (guidance_settings.GuidanceConfig, TrainConfig, SitlConfig):
        assert config.numeric_without_range(cls) == [], cls.__name__


def test_a_range_is_closed_or_open_as_declared():
    r = config.Range(0.0, 1.0, lo_open=True)
    assert not r.contains(0.0) and r.contains(1.0) and r.contains(0.5)
    assert not r.contains(math.nan) and not config.FINITE.contains(math.inf)
    assert not config.FINITE.contains(10**400)  # no OverflowError: simply out of range
    assert str(r) == "a number in (0, 1]" and str(config.POSITIVE) == "a finite number > 0"


# --------------------------------------------------------------------------------- properties
ANY_VALUE = st.recursive(
    st.none() | st.booleans() | st.integers(min_value=-(10**30), max_value=10**30) | st.floats() | st.text(max_size=12),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner, max_size=3),
    max_leaves=6,
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(path=st.sampled_from(leaf_paths(GUIDANCE_DEFAULTS)), value=ANY_VALUE)
def test_no_value_at_any_key_makes_a_traceback(path: tuple[str, ...], value: Any):
    try:
        cfg = guidance_settings.load(overrides=nested(path, value))
    except ConfigError as exc:
        text = str(exc)
        assert text and "\n" not in text
        assert text.startswith(path[0]) or text.startswith(".".join(path[:1]))
    else:
        assert isinstance(cfg, guidance_settings.GuidanceConfig)


@settings(max_examples=100, deadline=None)
@given(key=st.text(min_size=1, max_size=10).filter(lambda k: k not in GUIDANCE_DEFAULTS), value=ANY_VALUE)
def test_unknown_keys_are_refused_by_name(key: str, value: Any):
    with pytest.raises(ConfigError, match="unknown key"):
        guidance_settings.load(overrides={key: value})


@settings(max_examples=200, deadline=None)
@given(text=st.text(max_size=200))
def test_any_yaml_text_loads_as_a_mapping_or_is_a_config_error(tmp_path_factory: pytest.TempPathFactory, text: str):
    path = tmp_path_factory.mktemp("yaml") / "f.yaml"
    path.write_text(text, encoding="utf-8")
    try:
        data = config.load_yaml(path)
    except ConfigError as exc:
        assert str(path) in str(exc)
    else:
        assert isinstance(data, dict)
