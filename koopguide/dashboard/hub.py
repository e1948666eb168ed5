"""The dashboard's zenoh side: every vehicle's status and trail, each vehicle's field as streamlines.

* statuses and liveliness arrive in zenoh ring channels (no Python callbacks on zenoh threads) and
  :meth:`FleetHub.poll` drains them on the event loop into a :class:`koopguide.bus.monitor.MonitorState`
  (which decodes each payload with ``decode_status`` and counts malformed ones);
* each vehicle keeps a bounded trail of its last :data:`TRAIL_POINTS` positions;
* the field is asked once per (vehicle id, model file) with ``koopguide/<id>/field?n=`` :data:`FIELD_N`
  (a bounded query, at most :data:`FIELD_CACHE` fields kept, at most one query in flight per vehicle, a
  failed query retried after :data:`FIELD_RETRY_S`), on a worker thread, and turned into streamlines
  there (``streamlines.py``), so the event loop never waits for zenoh or numpy.

Positions are local NED metres ``[N, E]``; times are unix wall time [s] on this host's clock.
"""

from __future__ import annotations

import asyncio
import collections
import json
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import zenoh

from koopguide.bus import control
from koopguide.bus.monitor import (
    MonitorState,
    VehicleView,
    open_watch,
    vehicle_id_of,
)
from koopguide.bus.streamlines import FieldGrid, streamlines

log = logging.getLogger(__name__)

#: Positions kept per vehicle for its trail (at 5 Hz: 2 minutes).
TRAIL_POINTS = 600
#: Grid points per axis asked of the field queryable (the service allows 2 .. 200).
FIELD_N = 30
#: Fields kept (one per vehicle id and model); the oldest is forgotten beyond this.
FIELD_CACHE = 32
#: Seconds before a failed field query is tried again.
FIELD_RETRY_S = 5.0
#: Seconds a field query waits for its reply.
FIELD_TIMEOUT_S = 3.0


@dataclass
class FieldEntry:
    """The field of one (vehicle, model): ``lines`` NED [m] once ready, else the last error."""

    vehicle_id: str
    model: str
    lines: list[list[list[float]]] | None = None
    corners_ned: list[list[float]] | None = None
    goal_ned: list[float] | None = None
    arrival_radius_m: float | None = None
    error: str | None = None
    failed_at: float = 0.0
    pending: bool = False
    queries: int = 0

    def message(self) -> dict[str, Any]:
        return {
            "type": "field",
            "vehicle_id": self.vehicle_id,
            "model": self.model,
            "streamlines": self.lines,
            "corners_ned": self.corners_ned,
            "goal_ned": self.goal_ned,
            "arrival_radius_m": self.arrival_radius_m,
        }


@dataclass
class FleetHub:
    """One zenoh session watching every vehicle. Build with :meth:`open`; :meth:`close` at the end."""

    session: zenoh.Session
    statuses: Any
    liveliness: Any
    state: MonitorState = field(default_factory=MonitorState)
    trails: dict[str, collections.deque] = field(default_factory=dict)
    #: Statuses whose ``seq`` did not grow, per vehicle: the service restarted, or another peer publishes
    #: on its key (zenoh does not authenticate publishers; see issue 11 on access control).
    seq_regressions: dict[str, int] = field(default_factory=dict)
    fields: collections.OrderedDict[tuple[str, str], FieldEntry] = field(default_factory=collections.OrderedDict)

    @classmethod
    def open(cls, zenoh_config: zenoh.Config) -> FleetHub:
        """Open the session and subscribe; a session zenoh refuses to open is a ConfigError."""
        return cls(*open_watch(zenoh_config))

    def close(self) -> None:
        try:
            for subscriber in (self.liveliness, self.statuses):
                try:
                    subscriber.undeclare()
                except zenoh.ZError:
                    continue  # the session is closing anyway
        finally:
            self.session.close()

    # ------------------------------------------------------------------------------- statuses
    def poll(self, now: float | None = None) -> list[str]:
        """Apply every waiting sample; return the ids of vehicles with news (new status or liveliness)."""
        now = time.time() if now is None else now
        changed: list[str] = []
        while (sample := self.liveliness.try_recv()) is not None:
            key = str(sample.key_expr)
            self.state.on_liveliness(key, sample.kind == zenoh.SampleKind.PUT)
            changed.append(vehicle_id_of(key))
        while (sample := self.statuses.try_recv()) is not None:
            if sample.kind != zenoh.SampleKind.PUT:
                continue
            key = str(sample.key_expr)
            before = self.state.malformed
            previous = self.state.vehicles.get(vehicle_id_of(key))
            last_seq = previous.status["seq"] if previous is not None and previous.status else None
            self.state.on_status(key, sample.payload.to_bytes(), now)
            view = self.state.vehicles.get(vehicle_id_of(key))
            if view is None or self.state.malformed != before:
                continue
            if last_seq is not None and view.status["seq"] <= last_seq:  # a restart, or a second publisher
                self.seq_regressions[view.vehicle_id] = self.seq_regressions.get(view.vehicle_id, 0) + 1
            position = view.status["position_ned"] if view.status else None
            if position is not None:
                trail = self.trails.setdefault(view.vehicle_id, collections.deque(maxlen=TRAIL_POINTS))
                trail.append([round(position[0], 4), round(position[1], 4)])
            changed.append(view.vehicle_id)
        return list(dict.fromkeys(changed))

    def vehicle_message(self, vehicle_id: str, with_trail: bool = False) -> dict[str, Any]:
        view: VehicleView = self.state.vehicle(vehicle_id)
        out: dict[str, Any] = {
            "vehicle_id": vehicle_id,
            "alive": view.alive,
            "status": view.status,
            "received_at": view.received_at,
            "statuses": view.statuses,
            "malformed": view.malformed,
            "last_error": view.last_error,
            "seq_regressions": self.seq_regressions.get(vehicle_id, 0),
        }
        if with_trail:
            out["trail"] = list(self.trails.get(vehicle_id, ()))
        return out

    def snapshot(self) -> list[dict[str, Any]]:
        return [self.vehicle_message(vid, with_trail=True) for vid in sorted(self.state.vehicles)]

    # --------------------------------------------------------------------------------- fields
    def fields_due(self, now: float) -> list[FieldEntry]:
        """Entries to query now: a vehicle (with a status) whose (id, model) has no field yet."""
        due = []
        pending_ids = {e.vehicle_id for e in self.fields.values() if e.pending}
        for view in self.state.vehicles.values():
            if view.status is None or view.alive is False or view.vehicle_id in pending_ids:
                continue
            key = (view.vehicle_id, view.status["model"])
            entry = self.fields.get(key)
            if entry is None:
                entry = self.fields[key] = FieldEntry(*key)
                while len(self.fields) > FIELD_CACHE:
                    self.fields.popitem(last=False)
            if entry.lines is None and not entry.pending and now - entry.failed_at >= FIELD_RETRY_S:
                entry.pending = True
                due.append(entry)
        return due

    def ready_fields(self) -> list[dict[str, Any]]:
        """The newest ready field of each vehicle, as messages for a client."""
        newest: dict[str, FieldEntry] = {}
        for entry in self.fields.values():
            if entry.lines is not None:
                newest[entry.vehicle_id] = entry
        return [e.message() for e in newest.values()]

    def fetch_field(self, entry: FieldEntry) -> None:
        """Blocking (run on a worker thread): ask the field once, compute its streamlines into ``entry``."""
        entry.queries += 1
        selector = f"koopguide/{entry.vehicle_id}/field?n={FIELD_N}"
        try:
            replies = list(self.session.get(selector, timeout=FIELD_TIMEOUT_S))
            good = [r.ok for r in replies if r.ok is not None]
            if not good:
                errors = [r.err.payload.to_string() for r in replies if r.err is not None]
                raise ValueError(f"no field reply on {selector}" + (f": {errors[0]}" if errors else ""))
            grid = FieldGrid.from_reply(json.loads(good[0].payload.to_string()))
            lines = streamlines(grid)
        except (ValueError, zenoh.ZError) as exc:
            entry.error, entry.failed_at = str(exc), time.monotonic()
            entry.pending = False
            log.warning("field of %s (%s): %s; retrying in %g s", entry.vehicle_id, entry.model, exc, FIELD_RETRY_S)
            return
        entry.corners_ned = grid.corners_ned.round(4).tolist()
        entry.goal_ned = None if grid.goal_ned is None else grid.goal_ned.round(4).tolist()
        entry.arrival_radius_m = self._arrival_radius(entry.vehicle_id)
        entry.error = None
        entry.lines = [[[round(float(v), 4) for v in p] for p in line] for line in lines]  # last: now it is ready
        entry.pending = False

    def _arrival_radius(self, vehicle_id: str) -> float | None:
        """``arrival.radius_m`` from the vehicle's config queryable [m]; None when it does not say."""
        try:
            for reply in self.session.get(f"koopguide/{vehicle_id}/config", timeout=FIELD_TIMEOUT_S):
                if reply.ok is not None:
                    radius = json.loads(reply.ok.payload.to_string())["config"]["arrival"]["radius_m"]
                    if isinstance(radius, int | float) and not isinstance(radius, bool) and 0 <= radius < 1e6:
                        return float(radius)
        except (ValueError, KeyError, TypeError, zenoh.ZError) as exc:
            log.warning("config of %s: no arrival radius (%s)", vehicle_id, exc)
        return None

    # -------------------------------------------------------------------------------- control
    def send_control(self, action: str, vehicle_ids: list[str], token: str, source: str) -> dict[str, str]:
        """Blocking: one signed request per vehicle on ``koopguide/<id>/control``; returns id -> nonce."""
        nonces = {}
        for vehicle_id in vehicle_ids:
            payload = control.encode_control(action, vehicle_id, token, time.time(), source)
            self.session.put(control.control_key(vehicle_id), payload, encoding=zenoh.Encoding.APPLICATION_JSON)
            nonces[vehicle_id] = json.loads(payload)["nonce"]
        return nonces


async def run_fields(hub: FleetHub, on_ready: Callable[[FieldEntry], None]) -> None:
    """Forever: start the field queries that are due, each on a worker thread; report the ready ones."""
    running: set[asyncio.Task[None]] = set()

    async def fetch(entry: FieldEntry) -> None:
        await asyncio.to_thread(hub.fetch_field, entry)
        if entry.lines is not None:
            on_ready(entry)

    try:
        while True:
            for entry in hub.fields_due(time.monotonic()):
                task = asyncio.create_task(fetch(entry))
                running.add(task)
                task.add_done_callback(running.discard)
            await asyncio.sleep(0.2)
    finally:
        for task in list(running):
            task.cancel()
        await asyncio.gather(*running, return_exceptions=True)
