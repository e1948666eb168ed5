"""VehicleClock: the vehicle's time (seconds since its boot) as seen from here, from its message stamps.

Every message carrying ``time_boot_ms`` moves the clock; between messages it runs on at the estimated
rate of vehicle seconds per wall second (1 for a real vehicle, X for a simulator at speed-up X). So the
service's command rate, staleness and prediction all hold in vehicle time, and a simulated mission at
speed-up 20 behaves like real time.

A stamp is checked before it moves the clock (issue 11): one more than ``window_s`` (plus the elapsed
wall time at a generous rate) ahead of the newest stamp, or more than ``REBOOT_JUMP_S`` behind it, is
rejected - one forged or corrupt stamp (``time_boot_ms`` = 4e9) must not freeze the command schedule.
When ``confirm`` such stamps in a row agree with each other, the vehicle's clock really did restart
(a reboot: time went back) or jump: the clock restarts there and says so, so that the caller resets
its estimators and command schedule. Times: vehicle seconds; wall seconds from the injected clock.
"""

from __future__ import annotations

import enum
import time
from collections.abc import Callable

RATE_WINDOW_S = 0.5  # wall seconds of stamps per rate estimate
RATE_BOUNDS = (1e-3, 1e4)  # plausible vehicle/wall rates
REBOOT_JUMP_S = 1.0  # a stamp this far behind the newest one is not a late message but a restarted clock
AHEAD_RATE_FACTOR = 4.0  # elapsed wall time counts at this multiple of the rate (at least 1) when checking


class ClockVerdict(enum.Enum):
    FIRST = "first"  # the first stamp: the clock starts
    OK = "ok"  # in line with the clock
    LATE = "late"  # a reordered message a little older than the newest: the clock keeps its time
    AHEAD = "ahead"  # too far ahead: rejected (until confirmed)
    BEHIND = "behind"  # too far behind: rejected (until confirmed)
    REBOOT = "reboot"  # confirmed: the clock went back (the vehicle restarted); the clock restarted
    JUMP = "jump"  # confirmed: the clock jumped forward; the clock restarted


REJECTED = (ClockVerdict.AHEAD, ClockVerdict.BEHIND)
RESTARTED = (ClockVerdict.REBOOT, ClockVerdict.JUMP)


class VehicleClock:
    def __init__(self, wall: Callable[[], float] = time.monotonic, window_s: float = 5.0, confirm: int = 3) -> None:
        self.wall = wall
        self.window_s = window_s
        self.confirm = confirm
        self.rate = 1.0  # vehicle seconds per wall second
        self._last: tuple[float, float] | None = None  # (vehicle s, wall s) of the newest stamp
        self._anchor: tuple[float, float] | None = None  # start of the current rate window
        self._now = 0.0  # latest answer of now(), kept monotonic
        self._candidate: tuple[float, float, int] | None = None  # (vehicle s, wall s, count) of a rejected run
        self.reboots = 0
        self.jumps = 0

    @property
    def started(self) -> bool:
        return self._last is not None

    def observe(self, t_vehicle: float, wall: float | None = None) -> ClockVerdict:
        """A message stamped ``t_vehicle`` [s since vehicle boot] arrived at ``wall`` (default: now)."""
        wall = self.wall() if wall is None else wall
        if self._last is None:
            self._restart(t_vehicle, wall)
            return ClockVerdict.FIRST
        if self._fits(self._last, t_vehicle, wall):
            self._candidate = None
            if t_vehicle < self._last[0]:
                return ClockVerdict.LATE  # keep the clock monotonic
            self._advance(t_vehicle, wall)
            return ClockVerdict.OK
        behind = t_vehicle < self._last[0]
        candidate = self._candidate
        if candidate is not None and self._fits(candidate[:2], t_vehicle, wall) and t_vehicle >= candidate[0]:
            candidate = (t_vehicle, wall, candidate[2] + 1)
        else:
            candidate = (t_vehicle, wall, 1)
        self._candidate = candidate
        if candidate[2] < self.confirm:
            return ClockVerdict.BEHIND if behind else ClockVerdict.AHEAD
        self._restart(t_vehicle, wall)
        if behind:
            self.reboots += 1
            return ClockVerdict.REBOOT
        self.jumps += 1
        return ClockVerdict.JUMP

    def _fits(self, ref: tuple[float, float], t_vehicle: float, wall: float) -> bool:
        """Whether ``t_vehicle`` at ``wall`` is in line with the stamp ``ref`` = (vehicle s, wall s)."""
        elapsed = max(wall - ref[1], 0.0) * max(self.rate, 1.0) * AHEAD_RATE_FACTOR
        return ref[0] - REBOOT_JUMP_S <= t_vehicle <= ref[0] + self.window_s + elapsed

    def _restart(self, t_vehicle: float, wall: float) -> None:
        self._last = self._anchor = (t_vehicle, wall)
        self._now = t_vehicle
        self._candidate = None

    def _advance(self, t_vehicle: float, wall: float) -> None:
        self._last = (t_vehicle, wall)
        t0, w0 = self._anchor
        if wall - w0 >= RATE_WINDOW_S:
            rate = (t_vehicle - t0) / (wall - w0)
            self.rate = min(max(rate, RATE_BOUNDS[0]), RATE_BOUNDS[1])
            self._anchor = (t_vehicle, wall)

    def now(self) -> float:
        """The vehicle's time now [s]: the newest stamp run on at ``rate`` (0 before any stamp)."""
        if self._last is None:
            return 0.0
        t, w = self._last
        self._now = max(self._now, t + (self.wall() - w) * self.rate)
        return self._now

    def wall_seconds(self, vehicle_seconds: float) -> float:
        """How long ``vehicle_seconds`` of vehicle time take on the wall clock."""
        return vehicle_seconds / self.rate
