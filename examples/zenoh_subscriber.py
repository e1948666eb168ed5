"""Print every koopguide vehicle's state and position as its status arrives over zenoh.

Run next to one or more `koopguide run` daemons (same host, no flags needed):

    python examples/zenoh_subscriber.py              # until Ctrl-C
    python examples/zenoh_subscriber.py --duration 5 # for 5 seconds

The status schema (fields, units) is documented in koopguide/guidance/status.py.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import zenoh

from koopguide.bus.status import StatusFormatError, decode_status
from koopguide.bus.zenoh_config import load_zenoh_config

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--duration", type=float, help="stop after this many seconds (default: until Ctrl-C)")
parser.add_argument("--zenoh-config", type=Path, help="zenoh JSON5 config (default: config/zenoh.json5)")
args = parser.parse_args()

# The default config: peer mode, loopback only, no multicast, rendezvous on 127.0.0.1:7447.
end = None if args.duration is None else time.monotonic() + args.duration
with zenoh.open(load_zenoh_config(args.zenoh_config)) as session:
    # A ring channel keeps the newest samples; we read them on this thread (no zenoh callbacks).
    subscriber = session.declare_subscriber("koopguide/*/status", zenoh.handlers.RingChannel(256))
    try:
        while end is None or time.monotonic() < end:
            sample = subscriber.try_recv()
            if sample is None:
                time.sleep(0.02)
                continue
            try:
                status = decode_status(sample.payload.to_bytes())
            except StatusFormatError as exc:
                print(f"{sample.key_expr}: malformed status: {exc}")
                continue
            n_e = status["position_ned"]
            where = "no position yet" if n_e is None else f"N {n_e[0]:8.2f} m  E {n_e[1]:8.2f} m"
            print(f"{status['vehicle_id']:>12}  {status['state']:<8} {where}", flush=True)
    except KeyboardInterrupt:
        pass  # leaving the `with` block closes the session
