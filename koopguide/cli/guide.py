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

from koopguide.base.config import ConfigError
from koopguide.base.flags import Flag, add_flags, number_pair, overrides_from
from koopguide.mavlink.signing import SIGNING_KEY_FLAG

#: Flags of ``koopguide run`` that set keys of config/guidance.yaml.
GUIDANCE_FLAGS: tuple[Flag, ...] = (
    Flag(
        "--mavlink",
        "mavlink.endpoint",
        str,
        "udp:HOST:PORT (listen), udpout:, tcp:, tcpin: or DEVICE,BAUD",
        metavar="ENDPOINT",
    ),
    SIGNING_KEY_FLAG,
    Flag("--vehicle-id", "vehicle_id", str, "name on zenoh: koopguide/<id>/status"),
    Flag("--goal-ned", "frame.goal_ned", number_pair, "where the model's goal lands in local NED [m]", metavar="N,E"),
    Flag("--goal-latlon", "frame.goal_latlon", number_pair, "a geodetic goal instead [deg]", metavar="LAT,LON"),
    Flag("--scale", "frame.scale", float, "metres per model unit"),
    Flag("--heading-deg", "frame.heading_deg", float, "compass heading of the model's +x axis"),
    Flag("--max-speed", "command.max_speed_mps", float, "the field's top speed maps to this [m/s]"),
    Flag("--arm", "arm", None, "arm the vehicle after switching to GUIDED"),
    Flag(
        "--control-token-file",
        "status.control_token_file",
        str,
        "token shared with koopguide dashboard: obey its operator hold (docs/dashboard.md)",
        metavar="FILE",
    ),
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="steer a vehicle along a learned field over MAVLink (the guidance service)")
    p.add_argument("--model", required=True, type=Path, help="trained model file (.pt)")
    p.add_argument("--config", type=Path, help="YAML overriding config/guidance.yaml")
    add_flags(p, GUIDANCE_FLAGS)
    p.add_argument("--zenoh-config", type=Path, help="zenoh config (JSON5) replacing the loopback default")
    p.add_argument(
        "--log",
        type=Path,
        metavar="FILE.mcap",
        help="record fixes, estimates, setpoints, states and "
        "statuses as MCAP (render: koopguide replay FILE.mcap -o mission.gif)",
    )
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    p.set_defaults(run=cmd_run)

    p = sub.add_parser("demo", help="train Zshape if needed, simulate a boat in a current, guide it home, plot")
    p.add_argument("--out", type=Path, default=Path("out"), help="folder for the model cache and the plot")
    p.add_argument("--speedup", type=float, default=10.0, help="simulated seconds per wall second")
    p.add_argument("--start", type=int, default=0, help="which Zshape demonstration to start from (0-6)")
    p.add_argument(
        "--current-mps",
        type=float,
        default=0.03,
        help="speed of the current toward the north, across the field's final leg",
    )
    p.add_argument("--zenoh-config", type=Path, help="zenoh config (JSON5) replacing the loopback default")
    p.add_argument("--timeout-s", type=float, default=120.0, help="simulated seconds allowed to arrive")
    p.add_argument(
        "--fleet",
        type=int,
        metavar="N",
        help="instead: N = 2 boats on Multi_Models_4 from both "
        "demonstration starts, to rendezvous slots, keeping their separation (docs/fleet.md)",
    )
    p.set_defaults(run=cmd_demo)


def setup_logging(verbose: bool) -> None:
    logging.basicConfig(
        level=logging.DEBUG if verbose else logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )


def cmd_run(args: argparse.Namespace) -> int:
    from koopguide.bus.zenoh_config import load_zenoh_config
    from koopguide.guidance import settings
    from koopguide.guidance.link import link_settings

    cfg = settings.load(args.config, overrides_from(args, GUIDANCE_FLAGS))
    link_settings(cfg.mavlink)  # a bad endpoint or signing key is refused with the config's other errors
    if not args.model.is_file():
        raise ConfigError(f"model file {args.model} not found")
    if args.log is not None and (args.log.suffix.lower() != ".mcap" or not args.log.parent.is_dir()):
        raise ConfigError(f"--log must name a .mcap file in an existing folder, got {args.log}")
    zenoh_config = load_zenoh_config(args.zenoh_config)
    setup_logging(args.verbose)
    return asyncio.run(serve(cfg, args.model, zenoh_config, args.log))


async def serve(cfg: Any, model: Path, zenoh_config: Any, log_path: Path | None = None) -> int:
    """Run the daemon until SIGINT/SIGTERM; exit code 0 after a clean shutdown."""
    from koopguide.guidance.daemon import GuidanceDaemon
    from koopguide.guidance.latency import settle_heap

    daemon = await GuidanceDaemon.create(cfg, model, zenoh_config, log_path)
    if daemon.bus is not None and daemon.bus.enabled:
        daemon.field_grids.start()  # the field-query worker now, not mid-mission at a dashboard's first query
    settle_heap()  # no full garbage collection of the start-up objects between a fix and its setpoint
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
    if args.fleet is not None:
        from koopguide.harness.fleet_demo import run_fleet_demo

        return run_fleet_demo(args)
    from koopguide.harness.mission import run_demo

    return run_demo(args)
