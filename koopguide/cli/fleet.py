"""``koopguide fleet --config fleet.yaml``: N vehicles guided from one process (koopguide.guidance.fleet)."""

from __future__ import annotations

import argparse
import asyncio
import signal
from pathlib import Path
from typing import Any


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fleet", help="guide N vehicles from one process to rendezvous slots, keeping separation")
    p.add_argument(
        "--config", required=True, type=Path, help="fleet file: model, frame, slots, vehicles (docs/fleet.md)"
    )
    p.add_argument("--zenoh-config", type=Path, help="zenoh config (JSON5) replacing the loopback default")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    p.set_defaults(run=cmd_fleet)


def cmd_fleet(args: argparse.Namespace) -> int:
    from koopguide.base.config import ConfigError
    from koopguide.bus.zenoh_config import load_zenoh_config
    from koopguide.cli.guide import setup_logging
    from koopguide.guidance.fleet import load_fleet, vehicle_configs
    from koopguide.guidance.link import link_settings

    fleet = load_fleet(args.config)
    for cfg in vehicle_configs(fleet):  # every vehicle's config and link refused before anything opens
        link_settings(cfg.mavlink)
    if not fleet.model.is_file():
        raise ConfigError(f"model file {fleet.model} not found")
    zenoh_config = load_zenoh_config(args.zenoh_config)
    setup_logging(args.verbose)
    return asyncio.run(_serve(fleet, zenoh_config))


async def _serve(fleet: Any, zenoh_config: Any) -> int:
    from koopguide.guidance.fleet import run_fleet

    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        return await run_fleet(fleet, zenoh_config, stop)
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
