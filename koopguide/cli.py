"""Command-line entry point: ``koopguide <command> ...``.

Each command parses its own flags, builds its typed configuration once, and calls into the library.
Expected failures (bad input, bad files) end with one line ``koopguide: error: ...`` and exit code 2;
anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

# Errors that are the user's input, not our bug: each has a one-line message naming the problem.
USER_ERRORS: tuple[type[BaseException], ...] = (ValueError, FileNotFoundError, PermissionError, IsADirectoryError)

Registrar = Callable[[argparse._SubParsersAction], None]


def _registrars() -> list[Registrar]:
    # Imported lazily so `koopguide eval` never pays for torch, and `koopguide sitl` never for the learner.
    from koopguide import commands_guide, commands_learn, commands_monitor, replay
    from koopguide.dashboard import command as commands_dashboard

    registrars: list[Registrar] = [commands_learn.register, commands_guide.register, commands_monitor.register,
                                   commands_dashboard.register, replay.register]
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
    try:
        return int(args.run(args) or 0)
    except USER_ERRORS as exc:
        print(f"koopguide: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("koopguide: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
