"""Key paths of a configuration mapping, for property tests that put any value at any key."""

from __future__ import annotations

from typing import Any


def leaf_paths(data: dict[str, Any], prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every path to a non-mapping value, e.g. ``("command", "rate_hz")``."""
    out = []
    for key, value in data.items():
        if isinstance(value, dict):
            out += leaf_paths(value, (*prefix, key))
        else:
            out.append((*prefix, key))
    return out


def nested(path: tuple[str, ...], value: Any) -> dict[str, Any]:
    """``{"a": {"b": value}}`` for ``("a", "b")``."""
    out: Any = value
    for key in reversed(path):
        out = {key: out}
    return out
