"""Typed configuration: YAML mappings become frozen dataclasses, strictly.

A configuration is built once, at an entry point, from three layers merged in order: the shipped
defaults in ``config/<name>.yaml``, an optional user file (``--config FILE``), then command-line
overrides. :func:`build` turns the merged mapping into a dataclass and rejects unknown keys, missing
keys and ill-typed values with a :class:`ConfigError` that names the key path and the value seen.

Supported field types: ``bool``, ``int``, ``float`` (an int is accepted), ``str``, ``pathlib.Path``,
``enum.Enum`` subclasses (by value), ``tuple[T, ...]``, ``tuple[T1, T2]``, ``X | None`` and nested
dataclasses. Every numeric key declares its interval once, in its type: ``Annotated[float, Range(0, 50,
lo_open=True)]``; :func:`build` checks it (and finiteness) while loading, so a dataclass only checks
relations between keys in ``__post_init__`` (with :func:`check`). YAML numbers are read the YAML 1.2
way: ``1e7`` and ``1.0e300`` are numbers, not strings.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import re
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, TypeVar

import yaml

T = TypeVar("T")

#: The shipped defaults, one YAML file per entry point (train, sitl, guidance), installed with the package
#: (``koopguide/defaults``; the checkout's top-level ``config/`` is a link to it).
CONFIG_DIR = Path(__file__).resolve().parent.parent / "defaults"


class ConfigError(ValueError):
    """A configuration file or value is unusable; the message names the key and the value seen."""


@dataclass(frozen=True)
class Range:
    """The interval a numeric key must lie in (closed ends unless ``*_open``); NaN and infinity never do."""

    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    hi_open: bool = False

    def contains(self, value: float) -> bool:
        try:
            if not math.isfinite(value):
                return False
        except OverflowError:  # an integer beyond any float, e.g. a YAML 1 followed by 400 zeros
            return False
        above = value > self.lo if self.lo_open else value >= self.lo
        below = value < self.hi if self.hi_open else value <= self.hi
        return above and below

    def __str__(self) -> str:
        if self.lo == -math.inf and self.hi == math.inf:
            return "a finite number"
        if self.hi == math.inf:
            return f"a finite number {'>' if self.lo_open else '>='} {self.lo:g}"
        if self.lo == -math.inf:
            return f"a finite number {'<' if self.hi_open else '<='} {self.hi:g}"
        left, right = "(" if self.lo_open else "[", ")" if self.hi_open else "]"
        return f"a number in {left}{self.lo:g}, {self.hi:g}{right}"


#: Common intervals.
POSITIVE = Range(0.0, lo_open=True)
NON_NEGATIVE = Range(0.0)
FINITE = Range()
#: Shorthands for the common numeric key types.
PositiveFloat = Annotated[float, POSITIVE]
NonNegativeFloat = Annotated[float, NON_NEGATIVE]
FiniteFloat = Annotated[float, FINITE]


def check(ok: bool, key: str, value: Any, expected: str) -> None:
    """Raise a ConfigError naming ``key``, the value seen and what was expected, unless ``ok``."""
    if not ok:
        raise ConfigError(f"{key}: {value!r} is out of range (expected {expected})")


class _Yaml12Loader(yaml.SafeLoader):
    """PyYAML's safe loader, reading floats as YAML 1.2 does (``1e7``, ``1.0e300``; PyYAML wants a dot and a
    signed exponent and would otherwise return such numbers as strings)."""


_Yaml12Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"^(?:[-+]?(?:[0-9][0-9_]*\.[0-9_]*|\.[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)?|[-+]?[0-9][0-9_]*[eE][-+]?[0-9]+"
        r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$"
    ),
    list("-+0123456789."),
)


def default_config_path(name: str) -> Path:
    """Path of the shipped default configuration ``config/<name>.yaml``."""
    path = CONFIG_DIR / f"{name}.yaml"
    if not path.is_file():
        raise ConfigError(f"default configuration {path} is missing (a broken installation: reinstall koopguide)")
    return path


def read_config_text(path: Path, what: str = "configuration") -> str:
    """The text of a configuration file, or a ConfigError naming the file and what went wrong."""
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{path}: {what} file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read {what} ({exc})") from None


def load_yaml(path: str | Path) -> dict[str, Any]:
    """Read a YAML file whose top level is a mapping (an empty file is an empty mapping)."""
    path = Path(path)
    text = read_config_text(path)
    try:
        data = yaml.load(text, Loader=_Yaml12Loader)
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        at = f" at line {where.line + 1}" if where is not None else ""
        raise ConfigError(f"{path}: invalid YAML{at}: {getattr(exc, 'problem', exc)}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: top level must be a mapping of keys, got {type(data).__name__}")
    return data


def merge(base: Mapping[str, Any], override: Mapping[str, Any]) -> dict[str, Any]:
    """Deep-merge ``override`` into a copy of ``base`` (nested mappings merge, other values replace)."""
    out = dict(base)
    for key, value in override.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = merge(out[key], value)
        else:
            out[key] = value
    return out


def load_layers(name: str, user_file: str | Path | None, overrides: Mapping[str, Any]) -> dict[str, Any]:
    """Shipped defaults for ``name``, then the user's file, then explicit overrides."""
    data = load_yaml(default_config_path(name))
    if user_file is not None:
        data = merge(data, load_yaml(user_file))
    return merge(data, overrides)


def build(cls: type[T], data: Any, where: str = "") -> T:
    """Build dataclass ``cls`` from mapping ``data``; every key must be known and well typed."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"{where or 'configuration'}: expected a mapping, got {_seen(data)}")
    hints = typing.get_type_hints(cls, include_extras=True)
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(map(str, data)) - set(fields))
    if unknown:
        raise ConfigError(f"{_join(where, unknown[0])}: unknown key (known keys here: {', '.join(sorted(fields))})")
    values = {}
    for name, field in fields.items():
        key = _join(where, name)
        if name in data:
            values[name] = _convert(hints[name], data[name], key)
        elif field.default is dataclasses.MISSING and field.default_factory is dataclasses.MISSING:
            raise ConfigError(f"{key}: missing required key")
    return cls(**values)


def to_plain(obj: Any) -> Any:
    """A dataclass config as plain YAML/JSON-friendly data (enums by value, tuples as lists)."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, enum.Enum):
        return obj.value
    if isinstance(obj, tuple | list):
        return [to_plain(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    return obj


def numeric_without_range(cls: type) -> list[str]:
    """Keys of dataclass ``cls`` (recursively) whose numbers have no :class:`Range`: each should have one."""
    missing = []
    for name, tp in typing.get_type_hints(cls, include_extras=True).items():
        missing += [f"{name}{sub}" for sub in _unranged(tp)]
    return missing


def _unranged(tp: Any) -> list[str]:
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is Annotated:
        return [] if any(isinstance(m, Range) for m in tp.__metadata__) else _unranged(args[0])
    if tp in (int, float):
        return [""]
    if dataclasses.is_dataclass(tp):
        return [f".{key}" for key in numeric_without_range(tp)]
    if origin in (typing.Union, types.UnionType, tuple):
        return sorted({sub for a in args if a is not Ellipsis for sub in _unranged(a)})
    return []


def _check_range(interval: Range, value: Any, key: str) -> None:
    if isinstance(value, tuple):
        for i, item in enumerate(value):
            _check_range(interval, item, f"{key}[{i}]")
    elif isinstance(value, int | float) and not isinstance(value, bool) and not interval.contains(value):
        raise ConfigError(f"{key}: {value!r} is out of range (expected {interval})")


def _join(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


def _seen(value: Any) -> str:
    return f"{value!r} ({type(value).__name__})"


def _convert(tp: Any, value: Any, key: str) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin is Annotated:
        converted = _convert(args[0], value, key)
        for interval in (m for m in tp.__metadata__ if isinstance(m, Range)):
            _check_range(interval, converted, key)
        return converted
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        options = [a for a in args if a is not type(None)]
        errors = []
        for option in options:
            try:
                return _convert(option, value, key)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(errors[0] if len(errors) == 1 else f"{key}: {_seen(value)} matches none of {tp}")
    if dataclasses.is_dataclass(tp):
        return build(tp, value, key)
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{key}: expected a list, got {_seen(value)}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, f"{key}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(f"{key}: expected a list of {len(args)} values, got {len(value)}: {value!r}")
        return tuple(_convert(a, v, f"{key}[{i}]") for i, (a, v) in enumerate(zip(args, value, strict=True)))
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        try:
            return tp(value)
        except ValueError:
            choices = ", ".join(repr(m.value) for m in tp)
            raise ConfigError(f"{key}: {_seen(value)} is not one of {choices}") from None
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{key}: expected true or false, got {_seen(value)}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{key}: expected an integer, got {_seen(value)}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{key}: expected a number, got {_seen(value)}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{key}: expected a string, got {_seen(value)}")
        return value
    if tp is Path:
        if not isinstance(value, str | Path):
            raise ConfigError(f"{key}: expected a path string, got {_seen(value)}")
        return Path(value)
    raise TypeError(f"{key}: unsupported config field type {tp!r}")  # a programming error, not user input
