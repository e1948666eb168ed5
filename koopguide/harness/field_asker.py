"""A dashboard's field queries for ``koopguide bench guidance``: ``koopguide/<id>/field?n=N`` at a steady rate.

The bench drives it through :class:`FieldAsker` (start, ``go`` at the window's start, answers at its end).

Run as its own process (``python -m koopguide.harness.field_asker``), as a dashboard is: it opens a real
zenoh session with the shipped loopback configuration (multicast scouting off) on the bench's rendezvous
port, waits for the line ``go`` on stdin, then asks at ``--hz`` until stdin closes, cycling through
``--sizes``, each reply decoded as a dashboard would. One JSON line per query on stdout:
``{"t_s": since go, "n": asked, "ok": bool, "points": grid points, "bytes": reply size, "ms": round trip}``
(``error`` instead of ``points`` when the service answered with an error or not at all).
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import socket
import sys
import threading
import time
from asyncio.subprocess import PIPE
from dataclasses import dataclass
from typing import Any

import zenoh

from koopguide.bus.zenoh_config import default_zenoh_config

ASK_TIMEOUT_S = 20.0  # a query unanswered this long counts as failed
QUERY_HZ = 1.0  # field queries per second during the bench's window
QUERY_SIZES = (200,)  # their grid sizes n, cycled (200: the largest, 1.4 MB of JSON)
ASKER_TIMEOUT_S = 30.0  # wall seconds for the asker's zenoh session to open, and for its last reply


class AskerError(RuntimeError):
    """The asker process did not start or finish; the message says which."""


@dataclass(frozen=True)
class Queries:
    """The field queries asked during the window: rate [Hz] (0: no zenoh at all) and grid sizes cycled."""

    hz: float = QUERY_HZ
    sizes: tuple[int, ...] = QUERY_SIZES


DEFAULT_QUERIES = Queries()


class FieldAsker:
    """The bench's handle on one asker process: :meth:`start`, :meth:`go`, :meth:`answers`, :meth:`close`."""

    def __init__(self, process: asyncio.subprocess.Process) -> None:
        self.process = process

    @classmethod
    async def start(cls, zport: int, vehicle_id: str, queries: Queries) -> FieldAsker:
        """The asker started with its zenoh session open (rendezvous port ``zport``), waiting for go."""
        sizes = ",".join(str(n) for n in queries.sizes)
        command = ["-m", "koopguide.harness.field_asker", "--port", str(zport), "--vehicle", vehicle_id]
        process = await asyncio.create_subprocess_exec(
            sys.executable, *command, "--hz", f"{queries.hz:g}", "--sizes", sizes, stdin=PIPE, stdout=PIPE
        )
        asker = cls(process)
        try:
            ready = await asyncio.wait_for(process.stdout.readline(), ASKER_TIMEOUT_S)
        except TimeoutError:
            ready = b""
        if not ready.strip():
            await asker.close()
            raise AskerError(f"the field-query process did not open its zenoh session within {ASKER_TIMEOUT_S:g} s")
        return asker

    def go(self) -> None:
        """Start asking (the window starts)."""
        self.process.stdin.write(b"go\n")

    async def answers(self, seconds: float) -> list[dict[str, Any]]:
        """Stop asking; the queries asked within ``seconds`` of go (a slow last reply is waited for)."""
        self.process.stdin.close()
        try:
            out, _ = await asyncio.wait_for(self.process.communicate(), ASKER_TIMEOUT_S)
        except TimeoutError:
            raise AskerError(f"the field-query process did not finish within {ASKER_TIMEOUT_S:g} s") from None
        answers = [json.loads(line) for line in out.decode().splitlines() if line.strip()]
        return [a for a in answers if a["t_s"] < seconds]

    async def close(self) -> None:
        if self.process.returncode is None:
            self.process.kill()
            await self.process.wait()


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def size_list(text: str) -> list[int]:
    try:
        sizes = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated grid sizes, got {text!r}") from None
    if not sizes or not all(2 <= n <= 200 for n in sizes):
        raise argparse.ArgumentTypeError(f"expected grid sizes in 2 .. 200 (the service's range), got {text!r}")
    return sizes


def ask(session: zenoh.Session, key: str, n: int, t0: float) -> dict:
    started = time.perf_counter()
    line = {"t_s": round(started - t0, 3), "n": n, "ok": False}
    try:
        replies = list(session.get(f"{key}?n={n}", timeout=ASK_TIMEOUT_S))
    except zenoh.ZError as exc:
        return {**line, "error": f"{type(exc).__name__}: {exc}"}
    line["ms"] = round((time.perf_counter() - started) * 1000.0, 2)
    ok = [reply.ok for reply in replies if reply.ok is not None]
    if not ok:
        errors = [str(reply.err.payload.to_string()) for reply in replies if reply.err is not None]
        return {**line, "error": "; ".join(errors) or "no reply"}
    payload = ok[0].payload.to_bytes()
    grid = json.loads(payload)
    return {**line, "ok": True, "points": len(grid["position_ned"]), "bytes": len(payload)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m koopguide.harness.field_asker", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--port", type=int, required=True, help="zenoh rendezvous port (loopback)")
    parser.add_argument("--vehicle", required=True, help="the service's vehicle id")
    parser.add_argument("--hz", type=float, default=1.0, help="queries per second (default 1)")
    parser.add_argument("--sizes", type=size_list, default=list(QUERY_SIZES), help="grid sizes n, cycled (default 200)")
    args = parser.parse_args(argv)
    if not args.hz > 0:
        parser.error(f"--hz must be > 0, got {args.hz:g}")

    stop = threading.Event()
    with zenoh.open(default_zenoh_config(args.port)) as session:
        print(json.dumps({"ready": True}), flush=True)
        if sys.stdin.readline().strip() != "go":
            return 0
        threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
        t0 = time.perf_counter()
        key = f"koopguide/{args.vehicle}/field"
        for k, n in enumerate(itertools.cycle(args.sizes)):
            due = t0 + k / args.hz
            if stop.wait(max(due - time.perf_counter(), 0.0)):
                break
            print(json.dumps(ask(session, key, n, t0)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
