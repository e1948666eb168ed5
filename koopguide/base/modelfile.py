"""The model file: a torch ``.pt`` archive that also reads without torch.

Writing uses ``torch.save`` on a dict of float64 tensors and plain metadata, so
``torch.load(path, weights_only=True)`` reads it. Reading at query time needs numpy only: the archive
is a zip holding ``data.pkl`` and one raw little-endian buffer per tensor; :func:`read` unpickles it
with an allow-list (tensors, ordered dicts, nothing else), the same safety as ``weights_only``.

Layout of the saved dict::

    {"format": "koopguide-field", "format_version": 1,
     "weights": {"W": (nu, d), "b": (nu,), "A": (nu + d, r), "B": (nu + d, r),   # float64 tensors
                 "limit_table": (n_1, ..., n_d)},                                 # optional (version 2)
     "meta": {"dim", "goal", "substeps", "goal_centred", "nu", "rank", "bounds_lo", "bounds_hi",
              "hyperparameters", "data", "train",
              "limit": {"lo", "hi", "outside"}, "certificate": {...}}}                # optional (version 2)
"""

from __future__ import annotations

import collections
import io
import math
import pickle
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

FORMAT = "koopguide-field"
FORMAT_VERSION = 2  # 2: optional Lyapunov limit (weights.limit_table, meta.limit) and certificate


class ModelFileError(ValueError):
    """A model file that cannot be used: missing, corrupt, truncated, wrong kind or newer format."""


def write(path: str | Path, weights: dict[str, np.ndarray], meta: dict[str, Any]) -> None:
    """Save weights (float64) and metadata with ``torch.save`` (torch is a training dependency)."""
    import torch

    payload = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "weights": {k: torch.from_numpy(np.ascontiguousarray(v, dtype=np.float64)) for k, v in weights.items()},
        "meta": meta,
    }
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    torch.save(payload, tmp)
    tmp.replace(path)  # never leave a half-written model under the final name


def read(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Load ``(weights, meta)`` with numpy only; every failure is a :class:`ModelFileError`."""
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"{path}: model file not found")
    try:
        archive = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as exc:
        raise ModelFileError(f"{path}: not a koopguide model file (not a torch zip archive: {exc})") from None
    with archive:
        names = archive.namelist()
        pkl = [n for n in names if n.endswith("/data.pkl") or n == "data.pkl"]
        if len(pkl) != 1:
            raise ModelFileError(f"{path}: not a torch archive (no data.pkl among {len(names)} entries)")
        prefix = pkl[0][: -len("data.pkl")]
        byteorder = prefix + "byteorder"
        if byteorder in names and archive.read(byteorder).strip() not in (b"little", b""):
            raise ModelFileError(f"{path}: big-endian tensors are not supported")
        try:
            payload = _Unpickler(io.BytesIO(archive.read(pkl[0])), archive, prefix).load()
        except ModelFileError as exc:
            raise ModelFileError(f"{path}: {exc}") from None
        except (
            pickle.UnpicklingError,
            EOFError,
            KeyError,
            ValueError,
            TypeError,
            zipfile.BadZipFile,
            AttributeError,
            IndexError,
            OSError,
        ) as exc:
            raise ModelFileError(f"{path}: corrupt or truncated model file ({type(exc).__name__}: {exc})") from None
    return _validate(path, payload)


def _validate(path: Path, payload: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        kind = payload.get("format") if isinstance(payload, dict) else type(payload).__name__
        raise ModelFileError(f"{path}: wrong kind of file: format {kind!r}, expected {FORMAT!r}")
    version = payload.get("format_version")
    if not isinstance(version, int):
        raise ModelFileError(f"{path}: format_version missing or not an integer: {version!r}")
    if version > FORMAT_VERSION:
        raise ModelFileError(
            f"{path}: model format version {version} is newer than this koopguide reads ({FORMAT_VERSION}); "
            "upgrade koopguide"
        )
    weights, meta = payload.get("weights"), payload.get("meta")
    if not isinstance(weights, dict) or not isinstance(meta, dict):
        raise ModelFileError(f"{path}: 'weights' and 'meta' must both be mappings")
    missing = [k for k in ("W", "b", "A", "B") if k not in weights]
    missing += [k for k in ("dim", "goal", "substeps", "goal_centred", "nu", "rank") if k not in meta]
    if missing:
        raise ModelFileError(f"{path}: missing entries {missing}")
    d, nu, r = meta["dim"], meta["nu"], meta["rank"]
    for name, value, top in (("dim", d, 16), ("nu", nu, 1 << 16), ("rank", r, 1 << 12)):
        if not _is_count(value) or not 1 <= value <= top:
            raise ModelFileError(f"{path}: {name} must be an integer in [1, {top}], got {value!r}")
    if d < 2:
        raise ModelFileError(f"{path}: dim must be >= 2, got {d}")
    want = {"W": (nu, d), "b": (nu,), "A": (nu + d, r), "B": (nu + d, r)}
    for name, shape in want.items():
        arr = weights[name]
        if not isinstance(arr, np.ndarray) or arr.shape != shape:
            seen = getattr(arr, "shape", type(arr).__name__)
            raise ModelFileError(
                f"{path}: weight {name} has shape {seen}, expected {shape} for dim={d} nu={nu} rank={r}"
            )
        if arr.dtype.kind != "f":
            raise ModelFileError(f"{path}: weight {name} has dtype {arr.dtype}, expected floating point")
        if not np.all(np.isfinite(arr)):
            raise ModelFileError(f"{path}: weight {name} holds non-finite values")
    meta["goal"] = _finite_vector(path, "goal", meta["goal"], d)
    if "bounds_lo" in meta or "bounds_hi" in meta:
        lo = _finite_vector(path, "bounds_lo", meta.get("bounds_lo"), d)
        hi = _finite_vector(path, "bounds_hi", meta.get("bounds_hi"), d)
        if not np.all(np.asarray(lo) < np.asarray(hi)):
            raise ModelFileError(f"{path}: bounds must satisfy lo < hi in every coordinate, got lo={lo} hi={hi}")
        meta["bounds_lo"], meta["bounds_hi"] = lo, hi
    if not _is_count(meta["substeps"]) or not 1 <= meta["substeps"] <= 1_000_000:
        raise ModelFileError(f"{path}: substeps must be an integer in [1, 1000000], got {meta['substeps']!r}")
    if not isinstance(meta["goal_centred"], bool):
        raise ModelFileError(f"{path}: goal_centred must be true or false, got {meta['goal_centred']!r}")
    if "limit_table" in weights or "limit" in meta:
        _validate_limit(path, weights.get("limit_table"), meta.get("limit"), d)
    if "certificate" in meta and not isinstance(meta["certificate"], dict):
        raise ModelFileError(f"{path}: certificate must be a mapping, got {type(meta['certificate']).__name__}")
    return weights, meta


def _validate_limit(path: Path, table: Any, spec: Any, d: int) -> None:
    """The Lyapunov limit: a finite d-D ratio table of 2..4096 nodes per axis over a box with lo < hi."""
    if not isinstance(table, np.ndarray) or not isinstance(spec, dict):
        raise ModelFileError(f"{path}: a Lyapunov limit needs both weights.limit_table and meta.limit")
    if table.ndim != d or min(table.shape) < 2 or max(table.shape) > 4096 or table.dtype.kind != "f":
        raise ModelFileError(
            f"{path}: limit_table has shape {table.shape} and dtype {table.dtype}, expected a "
            f"{d}-D float grid of 2..4096 nodes per axis"
        )
    if not np.all(np.isfinite(table)) or np.min(table) < 0:
        raise ModelFileError(f"{path}: limit_table holds non-finite or negative ratios")
    lo = _finite_vector(path, "limit.lo", spec.get("lo"), d)
    hi = _finite_vector(path, "limit.hi", spec.get("hi"), d)
    if not np.all(np.asarray(lo) < np.asarray(hi)):
        raise ModelFileError(f"{path}: limit box must satisfy lo < hi in every coordinate, got lo={lo} hi={hi}")
    outside = spec.get("outside")
    if isinstance(outside, bool) or not isinstance(outside, int | float) or not 0 < outside < 1:
        raise ModelFileError(f"{path}: limit.outside must be a number in (0, 1), got {outside!r}")
    spec["lo"], spec["hi"] = lo, hi


def _finite_vector(path: Path, name: str, value: Any, dim: int) -> list[float]:
    """``value`` as ``dim`` finite floats (a list), or a ModelFileError naming the entry and values seen."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ModelFileError(f"{path}: {name} is not a list of numbers: {value!r}") from None
    if arr.shape != (dim,):
        raise ModelFileError(f"{path}: {name} has shape {arr.shape}, expected ({dim},)")
    if not np.all(np.isfinite(arr)):
        raise ModelFileError(f"{path}: {name} holds non-finite values {arr.tolist()}")
    return arr.tolist()


_DTYPES = {
    "DoubleStorage": np.float64, "FloatStorage": np.float32, "HalfStorage": np.float16,
    "LongStorage": np.int64, "IntStorage": np.int32, "ShortStorage": np.int16,
    "CharStorage": np.int8, "ByteStorage": np.uint8, "BoolStorage": np.bool_,
}  # fmt: skip


class _StorageType:
    def __init__(self, dtype: type) -> None:
        self.dtype = np.dtype(dtype)


#: Largest tensor the loader builds (elements); koopguide's own weights are far below it.
MAX_TENSOR_ELEMENTS = 1 << 26
#: Largest archive entry the loader reads (bytes).
MAX_ENTRY_BYTES = 1 << 30


def _rebuild_tensor(storage: np.ndarray, offset: Any, size: Any, stride: Any, *_: Any) -> np.ndarray:
    """Mirror of torch._utils._rebuild_tensor_v2 for a flat numpy storage.

    Shape, stride and offset are checked before any array is built: non-negative integers, a dense
    or strictly positive layout (no stride 0, no negative stride), at most ``MAX_TENSOR_ELEMENTS``
    elements and no element outside the storage.
    """
    if not isinstance(size, tuple) or not isinstance(stride, tuple) or len(size) != len(stride):
        raise ModelFileError(f"tensor with malformed size {size!r} / stride {stride!r}")
    if not all(_is_count(v) for v in (offset, *size, *stride)):
        raise ModelFileError(f"tensor with invalid offset {offset!r}, size {size!r} or stride {stride!r}")
    numel = math.prod(size)
    if numel > MAX_TENSOR_ELEMENTS or numel > storage.size:
        raise ModelFileError(
            f"tensor of size {size} ({numel} elements) exceeds its storage of {storage.size} "
            f"elements or the limit of {MAX_TENSOR_ELEMENTS}"
        )
    if numel == 0:
        return np.zeros(size, dtype=storage.dtype)
    if any(s == 0 for n, s in zip(size, stride, strict=True) if n > 1):
        raise ModelFileError(f"tensor of size {size} has a zero stride {stride} (expanded tensors are not allowed)")
    if not size:
        if offset >= storage.size:
            raise ModelFileError(f"scalar tensor at offset {offset} overruns its storage of {storage.size} elements")
        return storage[offset : offset + 1].reshape(()).copy()
    span = offset + sum((n - 1) * s for n, s in zip(size, stride, strict=True)) + 1
    if span > storage.size:
        raise ModelFileError(
            f"tensor of size {size} and stride {stride} overruns its storage of {storage.size} elements"
        )
    itemsize = storage.dtype.itemsize
    view = np.lib.stride_tricks.as_strided(
        storage[offset:], shape=size, strides=tuple(s * itemsize for s in stride), writeable=False
    )
    return np.array(view)


def _is_count(value: Any) -> bool:
    """A non-negative Python integer (not a bool)."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


class _Unpickler(pickle.Unpickler):
    """Allow-list unpickler: torch tensors become numpy arrays, nothing else is constructed."""

    def __init__(self, file: io.BytesIO, archive: zipfile.ZipFile, prefix: str) -> None:
        super().__init__(file)
        self.archive, self.prefix = archive, prefix

    def find_class(self, module: str, name: str) -> Any:
        if module == "torch._utils" and name == "_rebuild_tensor_v2":
            return _rebuild_tensor
        if module == "torch" and name in _DTYPES:
            return _StorageType(_DTYPES[name])
        if module == "collections" and name == "OrderedDict":
            return collections.OrderedDict
        raise ModelFileError(f"refusing to load {module}.{name} (not a koopguide model file)")

    def persistent_load(self, pid: Any) -> np.ndarray:
        if not (isinstance(pid, tuple) and len(pid) == 5 and pid[0] == "storage"):
            raise ModelFileError(f"unexpected persistent id {pid!r}")
        _, storage_type, key, _location, numel = pid
        if not isinstance(storage_type, _StorageType):
            raise ModelFileError(f"unsupported storage type {storage_type!r}")
        if not isinstance(key, str) or not _is_count(numel):
            raise ModelFileError(f"malformed storage reference {pid!r}")
        dtype = storage_type.dtype.newbyteorder("<")
        entry = f"{self.prefix}data/{key}"
        size = self.archive.getinfo(entry).file_size
        if size > MAX_ENTRY_BYTES or numel * dtype.itemsize > MAX_ENTRY_BYTES:
            raise ModelFileError(f"tensor storage {key} of {size} bytes exceeds the limit of {MAX_ENTRY_BYTES}")
        raw = self.archive.read(entry)
        if len(raw) != numel * dtype.itemsize:
            raise ModelFileError(f"tensor storage {key} holds {len(raw)} bytes, expected {numel * dtype.itemsize}")
        return np.frombuffer(raw, dtype=dtype)
