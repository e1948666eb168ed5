"""How every command-line entry point ends: one line for the user's errors, a traceback for our bugs.

Expected failures (bad input, bad files) end with one line ``PROG: error: ...`` on stderr and exit code
2; an interrupt exits 130; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

#: Errors that are the user's input, not our bug: each has a one-line message naming the problem.
USER_ERRORS: tuple[type[BaseException], ...] = (ValueError, FileNotFoundError, PermissionError, IsADirectoryError)


def run_entry(prog: str, command: Callable[[], int | None]) -> int:
    """Run ``command`` and turn the user's errors into one line and exit code 2."""
    try:
        return int(command() or 0)
    except USER_ERRORS as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
