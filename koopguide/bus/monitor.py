"""Watching every guidance daemon's zenoh status: the state kept per vehicle, the table, the session.

Three parts, so the table can be tested without zenoh:

* :class:`MonitorState` - what is known about each vehicle, fed with raw status payloads and
  liveliness events (malformed payloads are counted, never raised). Statuses that look forged are
  flagged and not shown as the vehicle's: a second publisher for a vehicle whose publisher is still
  live, or a sequence number that does not increase (zenoh's trust model: docs/zenoh.md, "Trust");
* :func:`render_table` - that state as a plain-text table (pure);
* :class:`Monitor` - a zenoh session subscribed to ``koopguide/*/status`` and to liveliness
  ``koopguide/*/alive`` (with history, so vehicles already alive show at once). Samples wait in
  zenoh ring channels and :meth:`Monitor.poll` drains them on the caller's thread: no Python code
  runs on zenoh's threads, and nothing is left behind to hang the process at exit.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import zenoh

from koopguide.base.config import ConfigError
from koopguide.bus.status import StatusFormatError, decode_status
from koopguide.bus.zenoh_config import zenoh_error_text

STATUS_KEYS = "koopguide/*/status"
ALIVE_KEYS = "koopguide/*/alive"
#: Samples a channel holds between two polls before dropping the oldest.
CHANNEL_CAPACITY = 4096
#: A vehicle's publisher silent this long [s] may be replaced by another (a restarted service).
PUBLISHER_HANDOVER_S = 2.0


@dataclass
class VehicleView:
    """The latest known about one vehicle. Times are unix wall time [s] on this host's clock."""

    vehicle_id: str
    status: dict[str, Any] | None = None
    received_at: float | None = None  # when the last well-formed status arrived
    statuses: int = 0  # well-formed statuses received
    alive: bool | None = None  # liveliness token present; None: never seen one
    malformed: int = 0  # payloads on this vehicle's status key that broke the schema
    last_error: str | None = None
    source: str | None = None  # zenoh id of the publisher whose statuses are shown
    suspect: int = 0  # statuses that look forged: another publisher, or a sequence that does not increase
    last_suspect: str | None = None


class MonitorState:
    """Vehicles by id, updated from raw samples; ``malformed`` counts rejected payloads overall."""

    def __init__(self) -> None:
        self.vehicles: dict[str, VehicleView] = {}
        self.malformed = 0
        self.last_error: str | None = None

    def vehicle(self, vehicle_id: str) -> VehicleView:
        view = self.vehicles.get(vehicle_id)
        if view is None:
            view = self.vehicles[vehicle_id] = VehicleView(vehicle_id)
        return view

    def on_status(self, key: str, payload: bytes, now: float, source: str | None = None) -> None:
        """One payload put on ``koopguide/<id>/status`` by publisher ``source`` (its zenoh id, when known)."""
        view = self.vehicle(vehicle_id_of(key))
        try:
            status = decode_status(payload)
            if status["vehicle_id"] != view.vehicle_id:
                raise StatusFormatError(
                    f"status key 'vehicle_id' is {status['vehicle_id']!r} but it was published on {key}"
                )
        except StatusFormatError as exc:
            view.malformed += 1
            view.last_error = str(exc)
            self.malformed += 1
            self.last_error = f"{view.vehicle_id}: {exc}"
            return
        doubt = self._doubt(view, status, now, source)
        if doubt is not None:
            view.suspect += 1
            view.last_suspect = doubt
            return
        view.source = source if source is not None else view.source
        view.status = status
        view.received_at = now
        view.statuses += 1

    @staticmethod
    def _doubt(view: VehicleView, status: dict[str, Any], now: float, source: str | None) -> str | None:
        """Why this well-formed status looks forged, or None."""
        live = view.received_at is not None and now - view.received_at <= PUBLISHER_HANDOVER_S
        if source is not None and view.source is not None and source != view.source:
            if live:
                return f"a second publisher {source[:8]} for a vehicle published by {view.source[:8]}"
            return None  # the old publisher went quiet: a restarted service takes over
        previous = view.status["seq"] if view.status is not None else None
        if previous is not None and live and status["seq"] <= previous:
            return f"sequence went from {previous} to {status['seq']}"
        return None

    def on_liveliness(self, key: str, alive: bool) -> None:
        """A token ``koopguide/<id>/alive`` appeared (True) or went away (False)."""
        self.vehicle(vehicle_id_of(key)).alive = alive

    def all_alive_reported(self) -> bool:
        """At least one status arrived, and every vehicle whose token is alive has sent one."""
        views = self.vehicles.values()
        return any(v.status is not None for v in views) and all(v.status is not None for v in views if v.alive)


def publisher_of(sample: zenoh.Sample) -> str | None:
    """The publishing session's zenoh id: from the sample's source info, else its timestamp's clock id."""
    info = sample.source_info
    if info is not None and info.source_id is not None:
        return str(info.source_id)
    return str(sample.timestamp.get_id()) if sample.timestamp is not None else None


def vehicle_id_of(key: str) -> str:
    """``koopguide/<id>/status`` -> ``<id>``."""
    parts = str(key).split("/")
    return parts[1] if len(parts) >= 3 else str(key)


# ------------------------------------------------------------------------------------ table
#: Columns: position N/E, distance to goal, |commanded velocity|, age of the position the daemon used,
#: age of the last status received here, guidance loop latency percentiles, malformed payloads.
COLUMNS = (
    "VEHICLE",
    "LIVE",
    "STATE",
    "MODE",
    "ARMED",
    "N[m]",
    "E[m]",
    "TO GOAL[m]",
    "CMD[m/s]",
    "POS AGE[s]",
    "MSG AGE[s]",
    "LOOP p50/p99[ms]",
    "BAD",
    "SUSPECT",
)
_RIGHT_ALIGNED = frozenset({"N[m]", "E[m]", "TO GOAL[m]", "CMD[m/s]", "POS AGE[s]", "MSG AGE[s]", "BAD", "SUSPECT"})


def render_table(
    vehicles: dict[str, VehicleView], now: float, *, malformed: int = 0, last_error: str | None = None
) -> str:
    """The vehicles as a text table, one row each sorted by id, with a summary line above.

    ``now`` is the current unix time [s], for the age of each vehicle's last status.
    """
    alive = sum(1 for v in vehicles.values() if v.alive)
    clock = time.strftime("%H:%M:%S", time.localtime(now))
    header = f"koopguide monitor  {clock}  vehicles {len(vehicles)} (alive {alive})"
    if malformed:
        header += f"  malformed statuses {malformed}"
    lines = [header]
    if last_error and malformed:
        lines.append(f"  last malformed: {_clip(last_error, 110)}")
    for view in sorted(vehicles.values(), key=lambda v: v.vehicle_id):
        if view.last_suspect:
            lines.append(
                f"  SUSPECT {view.vehicle_id}: {view.suspect} status(es) ignored, last: {_clip(view.last_suspect, 90)}"
            )
    if not vehicles:
        lines.append("(no vehicles yet: waiting for koopguide/*/status and koopguide/*/alive)")
        return "\n".join(lines)
    rows = [_row(vehicles[vid], now) for vid in sorted(vehicles)]
    widths = [max(len(col), *(len(r[i]) for r in rows)) for i, col in enumerate(COLUMNS)]
    for cells in (COLUMNS, *rows):
        lines.append("  ".join(_pad(text, widths[i], COLUMNS[i]) for i, text in enumerate(cells)).rstrip())
    return "\n".join(lines)


def _row(view: VehicleView, now: float) -> tuple[str, ...]:
    live = {True: "alive", False: "gone", None: "?"}[view.alive]
    status_age = "-" if view.received_at is None else _num(max(0.0, now - view.received_at), 1)
    s = view.status
    if s is None:
        return (
            view.vehicle_id,
            live,
            "-",
            "-",
            "-",
            "-",
            "-",
            "-",
            "-",
            "-",
            status_age,
            "-",
            str(view.malformed),
            str(view.suspect),
        )
    position = s["position_ned"] or (None, None)
    cmd = s["cmd_velocity_ned"]
    latency = s["loop_latency_ms"]
    return (
        view.vehicle_id,
        live,
        s["state"],
        s["mode"] or "-",
        {True: "yes", False: "no", None: "-"}[s["armed"]],
        _num(position[0], 1),
        _num(position[1], 1),
        _num(s["distance_to_goal_m"], 1),
        _num(math.hypot(cmd[0], cmd[1]), 2),
        _num(s["position_age_s"], 2),
        status_age,
        f"{_num(latency['p50'], 1)}/{_num(latency['p99'], 1)}",
        str(view.malformed),
        str(view.suspect),
    )


def _num(value: float | None, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _pad(text: str, width: int, column: str) -> str:
    return text.rjust(width) if column in _RIGHT_ALIGNED else text.ljust(width)


def _clip(text: str, limit: int) -> str:
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


# ---------------------------------------------------------------------------------- session
def open_watch(zenoh_config: zenoh.Config) -> tuple[zenoh.Session, zenoh.Subscriber, zenoh.Subscriber]:
    """A session subscribed to every status and to liveliness (with history), both into ring channels.

    A session zenoh refuses to open is a ConfigError; on any failure nothing is left open."""
    try:
        session = zenoh.open(zenoh_config)
    except zenoh.ZError as exc:
        raise ConfigError(f"cannot open a zenoh session with this configuration: {zenoh_error_text(exc)}") from None
    try:
        statuses = session.declare_subscriber(STATUS_KEYS, zenoh.handlers.RingChannel(CHANNEL_CAPACITY))
        liveliness = session.liveliness().declare_subscriber(
            ALIVE_KEYS, zenoh.handlers.RingChannel(CHANNEL_CAPACITY), history=True
        )
    except BaseException:
        session.close()
        raise
    return session, statuses, liveliness


class Monitor:
    """A zenoh session watching every vehicle; call :meth:`poll` often, :meth:`close` at the end."""

    def __init__(self, session: zenoh.Session, statuses: zenoh.Subscriber, liveliness: zenoh.Subscriber) -> None:
        self.state = MonitorState()
        self.opened_at = time.monotonic()
        self._session = session
        self._statuses = statuses
        self._liveliness = liveliness

    @classmethod
    def open(cls, zenoh_config: zenoh.Config) -> Monitor:
        """Open the session and subscribe; a session zenoh refuses to open is a ConfigError."""
        return cls(*open_watch(zenoh_config))

    def poll(self, now: float | None = None) -> int:
        """Apply every sample waiting in the channels; returns how many there were."""
        now = time.time() if now is None else now
        count = 0
        while (sample := self._liveliness.try_recv()) is not None:
            self.state.on_liveliness(str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)
            count += 1
        while (sample := self._statuses.try_recv()) is not None:
            if sample.kind == zenoh.SampleKind.PUT:
                self.state.on_status(str(sample.key_expr), sample.payload.to_bytes(), now, publisher_of(sample))
            count += 1
        return count

    def table(self, now: float | None = None) -> str:
        now = time.time() if now is None else now
        return render_table(self.state.vehicles, now, malformed=self.state.malformed, last_error=self.state.last_error)

    def close(self) -> None:
        try:
            for subscriber in (self._liveliness, self._statuses):
                try:
                    subscriber.undeclare()
                except zenoh.ZError:
                    continue  # the session is closing anyway
        finally:
            self._session.close()

    def __enter__(self) -> Monitor:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()
