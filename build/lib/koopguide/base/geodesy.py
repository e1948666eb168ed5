"""Local NED <-> geodetic coordinates about an origin (flat earth: fine for a tank, a harbour or a lake).

Conventions: (N, E) in metres from the origin; latitude/longitude in degrees; WGS-84 mean radius.
Shared by the guidance service (geodetic goals) and the simulator (GLOBAL_POSITION_INT).
"""

from __future__ import annotations

import math

EARTH_RADIUS_M = 6_371_008.8  # mean radius [m]


def ned_to_geodetic(n: float, e: float, lat0: float, lon0: float) -> tuple[float, float]:
    """(latitude, longitude) [deg] of the point (n, e) [m] in the local NED frame at (lat0, lon0) [deg]."""
    lat = lat0 + math.degrees(n / EARTH_RADIUS_M)
    lon = lon0 + math.degrees(e / (EARTH_RADIUS_M * math.cos(math.radians(lat0))))
    return lat, lon


def geodetic_to_ned(lat: float, lon: float, lat0: float, lon0: float) -> tuple[float, float]:
    """(N, E) [m] of (lat, lon) [deg] in the local NED frame at (lat0, lon0) [deg]."""
    n = math.radians(lat - lat0) * EARTH_RADIUS_M
    e = math.radians(lon - lon0) * EARTH_RADIUS_M * math.cos(math.radians(lat0))
    return n, e
