"""``koopguide dashboard``: serve the live web page of every guidance service's status over zenoh.

Read-only by default. ``--allow-control --control-token-file FILE`` adds the operator's hold/resume
buttons; the page asks for the token, and each request goes out signed with it (``control.py``).
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("dashboard", help="live web map of every vehicle over its field (zenoh)")
    p.add_argument(
        "--zenoh-config",
        type=Path,
        metavar="FILE",
        help="zenoh configuration (JSON5) replacing the default config/zenoh.json5",
    )
    p.add_argument(
        "--listen",
        default="127.0.0.1:8080",
        metavar="IP:PORT",
        help="address to serve on (default 127.0.0.1:8080; port 0 picks a free one)",
    )
    p.add_argument(
        "--allow-control",
        action="store_true",
        help="offer the operator's hold/resume actions (needs --control-token-file)",
    )
    p.add_argument(
        "--control-token-file",
        type=Path,
        metavar="FILE",
        help="file holding the control token shared with the guidance services (>= 16 characters)",
    )
    p.set_defaults(run=cmd_dashboard)


def cmd_dashboard(args: argparse.Namespace) -> int:
    from koopguide.base.config import read_config_text
    from koopguide.bus import control
    from koopguide.bus.zenoh_config import load_zenoh_config
    from koopguide.dashboard.server import Listen, serve

    listen = Listen.parse(args.listen)
    token = None
    if args.allow_control:
        if args.control_token_file is None:
            raise ValueError("--allow-control needs --control-token-file FILE (the token the services share)")
        token = control.check_token(read_config_text(args.control_token_file, "control token"))
    elif args.control_token_file is not None:
        raise ValueError("--control-token-file is only used with --allow-control")
    zenoh_config = load_zenoh_config(args.zenoh_config)
    logging.basicConfig(level=logging.INFO, format="koopguide dashboard: %(message)s", stream=sys.stderr)
    if not listen.loopback:
        logging.warning("serving on %s, not loopback: anyone who reaches it sees every vehicle", listen.host)
    return asyncio.run(serve(zenoh_config, listen, token, print_url=lambda line: print(line, flush=True)))
