"""The guidance side of the CLI: ``run`` (the service) and ``demo`` (a whole simulated mission).

Flags override ``config/guidance.yaml`` and a ``--config`` file; everything - model, config, zenoh
config, endpoint - is checked before the first byte goes to the vehicle.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import signal
from pathlib import Path
from typing import Any

from koopguide.config import ConfigError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="steer a vehicle along a learned field over MAVLink (the guidance service)")
    p.add_argument("--model", required=True, type=Path, help="trained model file (.pt)")
    p.add_argument("--mavlink", metavar="ENDPOINT", help="udp:HOST:PORT (listen), udpout:, tcp:, tcpin: or DEVICE,BAUD")
    p.add_argument("--signing-key", metavar="FILE", type=Path,
                   help="MAVLink 2 signing key: 32 raw bytes or 64 hex characters (docs/mavlink.md)")
    add_guidance_flags(p)
    p.set_defaults(run=cmd_run)

    p = sub.add_parser("demo", help="train Zshape if needed, simulate a boat in a current, guide it home, plot")
    p.add_argument("--out", type=Path, default=Path("out"), help="folder for the model cache and the plot")
    p.add_argument("--speedup", type=float, default=10.0, help="simulated seconds per wall second")
    p.add_argument("--start", type=int, default=0, help="which Zshape demonstration to start from (0-6)")
    p.add_argument("--current-mps", type=float, default=0.03,
                   help="speed of the current toward the north, across the field's final leg")
    p.add_argument("--zenoh-config", type=Path, help="zenoh config (JSON5) replacing the loopback default")
    p.add_argument("--timeout-s", type=float, default=120.0, help="simulated seconds allowed to arrive")
    p.set_defaults(run=cmd_demo)


def add_guidance_flags(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, help="YAML overriding config/guidance.yaml")
    p.add_argument("--vehicle-id", help="name on zenoh: koopguide/<id>/status")
    p.add_argument("--goal-ned", metavar="N,E", type=pair, help="where the model's goal lands in local NED [m]")
    p.add_argument("--goal-latlon", metavar="LAT,LON", type=pair, help="a geodetic goal instead [deg]")
    p.add_argument("--scale", type=float, help="metres per model unit")
    p.add_argument("--heading-deg", type=float, help="compass heading of the model's +x axis")
    p.add_argument("--max-speed", type=float, help="the field's top speed maps to this [m/s]")
    p.add_argument("--arm", action="store_true", default=None, help="arm the vehicle after switching to GUIDED")
    p.add_argument("--zenoh-config", type=Path, help="zenoh config (JSON5) replacing the loopback default")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")


def pair(text: str) -> tuple[float, float]:
    parts = text.split(",")
    try:
        values = tuple(float(v) for v in parts)
    except ValueError:
        values = ()
    if len(values) != 2:
        raise argparse.ArgumentTypeError(f"expected two numbers as A,B, got {text!r}")
    return values  # type: ignore[return-value]


def overrides_from(args: argparse.Namespace) -> dict[str, Any]:
    """The flags given, as a nested mapping over config/guidance.yaml."""
    out: dict[str, Any] = {}
    frame: dict[str, Any] = {}
    if getattr(args, "mavlink", None):
        out["mavlink"] = {"endpoint": args.mavlink}
    if getattr(args, "signing_key", None) is not None:
        out.setdefault("mavlink", {})["signing_key"] = str(args.signing_key)
    if args.vehicle_id is not None:
        out["vehicle_id"] = args.vehicle_id
    if args.arm:
        out["arm"] = True
    if args.goal_ned is not None:
        frame["goal_ned"] = list(args.goal_ned)
    if args.goal_latlon is not None:
        frame["goal_latlon"] = list(args.goal_latlon)
    if args.scale is not None:
        frame["scale"] = args.scale
    if args.heading_deg is not None:
        frame["heading_deg"] = args.heading_deg
    if frame:
        out["frame"] = frame
    if args.max_speed is not None:
        out["command"] = {"max_speed_mps": args.max_speed}
    return out


def setup_logging(verbose: bool) -> None:
    logging.basicConfig(level=logging.DEBUG if verbose else logging.INFO,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")


def cmd_run(args: argparse.Namespace) -> int:
    from koopguide.guidance import settings
    from koopguide.guidance.link import link_settings
    from koopguide.guidance.zenoh_config import load_zenoh_config

    cfg = settings.load(args.config, overrides_from(args))
    link_settings(cfg.mavlink)  # a bad endpoint or signing key is refused with the config's other errors
    if not args.model.is_file():
        raise ConfigError(f"model file {args.model} not found")
    zenoh_config = load_zenoh_config(args.zenoh_config)
    setup_logging(args.verbose)
    return asyncio.run(serve(cfg, args.model, zenoh_config))


async def serve(cfg: Any, model: Path, zenoh_config: Any) -> int:
    """Run the daemon until SIGINT/SIGTERM; exit code 0 after a clean shutdown."""
    from koopguide.guidance.daemon import GuidanceDaemon

    daemon = await GuidanceDaemon.create(cfg, model, zenoh_config)
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, daemon.stop)
    try:
        await daemon.run()
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    from koopguide.guidance.mission import run_demo

    return run_demo(args)
