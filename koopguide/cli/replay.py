"""``koopguide replay FILE.mcap -o mission.gif``: render a mission log (``koopguide run --log``)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="render a mission log (.mcap) over its field as an animated GIF")
    p.add_argument("log", type=Path, metavar="FILE.mcap", help="a mission log (koopguide run --log)")
    p.add_argument("-o", "--out", type=Path, required=True, metavar="OUT.gif", help="the animated GIF to write")
    p.add_argument("--fps", type=int, default=10, help="frames per second of the GIF (1 .. 50)")
    p.add_argument("--speed", type=float, default=5.0, help="vehicle seconds per GIF second (> 0)")
    p.set_defaults(run=cmd_replay)


def cmd_replay(args: argparse.Namespace) -> int:
    if not 1 <= args.fps <= 50:
        raise ValueError(f"--fps must be 1 .. 50, got {args.fps}")
    if not (math.isfinite(args.speed) and args.speed > 0):
        raise ValueError(f"--speed must be a positive number of vehicle seconds per second, got {args.speed:g}")
    if args.out.suffix.lower() != ".gif":
        raise ValueError(f"-o must name a .gif file, got {args.out}")
    from koopguide.bus.missionlog import read_mission
    from koopguide.dashboard.replay import render_replay

    record = read_mission(args.log)
    frames = render_replay(record, args.out, fps=args.fps, speed=args.speed)
    print(f"koopguide replay: wrote {args.out} ({frames} frames)")
    return 0
