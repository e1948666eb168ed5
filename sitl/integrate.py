"""Fixed-step integration of an ODE x_dot = f(t, x) over tuples of floats.

The classical fourth-order Runge-Kutta step; pure functions, no state. Stochastic inputs (flow noise)
are advanced separately with Euler-Maruyama (sitl.flow) and held constant within a step.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

Vector = tuple[float, ...]
Derivative = Callable[[float, Sequence[float]], Sequence[float]]


def rk4_step(f: Derivative, t: float, x: Sequence[float], h: float) -> Vector:
    """One classical RK4 step of size h [s] from (t, x); returns x(t + h)."""
    half = 0.5 * h
    k1 = f(t, x)
    k2 = f(t + half, tuple(xi + half * ki for xi, ki in zip(x, k1, strict=True)))
    k3 = f(t + half, tuple(xi + half * ki for xi, ki in zip(x, k2, strict=True)))
    k4 = f(t + h, tuple(xi + h * ki for xi, ki in zip(x, k3, strict=True)))
    sixth = h / 6.0
    return tuple(xi + sixth * (a + 2.0 * b + 2.0 * c + d) for xi, a, b, c, d in zip(x, k1, k2, k3, k4, strict=True))
