"""Command-line entry point: ``koopguide <command> ...``.

Each command parses its own flags, builds its typed configuration once, and calls into the library.
Expected failures (bad input, bad files) end with one line ``koopguide: error: ...`` and exit code 2
(:func:`koopguide.base.entry.run_entry`); anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

from koopguide.base.entry import run_entry

Registrar = Callable[[argparse._SubParsersAction], None]


def _registrars() -> list[Registrar]:
    # Imported lazily so `koopguide eval` never pays for torch, and `koopguide sitl` never for the learner.
    from koopguide.cli import dashboard, fleet, guide, learn, monitor, replay

    registrars: list[Registrar] = [
        learn.register,
        guide.register,
        monitor.register,
        dashboard.register,
        replay.register,
        fleet.register,
    ]
    try:
        from sitl import cli as sitl_cli
    except ImportError as exc:  # the simulator package is part of this distribution
        if exc.name not in ("sitl", "sitl.cli"):
            raise
    else:
        registrars.append(sitl_cli.register)
    return registrars


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="koopguide",
        description="Learn goal-converging flow fields from demonstrations and steer boats along them.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for register in _registrars():
        register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    return run_entry("koopguide", lambda: args.run(args))


if __name__ == "__main__":
    sys.exit(main())
