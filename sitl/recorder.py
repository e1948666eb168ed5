"""Ground-truth recording: one JSON object per line, for plots and tests.

Record kinds (field "kind"):
  "state":      t [s], sysid, n, e [m], psi [rad], u, v [m/s over ground, body], u_r, v_r [m/s relative
                to the water, body], r [rad/s], vn, ve [m/s over ground, NED], flow [V_N, V_E] at the boat
                [m/s], thrust [port, stbd] [N], command [port, stbd] in [-1, 1], mode, armed,
                target (the guided target or null), desired_heading [rad or null], desired_speed [m/s]
  "statustext": t, sysid, severity, text
  "wall":       t, sysid, walls, n, e
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import IO, Any

from sitl.boat import Boat, WallEvent
from sitl.vessel import body_velocity


def state_record(boat: Boat) -> dict[str, Any]:
    x = boat.state
    ap = boat.autopilot
    vc_n, vc_e = boat.flow_here()
    u, v = body_velocity(x, vc_n, vc_e)
    truth = boat.truth()
    target = None
    if ap.target is not None:
        target = {k: (val.value if hasattr(val, "value") else val) for k, val in dataclasses.asdict(ap.target).items()}
    return {
        "kind": "state",
        "t": round(boat.t, 9),
        "sysid": boat.sysid,
        "vehicle": boat.params.kind.value,
        "n": x[0],
        "e": x[1],
        "psi": x[2],
        "u": u,
        "v": v,
        "u_r": x[3],
        "v_r": x[4],
        "r": x[5],
        "vn": truth.vn,
        "ve": truth.ve,
        "flow": [vc_n, vc_e],
        "thrust": list(boat.thrusts()),
        "command": list(ap.commands),
        "mode": ap.mode_name,
        "armed": ap.armed,
        "target": target,
        "desired_heading": ap.control.desired_heading,
        "desired_speed": ap.control.desired_speed,
    }


class Recorder:
    """Writes records to a JSON-lines file and/or appends them to a list (in-process users)."""

    def __init__(self, path: Path | None = None, records: list[dict[str, Any]] | None = None):
        self.records = records
        self._file: IO[str] | None = None
        if path is not None:
            try:
                self._file = open(path, "w", encoding="utf-8")  # noqa: SIM115 - closed in close()
            except OSError as exc:
                raise ValueError(f"recorder.path {path}: cannot open for writing ({exc.strerror})") from None

    @property
    def active(self) -> bool:
        return self._file is not None or self.records is not None

    def write(self, record: dict[str, Any]) -> None:
        if self.records is not None:
            self.records.append(record)
        if self._file is not None:
            self._file.write(json.dumps(record, separators=(",", ":")) + "\n")

    def state(self, boat: Boat) -> None:
        self.write(state_record(boat))

    def statustext(self, t: float, sysid: int, severity: int, text: str) -> None:
        self.write({"kind": "statustext", "t": round(t, 9), "sysid": sysid, "severity": severity, "text": text})

    def wall(self, event: WallEvent) -> None:
        c = event.contact
        self.write(
            {
                "kind": "wall",
                "t": round(event.t, 9),
                "sysid": event.sysid,
                "walls": list(c.walls),
                "n": c.north_m,
                "e": c.east_m,
            }
        )

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
