"""The service's side of the operator's control requests (docs/dashboard.md, "Control"), no I/O.

Payloads put on ``koopguide/<vehicle-id>/control`` reach :meth:`OperatorControl.receive` (the zenoh bus
drains them on the event loop); a verified ``hold`` or ``resume`` becomes an
:class:`~koopguide.guidance.events.OperatorHold` event for the supervisor, and :attr:`ack` is published
in every status as ``control_ack``. Without a token (``status.control_token_file`` null, the default)
control is disabled: every request is refused, counted, and acknowledged as refused.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from koopguide.base.config import ConfigError
from koopguide.bus.control import ACTIONS, ControlInbox, check_token
from koopguide.guidance.events import OperatorHold

DISABLED = "control is disabled on this service (no status.control_token_file / --control-token-file)"


def load_token(path: Path) -> str:
    """The shared token in ``path`` (surrounding whitespace removed); ConfigError naming the file."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"status.control_token_file: {path} not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"status.control_token_file: {path} cannot be read ({exc})") from None
    try:
        return check_token(text)
    except ValueError as exc:
        raise ConfigError(f"status.control_token_file: {path}: {exc}") from None


class OperatorControl:
    """Requests for one vehicle: verified with the token (None: control disabled), turned into events."""

    def __init__(self, vehicle_id: str, token: str | None) -> None:
        self.inbox = ControlInbox(vehicle_id, token) if token is not None else None
        self._ack: dict[str, Any] | None = None  # the latest refusal while disabled
        self.ignored = 0  # requests received while control is disabled

    @property
    def enabled(self) -> bool:
        return self.inbox is not None

    @property
    def ack(self) -> dict[str, Any] | None:
        """``{"nonce", "action", "accepted", "reason"}`` for the latest request, None before any."""
        return self.inbox.ack if self.inbox is not None else self._ack

    @property
    def refused(self) -> int:
        """Requests refused so far (wrong MAC, stale, replayed, malformed, or control disabled)."""
        return self.inbox.refused if self.inbox is not None else self.ignored

    def receive(self, payload: bytes, unix_now: float, wall_s: float) -> OperatorHold | None:
        """The event for a verified request, or None (refused; the reason is in :attr:`ack`).
        ``unix_now`` is the host's wall time [s] (requests carry it), ``wall_s`` the service clock [s]."""
        if self.inbox is None:
            self.ignored += 1
            nonce, action = _named(payload)
            self._ack = {"nonce": nonce, "action": action, "accepted": False, "reason": DISABLED}
            return None
        request = self.inbox.receive(payload, unix_now)
        if request is None:
            return None
        return OperatorHold(wall_s, request.action == "hold", request.source.replace("\n", " ") or "unnamed")


def _named(payload: bytes) -> tuple[str | None, str | None]:
    """The ``nonce`` (32 hex digits) and ``action`` an unverified request names, so that the asker can
    match the refusal; None for what it lacks."""
    try:
        body = json.loads(bytes(payload).decode("utf-8"))
    except (UnicodeDecodeError, ValueError):
        return None, None
    if not isinstance(body, dict):
        return None, None
    nonce, action = body.get("nonce"), body.get("action")
    ok = isinstance(nonce, str) and re.fullmatch(r"[0-9a-f]{32}", nonce) is not None
    return (nonce if ok else None), (action if action in ACTIONS else None)
