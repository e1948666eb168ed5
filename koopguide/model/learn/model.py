"""KoopMotion's model in torch: learnable Fourier lifting and a low-rank Koopman operator.

Array conventions: states are row vectors, ``x`` of shape ``(N, d)``; lifted states ``(N, nu + d)``
with the state itself in the first ``d`` columns. ``K`` acts on column vectors (``z' = K z``), so on
row vectors ``z' = z K^T = (z B) A^T``; the ``(nu + d)^2`` matrix is never formed.
"""

from __future__ import annotations

import math

import torch
from torch import nn


class FourierKoopman(nn.Module):
    """``Psi(x) = [x, c cos(2 pi (W x + b))]``, ``c = sqrt(2 / nu)``  (KoopMotion eq. 3), ``K = A B^T``.

    With ``goal_centred`` the lifting is shifted so the goal lifts to the zero vector,
    ``Phi(x) = Psi(x) - Psi(g)``: then ``K Phi(g) = 0`` for any ``K`` and the goal is an exact fixed
    point of the re-lifted map ``f(x) = g + [K Phi(x)]_{1:d}``.
    """

    def __init__(
        self, dim: int, nu: int, rank: int, goal: torch.Tensor, goal_centred: bool, generator: torch.Generator
    ) -> None:
        super().__init__()
        self.dim, self.nu, self.rank = dim, nu, rank
        self.goal_centred = goal_centred
        self.c = math.sqrt(2.0 / nu)
        self.register_buffer("goal", goal.reshape(1, dim).clone())
        # Xavier-uniform initialisation throughout, as in the public reference implementation.
        self.W = nn.Parameter(_xavier((nu, dim), generator))
        self.b = nn.Parameter(_xavier((1, nu), generator).reshape(nu))
        self.A = nn.Parameter(_xavier((nu + dim, rank), generator))
        self.B = nn.Parameter(_xavier((nu + dim, rank), generator))

    def features(self, x: torch.Tensor) -> torch.Tensor:
        """The Fourier part ``c cos(2 pi (W x + b))``, ``(N, nu)``."""
        return self.c * torch.cos(2.0 * math.pi * (x @ self.W.T + self.b))

    def lift(self, x: torch.Tensor) -> torch.Tensor:
        """``Psi(x)`` or, goal-centred, ``Phi(x) = Psi(x) - Psi(g)``: ``(N, nu + d)``."""
        if self.goal_centred:
            feats = self.features(torch.cat([x, self.goal]))
            return torch.cat([x - self.goal, feats[:-1] - feats[-1:]], dim=1)
        return torch.cat([x, self.features(x)], dim=1)

    def advance(self, z: torch.Tensor) -> torch.Tensor:
        """One application of ``K``: ``(N, nu + d) -> (N, nu + d)``."""
        return (z @ self.B) @ self.A.T

    def step(self, x: torch.Tensor) -> torch.Tensor:
        """Re-lifted next state ``f(x) = [K Psi(x)]_{1:d}``; only the ``d`` state rows of ``K`` are used."""
        y = (self.lift(x) @ self.B) @ self.A[: self.dim].T
        return y + self.goal if self.goal_centred else y

    def jacobian_trace(self, x: torch.Tensor) -> torch.Tensor:
        """``trace(df/dx)`` at each row of ``x`` (exact, analytic): ``(N,)``.

        ``df/dx = A_x B^T dPsi/dx`` with ``dPsi/dx = [I; s W]``, ``s = -2 pi c sin(2 pi (W x + b))``, so
        ``trace = trace(A_x B_x^T) + s . q`` with ``q_n = sum_i (B_f A_x^T)_{n,i} W_{n,i}``: one matvec.
        """
        d = self.dim
        s = -2.0 * math.pi * self.c * torch.sin(2.0 * math.pi * (x @ self.W.T + self.b))  # (N, nu)
        A_x = self.A[:d]
        q = ((self.B[d:] @ A_x.T) * self.W).sum(dim=1)  # (nu,)
        return (A_x * self.B[:d]).sum() + s @ q

    def core(self) -> torch.Tensor:
        """``B^T A`` (r x r): its eigenvalues are the non-zero eigenvalues of ``K = A B^T``."""
        return self.B.T @ self.A


def _xavier(shape: tuple[int, int], generator: torch.Generator) -> torch.Tensor:
    fan_out, fan_in = shape
    bound = math.sqrt(6.0 / (fan_in + fan_out))
    return (torch.rand(shape, generator=generator, dtype=torch.float64) * 2.0 - 1.0) * bound
