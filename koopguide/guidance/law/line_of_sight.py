"""Line-of-sight steering onto a straight line (pure math).

Fossen (2021), "Handbook of Marine Craft Hydrodynamics and Motion Control", 2nd ed., section 12.4.2: the
lookahead-based LOS law ``chi_d = chi_p - atan(y_e / Delta)`` aims the course at the point ``Delta`` further
along the line, from the boat's offset ``y_e`` across it. Here the line is given by its unit axis ``a`` and right
normal ``n``, the way along it by ``travel`` (+1 along ``a``, -1 against it), and a boat going astern points its
bow opposite the course (law/line_approach.py).

Conventions: unit vectors ``(2,)`` NED, offsets [m] (``cross``: to the right of the axis), headings [rad] from north.
"""

from __future__ import annotations

import math

import numpy as np

from koopguide.guidance.law.maneuver import wrap_pi


def los_course(travel: float, delta: float, a: np.ndarray, n: np.ndarray, cross: float) -> np.ndarray:
    """The LOS course for ``travel`` (+1 along the axis ``a``, -1 against it), a unit NED vector: toward the point
    ``delta`` [m] along the line from a boat ``cross`` [m] to the right of it."""
    aim = delta * travel * a - cross * n
    return aim / float(np.hypot(*aim))


def los_heading(travel: float, delta: float, a: np.ndarray, n: np.ndarray, cross: float) -> float:
    """The LOS heading for ``travel`` [rad]: the bow along the course ahead (+1), or opposite it astern (-1)."""
    c = los_course(travel, delta, a, n, cross)
    course = math.atan2(c[1], c[0])
    return course if travel > 0 else wrap_pi(course + math.pi)
