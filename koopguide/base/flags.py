"""Command-line flags that override configuration keys, each declared once.

A :class:`Flag` names the flag, the configuration key it sets (a dotted path into the YAML), how its
text is parsed and its help; :func:`add_flags` adds a list of them to an argparse parser and
:func:`overrides_from` turns the parsed flags that were given into the nested override mapping that
:func:`koopguide.base.config.load_layers` merges over the defaults and the user's file.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Flag:
    """``--flag VALUE`` sets configuration key ``key`` to ``parse(VALUE)``; with ``parse=None`` it is a switch
    (given: true)."""

    flag: str
    key: str
    parse: Callable[[str], Any] | None
    help: str
    metavar: str | None = None
    repeat: bool = False  # may be given several times: the key gets the list of values

    @property
    def dest(self) -> str:
        return "cfg__" + self.key.replace(".", "__")


def add_flags(parser: argparse.ArgumentParser, flags: Sequence[Flag]) -> None:
    for f in flags:
        if f.parse is None:
            parser.add_argument(f.flag, dest=f.dest, action="store_true", default=None, help=f.help)
        else:
            parser.add_argument(
                f.flag,
                dest=f.dest,
                type=f.parse,
                metavar=f.metavar or f.flag.lstrip("-").upper().replace("-", "_"),
                help=f.help,
                action="append" if f.repeat else "store",
            )


def overrides_from(args: argparse.Namespace, flags: Sequence[Flag]) -> dict[str, Any]:
    """The flags that were given, as a nested mapping ``{"command": {"max_speed_mps": 0.3}, ...}``."""
    out: dict[str, Any] = {}
    for f in flags:
        value = getattr(args, f.dest, None)
        if value is None:
            continue
        *path, last = f.key.split(".")
        node = out
        for part in path:
            node = node.setdefault(part, {})
        node[last] = _plain(value)
    return out


def _plain(value: Any) -> Any:
    """Tuples become lists, as YAML would give them."""
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    return value


def number_pair(text: str) -> tuple[float, float]:
    """``A,B``: two numbers."""
    parts = text.split(",")
    try:
        values = tuple(float(v) for v in parts)
    except ValueError:
        values = ()
    if len(values) != 2:
        raise argparse.ArgumentTypeError(f"expected two numbers as A,B, got {text!r}")
    return values  # type: ignore[return-value]


def name_list(text: str) -> list[str]:
    """``a,b,c``: a comma-separated list of names (empty items dropped)."""
    return [item.strip() for item in text.split(",") if item.strip()]
