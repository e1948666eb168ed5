"""What a :class:`koopguide.mavlink.link.Link` is opened with: endpoint, own ids, trust and peer limits."""

from __future__ import annotations

from dataclasses import dataclass

from koopguide.mavlink.endpoint import Endpoint
from koopguide.mavlink.signing import SigningKey


@dataclass(frozen=True)
class LinkSettings:
    endpoint: Endpoint
    sources: tuple[tuple[int, int], ...]  # our own (system, component) ids; one encoder each
    vehicle: tuple[int, int] | None = None  # accept only this (system, component), pin to its address
    signing_key: SigningKey | None = None  # MAVLink 2 signing: sign all, accept only signed
    link_id: int = 0  # the signing link id of what we send [0 .. 255]
    max_peers: int = 8  # listening without ``vehicle``: answer at most this many recent peers [-]
    max_parsers: int = 64  # per-source parsers kept (least recently heard dropped) [-]
    repin_after_s: float = 3.0  # pinned vehicle silent this long: a new address may take over [s]
    reconnect_min_s: float = 0.5  # stream reopen back-off: first wait [s]
    reconnect_max_s: float = 8.0  # ... doubling up to this [s]
    retry_first_open: bool = True  # a stream endpoint that cannot open at start keeps trying (else raises)

    def __post_init__(self) -> None:
        checks = [
            (len(self.sources) >= 1 and all(len(ids) == 2 and all(0 <= i <= 255 for i in ids) for ids in self.sources),
             "sources", self.sources, "one or more (system, component) pairs of 0 .. 255"),
            (0 <= self.link_id <= 255, "link_id", self.link_id, "0 .. 255"),
            (self.max_peers >= 1, "max_peers", self.max_peers, ">= 1"),
            (self.max_parsers >= 1, "max_parsers", self.max_parsers, ">= 1"),
            (self.repin_after_s > 0, "repin_after_s", self.repin_after_s, "> 0"),
            (0 < self.reconnect_min_s <= self.reconnect_max_s, "reconnect_min_s", self.reconnect_min_s,
             f"> 0 and <= reconnect_max_s ({self.reconnect_max_s})"),
        ]  # fmt: skip
        for ok, name, value, want in checks:
            if not ok:
                raise ValueError(f"MAVLink link {name}: {value!r} is not {want}")
