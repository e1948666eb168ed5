"""VehicleClock: the vehicle's time (seconds since its boot) as seen from here, from its message stamps.

Every message carrying ``time_boot_ms`` moves the clock; between messages it runs on at the estimated
rate of vehicle seconds per wall second (1 for a real vehicle, X for a simulator at speed-up X). So the
service's command rate, staleness and prediction all hold in vehicle time, and a simulated mission at
speed-up 20 behaves like real time. A stamp far behind the clock (a reboot) restarts it.
"""

from __future__ import annotations

import time
from collections.abc import Callable

RATE_WINDOW_S = 0.5  # wall seconds of stamps per rate estimate
RATE_BOUNDS = (1e-3, 1e4)  # plausible vehicle/wall rates
REBOOT_JUMP_S = 1.0  # a stamp this far behind the clock means the vehicle restarted


class VehicleClock:
    def __init__(self, wall: Callable[[], float] = time.monotonic) -> None:
        self.wall = wall
        self.rate = 1.0  # vehicle seconds per wall second
        self._last: tuple[float, float] | None = None  # (vehicle s, wall s) of the newest stamp
        self._anchor: tuple[float, float] | None = None  # start of the current rate window
        self._now = 0.0  # latest answer of now(), kept monotonic
        self.reboots = 0

    @property
    def started(self) -> bool:
        return self._last is not None

    def observe(self, t_vehicle: float, wall: float | None = None) -> None:
        """A message stamped ``t_vehicle`` [s since vehicle boot] arrived at ``wall`` (default: now)."""
        wall = self.wall() if wall is None else wall
        if self._last is None or t_vehicle < self._last[0] - REBOOT_JUMP_S:
            if self._last is not None:
                self.reboots += 1
            self._last = self._anchor = (t_vehicle, wall)
            self._now = t_vehicle
            return
        if t_vehicle < self._last[0]:
            return  # a late, reordered message: keep the clock monotonic
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
