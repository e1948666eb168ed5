"""``koopguide sitl`` / ``python -m sitl``: run the boat simulator until interrupted (or --duration).

On start it prints one line per link, ``sitl: boat SYSID mavlink KIND:HOST:PORT`` (ports bound with
port 0 are resolved), then ``sitl: ready``, so a parent process can wait for it. SIGINT/SIGTERM stop
it cleanly; it then prints the simulated/wall time and each link's counters.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import signal
import sys
from typing import Any

from sitl import config as sitl_config
from sitl.config import SitlConfig
from sitl.runner import Simulation


def speedup_value(text: str) -> float:
    """--speedup: a factor > 0, or 'max' (as fast as possible)."""
    if text.lower() == "max":
        return 0.0
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number or 'max', got {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0 (or 'max'), got {text!r}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", metavar="FILE", help="YAML file overriding config/sitl.yaml")
    parser.add_argument(
        "--mavlink",
        metavar="ENDPOINT",
        action="append",
        help="udpout:HOST:PORT, udpin:HOST:PORT, tcpin:HOST:PORT or tcp:HOST:PORT; repeatable "
        "(default udpout:127.0.0.1:14550)",
    )
    parser.add_argument("--speedup", metavar="X", type=speedup_value, help="simulated s per wall s, or 'max'")
    parser.add_argument(
        "--flow", metavar="KIND", help="none, uniform, vortex, double_gyre, gusts; comma-separated to sum"
    )
    parser.add_argument("--count", metavar="N", type=int, help="number of boats (system ids 1..N)")
    parser.add_argument(
        "--vehicle",
        metavar="KIND",
        help="diff_thrust (default), rudder or vectored; comma-separated for one kind per boat",
    )
    parser.add_argument("--seed", metavar="N", type=int, help="random seed for flow and sensor noise")
    parser.add_argument("--duration", metavar="S", type=float, help="stop after S simulated seconds")
    parser.add_argument("--record", metavar="FILE", help="write ground truth as JSON lines to FILE")
    parser.add_argument("--quiet", action="store_true", help="log warnings only")


def overrides(args: argparse.Namespace) -> dict[str, Any]:
    """Config overrides from the flags that were given."""
    out: dict[str, Any] = {}
    if args.mavlink:
        out["mavlink"] = {"endpoints": list(args.mavlink)}
    if args.speedup is not None:
        out["speedup"] = args.speedup
    if args.flow is not None:
        out["flow"] = {"kinds": [k.strip() for k in args.flow.split(",") if k.strip()]}
    if args.count is not None:
        out["count"] = args.count
    if args.vehicle is not None:
        kinds = [k.strip() for k in args.vehicle.split(",") if k.strip()]
        if len(kinds) == 1:
            out["vehicle"] = kinds[0]
        else:
            out["vehicles"] = kinds
    if args.seed is not None:
        out["seed"] = args.seed
    if args.duration is not None:
        out["duration_s"] = args.duration
    if args.record is not None:
        out["recorder"] = {"path": args.record}
    return out


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "sitl",
        help="run the bundled boat simulator (speaks MAVLink like an ArduPilot Rover boat)",
        description="Simulate small autonomous surface vehicles in a tank with flow disturbances, "
        "each speaking MAVLink like an ArduPilot Rover boat.",
    )
    add_arguments(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    cfg = sitl_config.load(args.config, overrides(args))
    logging.basicConfig(
        level=logging.WARNING if args.quiet else logging.INFO, format="sitl: %(message)s", stream=sys.stderr
    )
    return asyncio.run(serve(cfg))


async def serve(cfg: SitlConfig) -> int:
    sim = await Simulation.create(cfg)
    try:
        loop = asyncio.get_running_loop()
        with contextlib.suppress(NotImplementedError):  # no signal handlers on some platforms
            loop.add_signal_handler(signal.SIGTERM, sim.stop)
        for sysid, addresses in sim.addresses().items():
            for address in addresses:
                print(f"sitl: boat {sysid} mavlink {address}")
        print("sitl: ready", flush=True)
        await sim.run()
    finally:
        await sim.close()
        wall = sim.wall_time_running_s
        ratio = sim.t / wall if wall > 0 else float("nan")
        print(f"sitl: stopped at t = {sim.t:.2f} s simulated, {wall:.2f} s wall ({ratio:.1f}x)", flush=True)
        for link in sim.links:
            s = link.stats
            print(
                f"sitl: {link.endpoint}: in {s.messages_in} msgs, out {s.messages_out} msgs, "
                f"garbage {s.garbage_bytes} bytes in {s.bad_messages} runs",
                flush=True,
            )
    return 0
