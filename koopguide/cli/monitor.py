"""``koopguide monitor``: a live terminal table of every guidance daemon's zenoh status.

On a terminal the table is redrawn in place about twice a second; when stdout is not a terminal
(a pipe, a file, a test) each refresh is printed as a plain block followed by a blank line.
``--once`` prints a single table as soon as every alive vehicle has reported, ``--duration S``
stops after S seconds; Ctrl-C (or SIGTERM) stops cleanly with exit code 0.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import shutil
import signal
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:
    from koopguide.bus.monitor import Monitor

#: Seconds between two tables.
REFRESH_S = 0.5
#: Seconds between two looks at the zenoh channels.
POLL_S = 0.05
#: ``--once`` gives up after this long without any status.
ONCE_TIMEOUT_S = 5.0
#: ``--once`` waits at least this long after opening, so every already-alive vehicle is known.
ONCE_SETTLE_S = 0.5


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("monitor", help="live table of every guidance daemon's status (zenoh)")
    p.add_argument(
        "--zenoh-config",
        type=Path,
        metavar="FILE",
        help="zenoh configuration (JSON5) replacing the default config/zenoh.json5",
    )
    when = p.add_mutually_exclusive_group()
    when.add_argument("--duration", type=float, metavar="S", help="exit (code 0) after S seconds")
    when.add_argument(
        "--once",
        action="store_true",
        help=f"print one table once every alive vehicle has reported; exit 1 if no status "
        f"arrives within {ONCE_TIMEOUT_S:g} s",
    )
    p.set_defaults(run=cmd_monitor)

    p = sub.add_parser(
        "zenoh-router",
        help="a zenoh router for a group of koopguide processes (e.g. with access "
        "control: config/zenoh-router-acl.json5), until interrupted",
    )
    p.add_argument(
        "--zenoh-config",
        type=Path,
        metavar="FILE",
        required=True,
        help="the router's zenoh configuration (JSON5), e.g. a copy of config/zenoh-router-acl.json5",
    )
    p.add_argument("--duration", type=float, metavar="S", help="exit (code 0) after S seconds")
    p.set_defaults(run=cmd_router)


def cmd_router(args: argparse.Namespace) -> int:
    """Hold a zenoh session in router mode open until SIGINT/SIGTERM (or ``--duration``)."""
    import zenoh

    from koopguide.base.config import ConfigError
    from koopguide.bus.zenoh_config import load_zenoh_config, zenoh_error_text

    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise ValueError(f"--duration must be a positive number of seconds, got {args.duration:g}")
    cfg = load_zenoh_config(args.zenoh_config)
    if json.loads(cfg.get_json("mode")) != "router":
        raise ConfigError(f'{args.zenoh_config}: mode must be "router" for a router')
    try:
        session = zenoh.open(cfg)
    except zenoh.ZError as exc:
        raise ConfigError(f"cannot start the zenoh router: {zenoh_error_text(exc)}") from None
    try:
        with stop_on_signals() as stop:
            print(
                f"koopguide zenoh-router: {session.zid()} listening on {json.loads(cfg.get_json('listen/endpoints'))}",
                file=sys.stderr,
                flush=True,
            )
            end = math.inf if args.duration is None else time.monotonic() + args.duration
            while not stop.is_set() and time.monotonic() < end:
                time.sleep(min(0.2, max(0.0, end - time.monotonic())))
    finally:
        session.close()
    return 0


def cmd_monitor(args: argparse.Namespace) -> int:
    from koopguide.bus.monitor import Monitor
    from koopguide.bus.zenoh_config import load_zenoh_config

    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise ValueError(f"--duration must be a positive number of seconds, got {args.duration:g}")
    zenoh_config = load_zenoh_config(args.zenoh_config)
    out = sys.stdout
    try:
        with Monitor.open(zenoh_config) as monitor, stop_on_signals() as stop:
            if args.once:
                return _once(monitor, out, stop)
            return _live(monitor, out, args.duration, stop)
    except KeyboardInterrupt:  # Ctrl-C while the session was still opening; it is closed above
        return 0
    except BrokenPipeError:  # `koopguide monitor | head`: the reader has gone, which is fine
        os.dup2(os.open(os.devnull, os.O_WRONLY), out.fileno())  # no second error when Python flushes at exit
        return 0


@contextlib.contextmanager
def stop_on_signals() -> Iterator[threading.Event]:
    """Ctrl-C (SIGINT) and SIGTERM set the event, which the loops below look at between two polls, instead of
    raising KeyboardInterrupt wherever the main thread happens to be: raised inside a zenoh call, it can leave the
    session unable to close (a monitor in CI hung for 10 s after Ctrl-C, its session never closed)."""
    stop = threading.Event()
    previous = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _once(monitor: Monitor, out: TextIO, stop: threading.Event) -> int:
    deadline = monitor.opened_at + ONCE_TIMEOUT_S
    while True:
        if stop.is_set():
            return 0
        monitor.poll()
        now = time.monotonic()
        settled = now - monitor.opened_at >= ONCE_SETTLE_S
        if (settled and monitor.state.all_alive_reported()) or now >= deadline:
            break
        time.sleep(POLL_S)
    state = monitor.state
    if not any(v.status is not None for v in state.vehicles.values()):
        alive = sorted(v.vehicle_id for v in state.vehicles.values() if v.alive)
        seen = f" ({len(alive)} alive: {', '.join(alive)})" if alive else ""
        print(f"koopguide monitor: no vehicle status received within {ONCE_TIMEOUT_S:g} s{seen}", file=sys.stderr)
        return 1
    out.write(monitor.table() + "\n")
    out.flush()
    silent = sorted(v.vehicle_id for v in state.vehicles.values() if v.alive and v.status is None)
    if silent:
        print(f"koopguide monitor: alive but no status yet: {', '.join(silent)}", file=sys.stderr)
    return 0


def _live(monitor: Monitor, out: TextIO, duration: float | None, stop: threading.Event) -> int:
    tty = out.isatty()
    start = time.monotonic()
    end = None if duration is None else start + duration
    next_draw = start
    drawn_lines = 0
    while True:
        if stop.is_set():  # Ctrl-C is how a live table is meant to end
            if tty:
                out.write("\n")
            return 0
        monitor.poll()
        now = time.monotonic()
        finished = end is not None and now >= end
        if now >= next_draw or finished:
            table = monitor.table()
            if tty:
                drawn_lines = _redraw(out, table, drawn_lines)
            else:
                out.write(table + "\n\n")
            out.flush()
            next_draw = max(next_draw + REFRESH_S, now)
        if finished:
            return 0
        time.sleep(POLL_S if end is None else max(0.0, min(POLL_S, end - now)))


def _redraw(out: TextIO, table: str, previous_lines: int) -> int:
    """Overwrite the previous table in place (ANSI: cursor up, clear each line, clear below)."""
    width = shutil.get_terminal_size((120, 24)).columns
    lines = [line[: width - 1] for line in table.splitlines()]  # a wrapped line would break the count
    up = f"\x1b[{previous_lines}F" if previous_lines else ""
    out.write(up + "".join(f"{line}\x1b[K\n" for line in lines) + "\x1b[J")
    return len(lines)
