"""Operator control requests on zenoh key ``koopguide/<vehicle-id>/control`` (pure, no I/O).

The dashboard (``koopguide dashboard --allow-control --control-token-file FILE``) publishes one request
per vehicle when an operator who knows the token asks for it. The guidance service that shares the
token passes each payload to a :class:`ControlInbox` (which verifies it with :func:`decode_control`
and a :class:`ReplayGuard`), acts on what it accepts, and publishes ``ControlInbox.ack`` in its status
as ``control_ack`` (see docs/dashboard.md, "Control").

One request is one compact UTF-8 JSON object:

``action``      str    ``"hold"`` (zero velocity, state ``hold``) or ``"resume"`` (guide again)
``vehicle_id``  str    the vehicle it is for; equal to the key's ``<vehicle-id>`` segment
``t``           float  unix wall time when it was made [s]
``nonce``       str    32 lowercase hex digits, random per request (replay protection)
``source``      str    who asked, free text up to 64 characters (e.g. ``"dashboard@host"``)
``mac``         str    64 lowercase hex digits: HMAC-SHA256, key = the token's UTF-8 bytes, message =
                       the UTF-8 JSON of the five keys above, sorted, separators ``,`` and ``:``

The token itself is never sent. A request is accepted only if its MAC matches, it is for this vehicle,
``|now - t| <= max_age_s`` (default 10 s) and its nonce was not seen within that window.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import math
import secrets
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from koopguide.bus.status import validate_vehicle_id

#: The actions a request may carry.
ACTIONS: tuple[str, ...] = ("hold", "resume")
#: Requests older or newer than this (vs the receiver's clock) are refused [s].
MAX_AGE_S = 10.0
#: The shortest token accepted (characters).
MIN_TOKEN_CHARS = 16
_SIGNED = ("action", "vehicle_id", "t", "nonce", "source")


class ControlError(ValueError):
    """A control request that is malformed, forged, stale or replayed; the message says which."""


@dataclass(frozen=True)
class ControlRequest:
    """One verified request; ``t`` unix time [s]."""

    action: str
    vehicle_id: str
    t: float
    nonce: str
    source: str


def control_key(vehicle_id: str) -> str:
    """``koopguide/<vehicle-id>/control``."""
    return f"koopguide/{validate_vehicle_id(vehicle_id)}/control"


def check_token(token: str) -> str:
    """Return ``token`` (surrounding whitespace removed) if it is long enough to be a secret."""
    token = token.strip()
    if len(token) < MIN_TOKEN_CHARS:
        raise ValueError(f"control token must be at least {MIN_TOKEN_CHARS} characters, got {len(token)}")
    return token


def encode_control(action: str, vehicle_id: str, token: str, now: float, source: str = "dashboard") -> bytes:
    """A signed request, ready to put on :func:`control_key` ``(vehicle_id)``."""
    if action not in ACTIONS:
        raise ControlError(f"control action must be one of {', '.join(ACTIONS)}, got {action!r}")
    validate_vehicle_id(vehicle_id)
    body = {
        "action": action,
        "vehicle_id": vehicle_id,
        "t": float(now),
        "nonce": secrets.token_hex(16),
        "source": source[:64],
    }
    body["mac"] = _mac(token, body)
    return json.dumps(body, separators=(",", ":"), allow_nan=False).encode("utf-8")


def decode_control(
    payload: bytes, token: str, vehicle_id: str, now: float, max_age_s: float = MAX_AGE_S
) -> ControlRequest:
    """Parse and verify one request for ``vehicle_id``; raise :class:`ControlError` naming the fault."""
    try:
        body = json.loads(bytes(payload).decode("utf-8"), parse_constant=_refuse_constant)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ControlError(f"control request is not UTF-8 JSON: {exc}") from None
    if not isinstance(body, dict):
        raise ControlError(f"control request must be a JSON object, got {type(body).__name__}")
    missing = [k for k in (*_SIGNED, "mac") if k not in body]
    if missing:
        raise ControlError(f"control request is missing {', '.join(missing)}")
    mac = body["mac"]
    if not isinstance(mac, str) or not hmac.compare_digest(mac, _mac(token, body)):
        raise ControlError("control request has a wrong MAC (not signed with this token)")
    if body["action"] not in ACTIONS:
        raise ControlError(f"control action must be one of {', '.join(ACTIONS)}, got {body['action']!r}")
    if body["vehicle_id"] != vehicle_id:
        raise ControlError(f"control request is for {body['vehicle_id']!r}, not {vehicle_id!r}")
    t = body["t"]
    if isinstance(t, bool) or not isinstance(t, int | float) or not math.isfinite(t):
        raise ControlError(f"control request 't' must be a finite number, got {t!r}")
    if abs(now - t) > max_age_s:
        raise ControlError(f"control request is {now - t:+.1f} s old (limit +-{max_age_s:g} s)")
    nonce, source = body["nonce"], body["source"]
    if not isinstance(nonce, str) or len(nonce) != 32 or any(c not in "0123456789abcdef" for c in nonce):
        raise ControlError(f"control request 'nonce' must be 32 hex digits, got {nonce!r}")
    if not isinstance(source, str):
        raise ControlError(f"control request 'source' must be a string, got {source!r}")
    return ControlRequest(body["action"], vehicle_id, float(t), nonce, source[:64])


class ReplayGuard:
    """Nonces seen within the last ``max_age_s`` [s]: a request seen twice is refused the second time."""

    def __init__(self, max_age_s: float = MAX_AGE_S) -> None:
        self.max_age_s = max_age_s
        self._seen: dict[str, float] = {}

    def admit(self, request: ControlRequest, now: float) -> ControlRequest:
        self._seen = {n: t for n, t in self._seen.items() if now - t <= 2 * self.max_age_s}
        if request.nonce in self._seen:
            raise ControlError(f"control request {request.nonce} was already received (replay)")
        self._seen[request.nonce] = request.t
        return request


class ControlInbox:
    """The service's side, pure: feed it each payload received on :func:`control_key` and publish
    :attr:`ack` in the status as ``control_ack``; act on the requests :meth:`receive` returns.

    ``ack`` is ``{"nonce", "action", "accepted", "reason"}`` for the latest payload (``nonce`` and
    ``action`` null when the payload did not carry them), or None before any.
    """

    def __init__(self, vehicle_id: str, token: str, max_age_s: float = MAX_AGE_S) -> None:
        self.vehicle_id = validate_vehicle_id(vehicle_id)
        self.token = check_token(token)
        self.max_age_s = max_age_s
        self.guard = ReplayGuard(max_age_s)
        self.ack: dict[str, Any] | None = None
        self.refused = 0

    def receive(self, payload: bytes, now: float) -> ControlRequest | None:
        """The verified request, or None (refused: counted, and the reason put in :attr:`ack`)."""
        try:
            request = self.guard.admit(decode_control(payload, self.token, self.vehicle_id, now, self.max_age_s), now)
        except ControlError as exc:
            self.refused += 1
            nonce, action = _peek(payload)
            self.ack = {"nonce": nonce, "action": action, "accepted": False, "reason": str(exc)}
            return None
        self.ack = {"nonce": request.nonce, "action": request.action, "accepted": True, "reason": None}
        return request


def _peek(payload: bytes) -> tuple[str | None, str | None]:
    """``nonce`` and ``action`` of an unverified payload, if it has them as short strings."""
    try:
        body = json.loads(bytes(payload).decode("utf-8"), parse_constant=_refuse_constant)
    except (UnicodeDecodeError, ValueError):
        return None, None
    if not isinstance(body, dict):
        return None, None
    nonce, action = body.get("nonce"), body.get("action")
    return (nonce if isinstance(nonce, str) and len(nonce) <= 64 else None, action if action in ACTIONS else None)


def _refuse_constant(name: str) -> None:
    raise ControlError(f"control request contains {name}, which is not a finite number")


def _mac(token: str, body: Mapping[str, Any]) -> str:
    signed = json.dumps({k: body[k] for k in _SIGNED}, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hmac.new(token.encode("utf-8"), signed.encode("utf-8"), hashlib.sha256).hexdigest()
