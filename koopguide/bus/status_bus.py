"""A daemon's zenoh presence: status publisher, liveliness token and two queryables, one session.

Keys for vehicle ``<id>`` (docs/zenoh.md):

``koopguide/<id>/status``   publisher; one JSON status per :meth:`StatusBus.publish` (schema: ``status``)
``koopguide/<id>/alive``    liveliness token, present while the bus is open
``koopguide/<id>/field``    queryable; the selector's parameters (``?n=30``) go to ``sample_field`` as a
                            dict of strings; it answers JSON bytes (awaited: the service computes them in
                            a worker process); a ValueError it raises becomes an error reply
``koopguide/<id>/config``   queryable; the reply is ``config_snapshot()`` as JSON
``koopguide/<id>/control``  subscriber (when ``on_control`` is given): each payload goes to
                            ``on_control(payload)`` on the event loop (operator requests, bus.control)
``koopguide/*/status``      subscribed only with ``listen_to_others``: the other vehicles' statuses (fleets),
                            drained with :meth:`StatusBus.take_others`

Zenoh is optional for guidance: if the session cannot be opened or an entity cannot be declared,
:meth:`StatusBus.create` logs one warning and returns a disabled bus whose :meth:`publish` does
nothing. A failing put is logged once per outage, never per cycle.

Threads: no Python callback is handed to zenoh (a callback left declared keeps a thread alive and
hangs the process at exit). Queries and control requests arrive in zenoh ring channels and a task on
the event loop drains them every :data:`QUERY_POLL_S`. ``config_snapshot`` is cheap and runs on the
event loop; ``sample_field`` is awaited, one query at a time, and does its heavy work off the loop (the
service's :mod:`koopguide.guidance.field_grid`), so a field query never holds up the control loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

import zenoh

from koopguide.bus.control import control_key
from koopguide.bus.status import StatusFormatError, decode_status, encode_status, validate_vehicle_id
from koopguide.bus.zenoh_config import load_zenoh_config, zenoh_error_text

__all__ = ["QUERY_POLL_S", "StatusBus", "StatusKeys", "load_zenoh_config"]

logger = logging.getLogger("koopguide.bus.status_bus")

#: Key prefix of everything koopguide publishes.
APP = "koopguide"
#: How often the event loop looks for queries [s]: the added latency of a field or config query.
QUERY_POLL_S = 0.02
#: Queries waiting beyond this many per queryable are dropped, oldest first (the asker sees no reply).
QUERY_BACKLOG = 16
#: Other vehicles' statuses waiting beyond this many are dropped, oldest first.
OTHERS_BACKLOG = 64

SampleField = Callable[[dict[str, str]], Awaitable[bytes]]
ConfigSnapshot = Callable[[], dict]
OnControl = Callable[[bytes], None]


@dataclass(frozen=True)
class StatusKeys:
    """The four key expressions of one vehicle."""

    status: str
    alive: str
    field: str
    config: str

    @classmethod
    def for_vehicle(cls, vehicle_id: str) -> StatusKeys:
        validate_vehicle_id(vehicle_id)
        return cls(*(f"{APP}/{vehicle_id}/{name}" for name in ("status", "alive", "field", "config")))


@dataclass
class _Declared:
    session: zenoh.Session
    publisher: zenoh.Publisher
    token: zenoh.LivelinessToken
    field_queryable: zenoh.Queryable
    config_queryable: zenoh.Queryable
    control: zenoh.Subscriber | None = None
    others: zenoh.Subscriber | None = None  # koopguide/*/status, in a ring channel


class StatusBus:
    """One zenoh session for one vehicle id. Build with :meth:`create`; close with :meth:`close`."""

    def __init__(
        self,
        vehicle_id: str,
        declared: _Declared | None,
        sample_field: SampleField,
        config_snapshot: ConfigSnapshot,
        on_control: OnControl | None = None,
    ) -> None:
        self.vehicle_id = vehicle_id
        self.keys = StatusKeys.for_vehicle(vehicle_id)
        self._declared = declared
        self._sample_field = sample_field
        self._config_snapshot = config_snapshot
        self._on_control = on_control
        self._query_task: asyncio.Task[None] | None = None
        self._put_failing = False
        #: Puts that raised since the bus opened (each outage is logged once).
        self.put_failures = 0

    # ------------------------------------------------------------------------------- lifecycle
    @classmethod
    async def create(
        cls,
        vehicle_id: str,
        zenoh_config: zenoh.Config,
        sample_field: SampleField,
        config_snapshot: ConfigSnapshot,
        on_control: OnControl | None = None,
        listen_to_others: bool = False,
    ) -> StatusBus:
        """Open the session off the event loop and declare everything; disabled (not raised) on failure.
        ``listen_to_others``: also subscribe to every vehicle's status (read with :meth:`take_others`).

        A malformed ``vehicle_id`` is the caller's error and raises ValueError.
        """
        keys = StatusKeys.for_vehicle(vehicle_id)
        control = control_key(vehicle_id) if on_control is not None else None
        opening = asyncio.ensure_future(
            asyncio.to_thread(_open_and_declare, zenoh_config, keys, control, listen_to_others)
        )
        try:
            declared = await asyncio.shield(opening)
        except (zenoh.ZError, OSError) as exc:
            logger.warning(
                "zenoh status for vehicle %r disabled: %s (guidance continues without status)",
                vehicle_id,
                zenoh_error_text(exc),
            )
            return cls(vehicle_id, None, sample_field, config_snapshot, on_control)
        except asyncio.CancelledError:
            opening.add_done_callback(_close_when_opened)  # the thread cannot be stopped; undo it when done
            raise
        bus = cls(vehicle_id, declared, sample_field, config_snapshot, on_control)
        bus._query_task = asyncio.create_task(bus._serve_queries(), name=f"zenoh queries {vehicle_id}")
        logger.debug("zenoh status for vehicle %r on %s", vehicle_id, keys.status)
        return bus

    @property
    def enabled(self) -> bool:
        """True while the session is open and the entities declared."""
        return self._declared is not None

    async def close(self) -> None:
        """Stop serving queries, undeclare the token (monitors see the vehicle go) and close the session."""
        declared, self._declared = self._declared, None
        task, self._query_task = self._query_task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        if declared is not None:
            await asyncio.to_thread(_undeclare_and_close, declared)

    async def __aenter__(self) -> StatusBus:
        return self

    async def __aexit__(self, *_exc: object) -> None:
        await self.close()

    # --------------------------------------------------------------------------------- publish
    def publish(self, status: dict[str, Any]) -> None:
        """Encode and put one status; never blocks. A malformed status raises StatusFormatError (a bug)."""
        declared = self._declared
        if declared is None:
            return
        payload = encode_status(status)
        try:
            declared.publisher.put(payload)
        except zenoh.ZError as exc:
            self.put_failures += 1
            if not self._put_failing:
                self._put_failing = True
                logger.warning(
                    "zenoh put on %s failed (logged once until it works again): %s",
                    self.keys.status,
                    zenoh_error_text(exc),
                )
            return
        if self._put_failing:
            self._put_failing = False
            logger.info("zenoh put on %s works again after %d failures", self.keys.status, self.put_failures)

    def take_others(self) -> list[dict[str, Any]]:
        """The other vehicles' statuses received since the last call (oldest first; own id and malformed
        payloads left out). Call on the event loop; never blocks."""
        declared = self._declared
        if declared is None or declared.others is None:
            return []
        out = []
        while (sample := declared.others.try_recv()) is not None:
            try:
                status = decode_status(sample.payload.to_bytes())
            except StatusFormatError as exc:
                logger.debug("ignoring a malformed status on %s: %s", sample.key_expr, exc)
                continue
            if status["vehicle_id"] != self.vehicle_id:
                out.append(status)
        return out

    # --------------------------------------------------------------------------------- queries
    async def _serve_queries(self) -> None:
        while (declared := self._declared) is not None:
            while (query := declared.field_queryable.try_recv()) is not None:
                await self._answer_field(query)
            while (query := declared.config_queryable.try_recv()) is not None:
                _reply_and_drop(query, self.keys.config, self._config_reply)
            if declared.control is not None and self._on_control is not None:
                while (sample := declared.control.try_recv()) is not None:
                    self._on_control(sample.payload.to_bytes())
            await asyncio.sleep(QUERY_POLL_S)

    async def _answer_field(self, query: zenoh.Query) -> None:
        try:
            try:
                payload = await self._sample_field(dict(query.parameters))
            except ValueError as exc:  # the asker's parameters are wrong: tell them
                query.reply_err(str(exc), encoding=zenoh.Encoding.TEXT_PLAIN)
                return
            except Exception as exc:  # a bug in the service's callback: answer, log, keep serving
                logger.exception("answering a query on %s failed", self.keys.field)
                query.reply_err(f"internal error: {type(exc).__name__}: {exc}", encoding=zenoh.Encoding.TEXT_PLAIN)
                return
            query.reply(self.keys.field, payload, encoding=zenoh.Encoding.APPLICATION_JSON)
        except zenoh.ZError as exc:  # the asker left, or the session is closing
            logger.debug("could not reply to a query on %s: %s", self.keys.field, zenoh_error_text(exc))
        finally:
            query.drop()  # tells the asker that no more replies follow

    def _config_reply(self, _query: zenoh.Query) -> Any:
        return self._config_snapshot()


def _reply_and_drop(query: zenoh.Query, key: str, answer: Callable[[zenoh.Query], Any]) -> None:
    try:
        _answer(query, key, answer)
    except zenoh.ZError as exc:  # the asker left, or the session is closing
        logger.debug("could not reply to a query on %s: %s", key, zenoh_error_text(exc))
    finally:
        query.drop()  # tells the asker that no more replies follow


def _answer(query: zenoh.Query, key: str, answer: Callable[[zenoh.Query], Any]) -> None:
    try:
        body = answer(query)
    except ValueError as exc:  # the asker's parameters are wrong: tell them
        query.reply_err(str(exc), encoding=zenoh.Encoding.TEXT_PLAIN)
        return
    except Exception as exc:  # a bug in the daemon's callback: answer, log, keep serving the others
        logger.exception("answering a query on %s failed", key)
        query.reply_err(f"internal error: {type(exc).__name__}: {exc}", encoding=zenoh.Encoding.TEXT_PLAIN)
        return
    try:
        payload = json.dumps(body, separators=(",", ":"), allow_nan=False)
    except (TypeError, ValueError) as exc:
        logger.error("the reply on %s is not finite JSON: %s", key, exc)
        query.reply_err(f"internal error: reply is not finite JSON: {exc}", encoding=zenoh.Encoding.TEXT_PLAIN)
        return
    query.reply(key, payload, encoding=zenoh.Encoding.APPLICATION_JSON)


# ------------------------------------------------------------------------- blocking zenoh calls
def _open_and_declare(
    zenoh_config: zenoh.Config, keys: StatusKeys, control: str | None = None, listen_to_others: bool = False
) -> _Declared:
    """Runs on a worker thread. On any failure, closes what it opened and re-raises."""
    session = zenoh.open(zenoh_config)
    try:
        ring = zenoh.handlers.RingChannel(QUERY_BACKLOG)
        others = (
            session.declare_subscriber(f"{APP}/*/status", zenoh.handlers.RingChannel(OTHERS_BACKLOG))
            if listen_to_others
            else None
        )
        return _Declared(
            session=session,
            publisher=session.declare_publisher(keys.status, encoding=zenoh.Encoding.APPLICATION_JSON),
            token=session.liveliness().declare_token(keys.alive),
            field_queryable=session.declare_queryable(keys.field, zenoh.handlers.RingChannel(QUERY_BACKLOG)),
            config_queryable=session.declare_queryable(keys.config, zenoh.handlers.RingChannel(QUERY_BACKLOG)),
            control=session.declare_subscriber(control, ring) if control is not None else None,
            others=others,
        )
    except BaseException:
        session.close()
        raise


def _undeclare_and_close(declared: _Declared) -> None:
    try:
        entities = (declared.token, declared.field_queryable, declared.config_queryable, declared.publisher)
        extra = [e for e in (declared.control, declared.others) if e is not None]
        for entity in (*entities, *extra):
            try:
                entity.undeclare()
            except zenoh.ZError as exc:
                logger.debug("undeclaring %s failed: %s", type(entity).__name__, zenoh_error_text(exc))
    finally:
        declared.session.close()


def _close_when_opened(opening: asyncio.Future[_Declared]) -> None:
    if opening.cancelled() or opening.exception() is not None:
        return
    _undeclare_and_close(opening.result())
