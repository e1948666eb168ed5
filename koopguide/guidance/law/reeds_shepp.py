"""Reeds-Shepp paths: the shortest ways between two poses for a vehicle that drives ahead and astern on arcs of
radius R or straight (pure math, no I/O).

Reeds & Shepp (1990), "Optimal paths for a car that goes both forwards and backwards", Pacific J. Math.
145(2): every shortest path is one of 48 words of at most five arcs (C) and straights (S) with at most two
cusps. The formulas below (the paper's section 8: 8.1, 8.2, 8.3, 8.7, 8.8, 8.9, 8.10, 8.11) give the base words
from the normalised goal pose; the others follow by the paper's three symmetries: time flip (the same path
driven the other way round in time: lengths negated), reflection (left and right turns swapped) and
backwards (the path from the goal to the start, reversed). A boat that cannot go astern gets Dubins' paths instead
(Dubins (1957), "On curves of minimal length with a constraint on average curvature...", Am. J. Math. 79(3)): the
four words of two arcs ahead joined by a straight (CSC), each arc up to a full turn. Every candidate is checked by
driving it from the start: a word whose end misses the goal is dropped, so an error in a formula costs candidates,
never a wrong path.

Conventions (this module): the normalised frame of the start pose, x ahead, y to port (left), angles
counter-clockwise [rad], lengths in turning radii; a segment is (kind, length) with kind "L" (turn to
port), "R" (to starboard) or "S" (straight) and length signed (negative: astern). :func:`plan` works in local
NED metres with headings from north, clockwise, as the rest of the guidance does.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

Segment = tuple[str, float]  # ("L" | "R" | "S", signed length [turning radii]; negative astern)
HALF_PI = 0.5 * math.pi
ZERO = 1e-9
END_TOLERANCE = 1e-6  # a word whose end misses the goal by more than this (normalised) is dropped


def mod2pi(a: float) -> float:
    """``a`` wrapped into (-pi, pi]."""
    v = math.fmod(a, 2.0 * math.pi)
    if v < -math.pi:
        v += 2.0 * math.pi
    elif v > math.pi:
        v -= 2.0 * math.pi
    return v


def _polar(x: float, y: float) -> tuple[float, float]:
    return math.hypot(x, y), math.atan2(y, x)


def _tau_omega(u: float, v: float, xi: float, eta: float, phi: float) -> tuple[float, float]:
    delta = mod2pi(u - v)
    a = math.sin(u) - math.sin(delta)
    b = math.cos(u) - math.cos(delta) - 1.0
    t1 = math.atan2(eta * a - xi * b, xi * a + eta * b)
    t2 = 2.0 * (math.cos(delta) - math.cos(v) - math.cos(u)) + 3.0
    tau = mod2pi(t1 + math.pi) if t2 < 0 else mod2pi(t1)
    return tau, mod2pi(tau - u + v - phi)


# ---- the base words (Reeds & Shepp 1990, section 8); each returns the signed lengths or None -------------------
# (the CSC words take ``wrap``, how their arcs' angles wrap: mod2pi, or _mod_turn for Dubins' arcs of up to a turn)
def _lsl(x: float, y: float, phi: float, wrap: Callable[[float], float] = mod2pi) -> tuple[float, ...] | None:
    # 8.1: L+ S+ L+
    u, t = _polar(x - math.sin(phi), y - 1.0 + math.cos(phi))
    t = wrap(t)
    if t >= -ZERO:
        v = wrap(phi - t)
        if v >= -ZERO:
            return t, u, v
    return None


def _lsr(x: float, y: float, phi: float, wrap: Callable[[float], float] = mod2pi) -> tuple[float, ...] | None:
    # 8.2: L+ S+ R+
    u1, t1 = _polar(x + math.sin(phi), y - 1.0 - math.cos(phi))
    u1 *= u1
    if u1 < 4.0:
        return None
    u = math.sqrt(u1 - 4.0)
    t = wrap(t1 + math.atan2(2.0, u))
    v = wrap(t - phi)
    return (t, u, v) if t >= -ZERO and v >= -ZERO else None


def _lrl(x: float, y: float, phi: float) -> tuple[float, ...] | None:  # 8.3: L+ R- L
    u1, theta = _polar(x - math.sin(phi), y - 1.0 + math.cos(phi))
    if u1 > 4.0:
        return None
    u = -2.0 * math.asin(0.25 * u1)
    t = mod2pi(theta + 0.5 * u + math.pi)
    v = mod2pi(phi - t + u)
    return (t, u, v) if t >= -ZERO and u <= ZERO else None


def _lrlr_a(x: float, y: float, phi: float) -> tuple[float, ...] | None:  # 8.7: L+ R+ L- R-
    xi, eta = x + math.sin(phi), y - 1.0 - math.cos(phi)
    rho = 0.25 * (2.0 + math.hypot(xi, eta))
    if rho > 1.0:
        return None
    u = math.acos(rho)
    t, v = _tau_omega(u, -u, xi, eta, phi)
    return (t, u, -u, v) if t >= -ZERO and v <= ZERO else None


def _lrlr_b(x: float, y: float, phi: float) -> tuple[float, ...] | None:  # 8.8: L+ R- L- R+
    xi, eta = x + math.sin(phi), y - 1.0 - math.cos(phi)
    rho = (20.0 - xi * xi - eta * eta) / 16.0
    if not 0.0 <= rho <= 1.0:
        return None
    u = -math.acos(rho)
    if u < -HALF_PI:
        return None
    t, v = _tau_omega(u, u, xi, eta, phi)
    return (t, u, u, v) if t >= -ZERO and v >= -ZERO else None


def _lrsl(x: float, y: float, phi: float) -> tuple[float, ...] | None:  # 8.9: L+ R-(pi/2) S- L-
    rho, theta = _polar(x - math.sin(phi), y - 1.0 + math.cos(phi))
    if rho < 2.0:
        return None
    r = math.sqrt(rho * rho - 4.0)
    u = 2.0 - r
    t = mod2pi(theta + math.atan2(r, -2.0))
    v = mod2pi(phi - HALF_PI - t)
    return (t, -HALF_PI, u, v) if t >= -ZERO and u <= ZERO and v <= ZERO else None


def _lrsr(x: float, y: float, phi: float) -> tuple[float, ...] | None:  # 8.10: L+ R-(pi/2) S- R-
    xi, eta = x + math.sin(phi), y - 1.0 - math.cos(phi)
    rho, theta = _polar(-eta, xi)
    if rho < 2.0:
        return None
    t, u = theta, 2.0 - rho
    v = mod2pi(t + HALF_PI - phi)
    return (t, -HALF_PI, u, v) if t >= -ZERO and u <= ZERO and v <= ZERO else None


def _lrslr(x: float, y: float, phi: float) -> tuple[float, ...] | None:  # 8.11: L+ R-(pi/2) S- L-(pi/2) R+
    xi, eta = x + math.sin(phi), y - 1.0 - math.cos(phi)
    rho, _ = _polar(xi, eta)
    if rho < 2.0:
        return None
    u = 4.0 - math.sqrt(rho * rho - 4.0)
    if u > ZERO:
        return None
    t = mod2pi(math.atan2((4.0 - u) * xi - 2.0 * eta, -2.0 * xi + (u - 4.0) * eta))
    v = mod2pi(t - phi)
    return (t, -HALF_PI, u, -HALF_PI, v) if t >= -ZERO and v >= -ZERO else None


BASE_WORDS: tuple[tuple[str, Callable[[float, float, float], tuple[float, ...] | None]], ...] = (
    ("LSL", _lsl),
    ("LSR", _lsr),
    ("LRL", _lrl),
    ("LRLR", _lrlr_a),
    ("LRLR", _lrlr_b),
    ("LRSL", _lrsl),
    ("LRSR", _lrsr),
    ("LRSLR", _lrslr),
)
SWAP = {"L": "R", "R": "L", "S": "S"}


def drive(segments: tuple[Segment, ...], x: float = 0.0, y: float = 0.0, th: float = 0.0) -> tuple[float, float, float]:
    """The pose (x, y, theta) reached by driving ``segments`` from (x, y, th) (normalised frame)."""
    for kind, t in segments:
        if kind == "S":
            x, y = x + t * math.cos(th), y + t * math.sin(th)
        elif kind == "L":
            x, y, th = x + math.sin(th + t) - math.sin(th), y - math.cos(th + t) + math.cos(th), th + t
        else:
            x, y, th = x - math.sin(th - t) + math.sin(th), y + math.cos(th - t) - math.cos(th), th - t
    return x, y, th


def words(x: float, y: float, phi: float) -> Iterator[tuple[Segment, ...]]:
    """Every Reeds-Shepp word from (0, 0, 0) to (x, y, phi) (normalised), checked by driving it."""
    xb = x * math.cos(phi) + y * math.sin(phi)
    yb = x * math.sin(phi) - y * math.cos(phi)
    for word, formula in BASE_WORDS:
        for backwards in (False, True):
            bx, by = (xb, yb) if backwards else (x, y)
            for flip, reflect in ((False, False), (True, False), (False, True), (True, True)):
                lengths = formula(-bx if flip else bx, -by if reflect else by, -phi if flip != reflect else phi)
                if lengths is None:
                    continue
                segs = [(SWAP[k] if reflect else k, -t if flip else t) for k, t in zip(word, lengths, strict=True)]
                if backwards:
                    segs.reverse()
                path = tuple((k, t) for k, t in segs if abs(t) > ZERO)
                if _reaches(path, x, y, phi):
                    yield path


def _mod_turn(a: float) -> float:
    """``a`` wrapped into [0, 2 pi): an arc ahead of any length up to a full turn."""
    return a % (2.0 * math.pi)


def ahead_words(x: float, y: float, phi: float) -> Iterator[tuple[Segment, ...]]:
    """Dubins' CSC words (ahead only) from (0, 0, 0) to (x, y, phi) (normalised), checked by driving them: the base
    words L S L and L S R with arcs of up to a full turn, the others by reflection (port <-> starboard)."""
    for reflect in (False, True):
        for word, formula in (("LSL", _lsl), ("LSR", _lsr)):
            lengths = formula(x, -y if reflect else y, -phi if reflect else phi, _mod_turn)
            if lengths is None:
                continue
            path = tuple((SWAP[k] if reflect else k, v) for k, v in zip(word, lengths, strict=True) if v > ZERO)
            if _reaches(path, x, y, phi):
                yield path


def _reaches(path: tuple[Segment, ...], x: float, y: float, phi: float) -> bool:
    """Whether ``path`` driven from (0, 0, 0) ends on the pose (x, y, phi) (normalised)."""
    ex, ey, eth = drive(path)
    return math.hypot(ex - x, ey - y) <= END_TOLERANCE and abs(mod2pi(eth - phi)) <= END_TOLERANCE


@dataclass(frozen=True)
class Path:
    """A planned path in local NED: from ``start`` (N [m], E [m], heading from north [rad]) along ``segments``
    (normalised: lengths in turning radii, negative astern) on arcs of ``radius_m``."""

    start: tuple[float, float, float]
    radius_m: float
    segments: tuple[Segment, ...]

    @property
    def length_m(self) -> float:
        return self.radius_m * sum(abs(t) for _, t in self.segments)

    @property
    def cusps(self) -> int:
        """Changes between ahead and astern along the path."""
        signs = [t > 0 for _, t in self.segments]
        return sum(a != b for a, b in itertools.pairwise(signs))

    def sample(self, step_m: float) -> list[tuple[float, float, float, float]]:
        """Points (N [m], E [m], heading [rad], direction: +1 ahead, -1 astern) about every ``step_m`` along the
        path, from its start to its end."""
        n0, e0, psi0 = self.start
        r = self.radius_m
        first = 1.0 if not self.segments or self.segments[0][1] > 0 else -1.0
        out = [(n0, e0, psi0, first)]
        x = y = th = 0.0
        for kind, t in self.segments:
            steps = max(1, math.ceil(abs(t) * r / step_m))
            direction = 1.0 if t > 0 else -1.0
            for k in range(1, steps + 1):
                px, py, pth = drive(((kind, t * k / steps),), x, y, th)
                out.append((*_to_ned(n0, e0, psi0, px * r, py * r), mod2pi(psi0 - pth), direction))
            x, y, th = drive(((kind, t),), x, y, th)
        return out


def _to_ned(n0: float, e0: float, psi0: float, x: float, y: float) -> tuple[float, float]:
    """A point (x ahead, y to port) [m] of the frame of the pose (n0, e0, psi0) in local NED [m]."""
    c, s = math.cos(psi0), math.sin(psi0)
    return n0 + c * x + s * y, e0 + s * x - c * y


def plan(
    start: tuple[float, float, float], goal: tuple[float, float, float], radius_m: float, astern: bool = True
) -> list[Path]:
    """Every Reeds-Shepp path from ``start`` to ``goal`` (N [m], E [m], heading from north [rad]) on arcs of
    ``radius_m``, shortest first; with ``astern`` False, Dubins' (ahead only)."""
    n0, e0, psi0 = start
    dn, de = goal[0] - n0, goal[1] - e0
    c, s = math.cos(psi0), math.sin(psi0)
    x = (c * dn + s * de) / radius_m  # ahead
    y = (s * dn - c * de) / radius_m  # to port
    phi = mod2pi(-(goal[2] - psi0))  # counter-clockwise
    paths = [Path(start, radius_m, segs) for segs in (words if astern else ahead_words)(x, y, phi)]
    return sorted(paths, key=lambda p: p.length_m)
