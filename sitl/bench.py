"""``python -m sitl.bench``: how much faster than real time the simulator runs, with no client.

It runs the full simulator - physics, sensors, autopilot, recorder off, telemetry encoded and sent at
the default rates to a loopback UDP port nobody listens on - for a stretch of simulated time and
prints the simulated-to-wall ratio. ``--speedup max`` (the default) measures the ceiling on one core;
``--speedup 20`` checks that the paced clock keeps up.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import socket
import sys
import time

from sitl import config as sitl_config
from sitl.cli import speedup_value
from sitl.runner import Simulation


def unused_udp_port() -> int:
    """A loopback UDP port that nothing listens on (bound briefly by the OS, then released)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


async def measure(count: int, flow: str, speedup: float, sim_seconds: float) -> tuple[float, float]:
    """(simulated seconds, wall seconds) of one run."""
    cfg = sitl_config.load(
        overrides={
            "count": count,
            "speedup": speedup,
            "flow": {"kinds": [k for k in flow.split(",") if k]},
            "mavlink": {"endpoints": [f"udpout:127.0.0.1:{unused_udp_port()}"], "port_stride": 0},
            "unix_time_at_boot_s": 0.0,
        }
    )
    async with await Simulation.create(cfg) as sim:
        start = time.perf_counter()
        await sim.run(duration_s=sim_seconds)
        wall = time.perf_counter() - start
        return sim.t, wall


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m sitl.bench", description=__doc__.splitlines()[0])
    parser.add_argument("--speedup", type=speedup_value, default=0.0, help="factor or 'max' (default max)")
    parser.add_argument(
        "--seconds", type=float, default=None, help="simulated seconds (default 300, 20 x speedup when paced)"
    )
    parser.add_argument("--count", type=int, default=1, help="boats (default 1)")
    parser.add_argument("--flow", default="none", help="flow kinds, comma-separated (default none)")
    args = parser.parse_args(argv)
    logging.getLogger("sitl").setLevel(logging.ERROR)  # wall contacts are not news in a benchmark
    seconds = args.seconds if args.seconds is not None else (300.0 if args.speedup == 0 else 5.0 * args.speedup)
    sim_s, wall_s = asyncio.run(measure(args.count, args.flow, args.speedup, seconds))
    pace = "max speed" if args.speedup == 0 else f"--speedup {args.speedup:g}"
    print(
        f"sitl bench ({pace}): {args.count} boat(s), flow {args.flow}: {sim_s:.1f} s simulated in "
        f"{wall_s:.2f} s wall -> sim-to-wall ratio {sim_s / wall_s:.1f}x"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
