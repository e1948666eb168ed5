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

from koopguide.base.entry import run_entry
from koopguide.base.flags import Flag, add_flags, name_list, overrides_from
from koopguide.mavlink.signing import SIGNING_KEY_FLAG
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


#: Flags of ``koopguide sitl`` that set keys of config/sitl.yaml.
SITL_FLAGS: tuple[Flag, ...] = (
    Flag(
        "--mavlink",
        "mavlink.endpoints",
        str,
        "udpout:HOST:PORT, udpin:HOST:PORT, tcpin:HOST:PORT or "
        "tcp:HOST:PORT; repeatable (default udpout:127.0.0.1:14550)",
        metavar="ENDPOINT",
        repeat=True,
    ),
    SIGNING_KEY_FLAG,
    Flag("--speedup", "speedup", speedup_value, "simulated s per wall s, or 'max'", metavar="X"),
    Flag(
        "--flow",
        "flow.kinds",
        name_list,
        "none, uniform, vortex, double_gyre, gusts; comma-separated to sum",
        metavar="KIND",
    ),
    Flag("--count", "count", int, "number of boats (system ids 1..N)", metavar="N"),
    Flag(
        "--vehicle",
        "vehicles",
        name_list,
        "diff_thrust (default), rudder or vectored; comma-separated for one kind per boat",
        metavar="KIND",
    ),
    Flag("--seed", "seed", int, "random seed for flow and sensor noise", metavar="N"),
    Flag("--duration", "duration_s", float, "stop after S simulated seconds", metavar="S"),
    Flag("--record", "recorder.path", str, "write ground truth as JSON lines to FILE", metavar="FILE"),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", metavar="FILE", help="YAML file overriding config/sitl.yaml")
    add_flags(parser, SITL_FLAGS)
    parser.add_argument("--quiet", action="store_true", help="log warnings only")


def overrides(args: argparse.Namespace) -> dict[str, Any]:
    """Config overrides from the flags that were given (one ``--vehicle`` kind is every boat's ``vehicle``)."""
    out = overrides_from(args, SITL_FLAGS)
    if len(out.get("vehicles", ())) == 1:
        out["vehicle"] = out.pop("vehicles")[0]
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


def main(argv: list[str] | None = None) -> int:
    """``python -m sitl``: the same command as ``koopguide sitl``."""
    parser = argparse.ArgumentParser(prog="sitl", description="Run the bundled boat simulator.")
    add_arguments(parser)
    args = parser.parse_args(argv)
    return run_entry("koopguide", lambda: run(args))


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
                f"sitl: {link.endpoint}: in {s.received} msgs, out {s.sent} msgs, "
                f"garbage {s.garbage_bytes} bytes in {s.corrupt} runs, "
                f"dropped {s.unsigned} unsigned and {s.bad_signature} badly signed",
                flush=True,
            )
    return 0
