"""The field on a grid in NED, as the JSON the ``field`` queryable answers with, computed off the control loop.

Sampling a 200 x 200 grid and encoding it as JSON costs about 0.3 s of numpy and 0.5 s of JSON encoding
that holds Python's interpreter lock the whole time: on a thread it would still stall the event loop
that sends the setpoints. So a worker *process* (started by :meth:`FieldGrids.start` when ``koopguide
run`` starts, else at the first query; one for the service's life) loads the same model and settings
once, and each query sends it only the grid size and the current placement of the model
(:class:`~koopguide.guidance.law.frames.ModelFrame`); the encoded bytes come back and are cached per
(size, placement).
"""

from __future__ import annotations

import asyncio
import json
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from koopguide.guidance.law.command import GuidanceLaw
from koopguide.guidance.law.frames import ModelFrame
from koopguide.guidance.settings import GuidanceConfig
from koopguide.model.field import load_field

CACHE_SIZE = 4  # encoded grids kept (per size and placement)

_worker_law: GuidanceLaw | None = None  # the worker process's own copy of the service's law


def _start_worker(model_path: Path, cfg: GuidanceConfig) -> None:
    global _worker_law
    _worker_law = GuidanceLaw.from_config(load_field(model_path), cfg)


def _loaded() -> bool:
    return _worker_law is not None


def _encode(n: int, frame: ModelFrame) -> bytes:
    law = _worker_law
    if law is None:  # pragma: no cover - the pool's initializer always ran
        raise RuntimeError("field grid worker not initialised")
    law.frame = frame
    return json.dumps(law.sample_grid(n), separators=(",", ":"), allow_nan=False).encode("utf-8")


class FieldGrids:
    """Encoded field grids for one service's model; :meth:`close` ends the worker process."""

    def __init__(self, model_path: Path, cfg: GuidanceConfig) -> None:
        self._model_path, self._cfg = model_path, cfg
        self._pool: ProcessPoolExecutor | None = None
        self._cache: dict[tuple[int, ModelFrame], bytes] = {}

    async def answer(self, params: dict[str, str], default_n: int, goal_placed: bool, frame: ModelFrame) -> bytes:
        """A field query's answer: ``n`` from ``params`` (default ``default_n``) checked, then the grid; a
        ValueError (sent back to the asker) for a bad ``n`` or a geodetic goal not yet placed."""
        text = params.get("n", str(default_n))
        try:
            n = int(text)
        except ValueError:
            raise ValueError(f"field query: n must be an integer, got {text!r}") from None
        if not 2 <= n <= 200:
            raise ValueError(f"field query: n must be 2 .. 200, got {n}")
        if not goal_placed:
            raise ValueError("field query: the geodetic goal is not placed yet (no GLOBAL_POSITION_INT so far)")
        return await self.encoded(n, frame)

    async def encoded(self, n: int, frame: ModelFrame) -> bytes:
        """The grid of ``n x n`` points at placement ``frame`` as UTF-8 JSON (see docs/zenoh.md)."""
        key = (n, frame)
        if key not in self._cache:
            payload = await asyncio.get_running_loop().run_in_executor(self._worker(), _encode, n, frame)
            if len(self._cache) >= CACHE_SIZE:
                self._cache.pop(next(iter(self._cache)))
            self._cache[key] = payload
        return self._cache[key]

    def start(self) -> None:
        """Start the worker process now (it loads the model once) rather than at the first query: a dashboard
        that connects mid-mission then costs no process start-up (1-2 s of a CPU) beside the control loop.
        ``koopguide run`` calls this once started; without it the worker starts at the first query."""
        self._worker().submit(_loaded)

    def _worker(self) -> ProcessPoolExecutor:
        if self._pool is None:
            self._pool = ProcessPoolExecutor(
                1,
                mp_context=multiprocessing.get_context("spawn"),
                initializer=_start_worker,
                initargs=(self._model_path, self._cfg),
            )
        return self._pool

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
