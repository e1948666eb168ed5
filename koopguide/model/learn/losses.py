"""KoopMotion's training losses (all mean squared errors).

Array conventions as in :mod:`koopguide.model.learn.model`: states ``(N, d)``, windows ``(M, H + 1, d)``.
"""

from __future__ import annotations

import enum

import torch

from koopguide.model.learn.model import FourierKoopman


class DivergenceOf(enum.Enum):
    """Which map's Jacobian trace the divergence loss penalises."""

    #: ``F(x) = f(x) - x``, the learned velocity field: ``div F = trace(df/dx) - d``. The flow-field
    #: reading of the paper ("almost divergence-free"), and the one koopguide uses by default.
    FIELD = "field"
    #: ``f(x)`` itself, as the public reference code does: drives ``div F`` towards ``-d``, i.e. a
    #: strongly contracting field rather than a divergence-free one.
    NEXT_STATE = "next_state"


def pair_losses(model: FourierKoopman, x: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """One-step losses on pairs ``x -> y``, both from a single lift of the stacked batch:

    - Koopman linearity ``|Psi(y) - K Psi(x)|^2`` over all ``nu + d`` lifted coordinates (KoopMotion eq. 5);
    - state prediction ``|f(x) - y|^2``, the first ``d`` coordinates of the same residual: the
      re-lifted map a vehicle that re-measures its position follows.
    """
    z = model.lift(torch.cat([x, y]))
    n = x.shape[0]
    residual = z[n:] - model.advance(z[:n])
    return torch.mean(residual**2), torch.mean(residual[:, : model.dim] ** 2)


def koopman_loss(model: FourierKoopman, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Linearity in the lifted space: ``|Psi(y) - K Psi(x)|^2``  (KoopMotion eq. 5)."""
    return pair_losses(model, x, y)[0]


def goal_loss(model: FourierKoopman) -> torch.Tensor:
    """Goal invariance ``|Psi(g) - K Psi(g)|^2``  (KoopMotion eq. 7); identically 0 when goal-centred."""
    z = model.lift(model.goal)
    return torch.mean((z - model.advance(z)) ** 2)


def divergence_loss(model: FourierKoopman, x: torch.Tensor, of: DivergenceOf) -> torch.Tensor:
    """Squared divergence at the points ``x``  (KoopMotion eq. 6), exact Jacobian."""
    trace = model.jacobian_trace(x)
    if of is DivergenceOf.FIELD:
        trace = trace - model.dim
    return torch.mean(trace**2)


def multistep_loss(model: FourierKoopman, windows: torch.Tensor) -> torch.Tensor:
    """Long-horizon linearity ``sum_h |Psi(x_h) - K^h Psi(x_0)|^2 / H`` over windows ``(M, H + 1, d)``.

    Each horizon is weighted equally; the lifted state is propagated by ``K`` alone (no re-lifting),
    which is what a trajectory of the linear lifted system must satisfy.
    """
    horizon = windows.shape[1] - 1
    z = model.lift(windows[:, 0])
    total = windows.new_zeros(())
    for h in range(1, horizon + 1):
        z = model.advance(z)
        total = total + torch.mean((model.lift(windows[:, h]) - z) ** 2)
    return total / horizon
