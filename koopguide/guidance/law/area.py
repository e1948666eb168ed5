"""The area a boat may manoeuvre in: the model's domain with room to turn, and the geofence (pure math).

The service knows neither a tank's walls nor a shore; what it knows is where its model holds (the
demonstrations' box grown by ``command.domain_margin``) and, when one is configured, the geofence. A boat that
needs room to turn (law/line_approach.py, law/approach_path.py) keeps to the domain grown by
``command.turning_room_m`` and to the geofence. The room is there because the demonstrations end at the goal, so
the goal lies at the edge of their box (Zshape: 0.175 m inside the domain's east edge and 0.32 m inside its
south edge), where a boat that turns on a circle of 1-2 m cannot line up on a current's line within the domain.

Conventions: points ``(K, 2)`` local NED [m]; the domain in model units, placed by a
:class:`~koopguide.guidance.law.frames.ModelFrame`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from koopguide.guidance.law.frames import ModelFrame

Fence = tuple[tuple[float, float], tuple[float, float]] | None  # ((N_min, N_max), (E_min, E_max)) [m]
EDGE_INSET_M = 0.05  # a boat this close to the area's edge (a tank's wall, a bank) may be set, stopped or turned [m]
OFF_EDGE_S = 4.0  # a current that carries a boat at the edge clear of it within this long: no wall holds it there [s]


def outside_area(
    P: np.ndarray, frame: ModelFrame, lo: np.ndarray, hi: np.ndarray, fence: Fence, room_m: float = 0.0
) -> np.ndarray:
    """How far each point of ``P`` ``(K, 2)`` [m] lies outside the domain [lo, hi] (model units, placed by
    ``frame``) grown by ``room_m`` [m] (round at its corners), or outside the geofence [m]; 0 inside both."""
    P = np.atleast_2d(np.asarray(P, dtype=float))
    X = frame.to_model(P)
    excess = np.maximum(lo - X, 0.0) + np.maximum(X - hi, 0.0)
    out = np.maximum(np.hypot(excess[:, 0], excess[:, 1]) * frame.scale - room_m, 0.0)
    if fence is not None:
        f_lo, f_hi = np.array([f[0] for f in fence]), np.array([f[1] for f in fence])
        fence_excess = np.maximum(f_lo - P, 0.0) + np.maximum(P - f_hi, 0.0)
        out = np.maximum(out, np.hypot(fence_excess[:, 0], fence_excess[:, 1]))
    return out


def at_edge(outside: Callable[[np.ndarray], np.ndarray], p_ned: np.ndarray) -> bool:
    """Whether ``p_ned`` ``(2,)`` [m] lies within ``EDGE_INSET_M`` of the area's edge, or beyond it (it, or a point
    that far north, south, east or west of it, is outside). ``outside``: how far points ``(K, 2)`` lie outside the
    area [m], e.g. :func:`outside_area` placed. A boat set onto a tank's wall there (or a bank) slides along it: its
    slip is not the current's, and read as such it took the estimate 0.1 m/s off, whose innovations on the next
    headings then read as sheared water (a rudder boat in a uniform current then held a still-water line across it
    and never arrived: the default campaign's rudder start 2 toward the east, stop 30)."""
    steps = EDGE_INSET_M * np.array([[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    return float(np.max(outside(np.asarray(p_ned, dtype=float) + steps))) > 0.0


def off_edge(outside: Callable[[np.ndarray], np.ndarray], p_ned: np.ndarray, current_ned: np.ndarray | None) -> bool:
    """Whether the current ``current_ned`` [m/s] (None: none known) carries a boat at ``p_ned`` [m] clear of the
    area's edge (:func:`at_edge`) within ``OFF_EDGE_S``: then no wall there can hold it at rest. A kinematic rudder
    boat that holds its ground at speed 0, held on its line 0.6 m upstream of the goal just beyond the area's edge,
    learned nothing there of how speed 0 holds it and was sent 0 for 40 s (the CI's flight toward N, stop 52)."""
    if current_ned is None:
        return False
    return not at_edge(outside, np.asarray(p_ned, dtype=float) + OFF_EDGE_S * np.asarray(current_ned, dtype=float))
