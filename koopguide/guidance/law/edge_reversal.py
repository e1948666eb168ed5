"""Reversing before the area's edge: a boat that needs way, on the line toward its goal, goes astern (or ahead
again) before it leaves the area it may use (the model's domain and the geofence), where a tank's walls or the
shore may be, and keeps the new way for ``EDGE_LEG_M``: a boat that went the other way again as soon as that no
longer led out shuttled a few centimetres each way in the area's corner for a minute, its bow never turning (every
reversal holds the heading, law/line_approach.py). Pure math.

Conventions: positions ``(2,)`` local NED [m], ``outside(points)`` how far points lie outside the area [m] (0
inside), ground speeds [m/s].
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

EDGE_LOOK_S = 1.5  # reverse when the point this long ahead at the present speed (or EDGE_MIN_M) leaves the area
EDGE_MIN_M = 0.15  # [m]
EDGE_SLANT = math.sin(math.radians(20.0))  # ... "leaves" when at least this fraction of the look goes outward
EDGE_LEG_M = 0.3  # after a reversal at the edge the boat keeps its new way this far (the bow turns on the way) [m]


class EdgeReversal:
    """Call :meth:`way` each tick with the way the guidance wants; :meth:`reset` with a new approach."""

    def __init__(self) -> None:
        self.leg: tuple[np.ndarray, bool] | None = None  # where a reversal at the edge began [m], and its way

    def reset(self) -> None:
        self.leg = None

    def way(
        self,
        p: np.ndarray,
        bow: np.ndarray,
        speed_mps: float,
        astern: bool,
        outside: Callable[[np.ndarray], float],
    ) -> bool:
        """Whether the boat at ``p`` [m] with unit bow vector ``bow`` and ground speed ``speed_mps`` goes astern,
        given that the guidance wants it astern (``astern``) or not."""
        look = max(EDGE_MIN_M, EDGE_LOOK_S * speed_mps)
        here = outside(p)

        def leads_out(astern: bool) -> bool:  # heading out, more than along the edge
            sign = -1.0 if astern else 1.0
            onward, back = outside(p + sign * look * bow), outside(p - sign * look * bow)
            return onward > here + EDGE_SLANT * look and back < onward

        if self.leg is not None:  # a leg away from the edge goes on for EDGE_LEG_M (the bow turns on it)
            start, leg_astern = self.leg
            if float(np.hypot(*(p - start))) < EDGE_LEG_M and not leads_out(leg_astern):
                return leg_astern
            self.leg = None
        if leads_out(astern):
            self.leg = (p.copy(), not astern)
            return not astern
        return astern
