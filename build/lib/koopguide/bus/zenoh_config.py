"""The zenoh configuration of daemons and monitors: the shipped default, or the user's JSON5 file.

The default is ``config/zenoh.json5`` (read it: it is commented). In short: peer mode, loopback only,
multicast scouting off, gossip on, timestamping on, and a well-known rendezvous port
``127.0.0.1:7447`` that every process both tries to listen on and connects to, so that any number of
processes on one host find each other with no flags. A process that cannot bind the port (another
one holds it) still starts and connects to it; connections are retried in the background.

``--zenoh-config FILE`` replaces the default entirely (no merging): the file is the whole
configuration. Errors are :class:`koopguide.base.config.ConfigError` with one line naming the file.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import zenoh

from koopguide.base.config import CONFIG_DIR, ConfigError, read_config_text

#: The shipped default configuration.
DEFAULT_ZENOH_CONFIG_FILE = CONFIG_DIR / "zenoh.json5"
#: The shipped templates with authentication and access control (docs/zenoh.md, "Trust"): the router
#: that enforces them, and its clients.
ACL_ROUTER_CONFIG_FILE = CONFIG_DIR / "zenoh-router-acl.json5"
ACL_CLIENT_CONFIG_FILE = CONFIG_DIR / "zenoh-client-auth.json5"
#: The rendezvous port of the default configuration (loopback only).
WELL_KNOWN_PORT = 7447


def load_zenoh_config(path: str | Path | None) -> zenoh.Config:
    """``path`` (a JSON5 zenoh configuration) if given, else the shipped default."""
    if path is None:
        return default_zenoh_config()
    return _read(Path(path))


def default_zenoh_config(port: int = WELL_KNOWN_PORT, file: Path = DEFAULT_ZENOH_CONFIG_FILE) -> zenoh.Config:
    """The shipped default (or another shipped ``file``); ``port`` moves its rendezvous port (a separate
    group, e.g. for tests)."""
    if isinstance(port, bool) or not isinstance(port, int) or not 1 <= port <= 65535:
        raise ValueError(f"zenoh rendezvous port must be an integer in 1..65535, got {port!r}")
    cfg = _read(file)
    if port != WELL_KNOWN_PORT:
        for key in ("listen/endpoints", "connect/endpoints"):
            endpoints = json.loads(cfg.get_json(key))
            if isinstance(endpoints, dict):  # not set in the file: zenoh's per-mode defaults, no 7447 in them
                continue
            if not isinstance(endpoints, list):
                raise ConfigError(f"{file}: {key} must be a list, got {endpoints!r}")
            moved = [_with_port(endpoint, port) for endpoint in endpoints]
            cfg.insert_json5(key, json.dumps(moved))
    return cfg


def _with_port(endpoint: str, port: int) -> str:
    suffix = f":{WELL_KNOWN_PORT}"
    return endpoint[: -len(suffix)] + f":{port}" if endpoint.endswith(suffix) else endpoint


def _read(path: Path) -> zenoh.Config:
    text = read_config_text(path, "zenoh configuration")
    if not text.strip():
        raise ConfigError(f"{path}: zenoh configuration file is empty (write {{}} for zenoh's own defaults)")
    try:
        return zenoh.Config.from_json5(text)
    except zenoh.ZError as exc:
        raise ConfigError(f"{path}: invalid zenoh configuration: {zenoh_error_text(exc)}") from None


_RUST_LOCATION = re.compile(r"\s+at\s+\S+\.rs:\d+\.?\s*$")
_JSON5_POSITION = re.compile(r"-->\s*(\d+):(\d+)")
_SERDE_MESSAGE = re.compile(r'msg:\s*"(.*?)",\s*location:\s*Some\(Location\s*\{\s*line:\s*(\d+),\s*column:\s*(\d+)')


def zenoh_error_text(exc: BaseException) -> str:
    """A zenoh error as one readable line (no Rust source locations, no multi-line carets)."""
    text = _RUST_LOCATION.sub("", str(exc).strip())
    serde = _SERDE_MESSAGE.search(text)
    if serde:
        return f"line {serde.group(2)} column {serde.group(3)}: {serde.group(1)}"
    position = _JSON5_POSITION.search(text)
    if position:
        reason = text.rsplit("=", 1)[-1].strip() if "=" in text else "syntax error"
        return f"line {position.group(1)} column {position.group(2)}: {reason}"
    return " ".join(text.split())
