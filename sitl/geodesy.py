"""Local NED <-> geodetic coordinates about a configured origin (flat-earth, fine for a tank or lake).

Conventions: (N, E) in metres from the origin; latitude/longitude in degrees, WGS-84 mean radius.
"""

from __future__ import annotations

import math

from sitl.config import OriginConfig

EARTH_RADIUS_M = 6_371_008.8  # mean radius [m]


def ned_to_geodetic(n: float, e: float, origin: OriginConfig) -> tuple[float, float]:
    """(latitude, longitude) [deg] of the point (n, e) [m] in the origin's local NED frame."""
    lat = origin.latitude_deg + math.degrees(n / EARTH_RADIUS_M)
    lon = origin.longitude_deg + math.degrees(
        e / (EARTH_RADIUS_M * math.cos(math.radians(origin.latitude_deg)))
    )
    return lat, lon


def geodetic_to_ned(lat: float, lon: float, origin: OriginConfig) -> tuple[float, float]:
    """(N, E) [m] of (lat, lon) [deg] in the origin's local NED frame."""
    n = math.radians(lat - origin.latitude_deg) * EARTH_RADIUS_M
    e = (
        math.radians(lon - origin.longitude_deg)
        * EARTH_RADIUS_M
        * math.cos(math.radians(origin.latitude_deg))
    )
    return n, e
