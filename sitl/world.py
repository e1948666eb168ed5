"""The tank: a rectangle in local NED whose walls stop a boat.

A boat's hull is kept inside the walls by a margin of half its length (a disc of that radius, so the
heading does not matter). A boat pressing on a wall keeps its velocity along the wall and loses the
part into it; each new contact is an event, reported by the caller (STATUSTEXT and log). A contact
ends when the boat is WALL_RELEASE_M clear of the walls, so a boat jostled along a wall is one event.
"""

from __future__ import annotations

from dataclasses import dataclass

from sitl.config import WorldConfig

WALL_RELEASE_M = 0.05  # distance from the walls that ends a contact [m]


@dataclass(frozen=True)
class WallContact:
    """The walls a boat touches after a step, e.g. ('north',) or ('north', 'east')."""

    walls: tuple[str, ...]
    north_m: float  # clamped position [m]
    east_m: float  # clamped position [m]


class Tank:
    def __init__(self, cfg: WorldConfig, margin_m: float):
        self.enabled = cfg.walls
        self.n_min = cfg.north_m[0] + margin_m
        self.n_max = cfg.north_m[1] - margin_m
        self.e_min = cfg.east_m[0] + margin_m
        self.e_max = cfg.east_m[1] - margin_m
        if self.enabled and (self.n_min >= self.n_max or self.e_min >= self.e_max):
            raise ValueError(
                f"world: tank {cfg.north_m} x {cfg.east_m} m is too small for a hull margin of {margin_m} m"
            )

    def contains(self, n: float, e: float, inset_m: float = 0.0) -> bool:
        """True if (n, e) [m] is inside the walls by at least inset_m [m] (always, without walls)."""
        return not self.enabled or (
            self.n_min + inset_m <= n <= self.n_max - inset_m and self.e_min + inset_m <= e <= self.e_max - inset_m
        )

    def confine(
        self, n: float, e: float, vn: float, ve: float
    ) -> tuple[float, float, float, float, WallContact | None]:
        """Clamp position (n, e) [m] inside the walls and cancel the velocity (vn, ve) [m/s] into them."""
        if self.contains(n, e):
            return n, e, vn, ve, None
        walls = []
        if n < self.n_min:
            n, vn = self.n_min, max(vn, 0.0)
            walls.append("south")
        elif n > self.n_max:
            n, vn = self.n_max, min(vn, 0.0)
            walls.append("north")
        if e < self.e_min:
            e, ve = self.e_min, max(ve, 0.0)
            walls.append("west")
        elif e > self.e_max:
            e, ve = self.e_max, min(ve, 0.0)
            walls.append("east")
        return n, e, vn, ve, WallContact(tuple(walls), n, e)
