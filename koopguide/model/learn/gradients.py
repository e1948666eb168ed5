"""The training loss of :mod:`koopguide.model.learn.losses` and its exact gradient, by hand, in one pass.

Autograd records a graph of some 60 small operations per step and walks it back; at KoopMotion's sizes
(a batch of 32 pairs, ``nu = 1024``, rank 32) that bookkeeping costs more than the arithmetic. Here the
forward pass keeps what the backward pass needs and the gradient is written out (reverse-mode by hand),
so a step is a handful of matrix products and elementwise passes. ``tests/model`` checks every term
against autograd on :class:`~koopguide.model.learn.model.FourierKoopman`.

Array conventions as in :mod:`koopguide.model.learn.model`: states ``(N, d)``; lifted states
``(N, D)``, ``D = nu + d``, the state in the first ``d`` columns; ``K = A B^T`` acts on row vectors as
``z K^T = (z B) A^T``. The parameters live in one flat vector (:class:`FlatParams`) so the optimizer
updates them all in a few operations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from koopguide.model.learn.losses import DivergenceOf

TWO_PI = 2.0 * math.pi


class FlatParams:
    """``W (nu, d)``, ``b (nu,)``, ``A, B (D, r)`` as views into one flat vector, and a gradient of the same layout."""

    def __init__(self, W: torch.Tensor, b: torch.Tensor, A: torch.Tensor, B: torch.Tensor) -> None:
        tensors = (W, b, A, B)
        self.flat = torch.cat([t.reshape(-1) for t in tensors])
        self.grad = torch.zeros_like(self.flat)
        self.W, self.b, self.A, self.B = self._views(self.flat, tensors)
        self.gW, self.gb, self.gA, self.gB = self._views(self.grad, tensors)

    @staticmethod
    def _views(flat: torch.Tensor, like: tuple[torch.Tensor, ...]) -> list[torch.Tensor]:
        out, start = [], 0
        for t in like:
            out.append(flat[start : start + t.numel()].view(t.shape))
            start += t.numel()
        return out


@dataclass(frozen=True)
class LossWeights:
    koopman: float  # beta_k
    state: float  # weight of |f(x) - y|^2
    divergence: float  # beta_d
    goal: float  # beta_g (used only without goal-centring)
    divergence_of: DivergenceOf


def loss_and_gradient(
    p: FlatParams,
    goal: torch.Tensor,
    goal_centred: bool,
    x: torch.Tensor,
    y: torch.Tensor,
    pts: torch.Tensor,
    w: LossWeights,
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """The weighted loss at pairs ``x -> y`` ``(n, d)`` and divergence points ``pts`` ``(m, d)``; writes
    its gradient into ``p.grad``; returns the loss and its unweighted terms (0-d tensors).

    Terms (KoopMotion eqs. 5-7): ``beta_k |Phi(y) - K Phi(x)|^2 / (n D)`` + ``beta_s |f(x) - y|^2 / (n d)``
    + ``beta_d mean(trace(df/dx) [- d])^2`` + (plain lifting only) ``beta_g |Psi(g) - K Psi(g)|^2 / D``.
    """
    n, d = x.shape
    m = pts.shape[0]
    nu = p.W.shape[0]
    D = nu + d
    c = math.sqrt(2.0 / nu)
    goal = goal.reshape(1, d)
    with_goal_row = not goal_centred and w.goal > 0
    X = torch.cat([x, y, goal, pts])  # (2n + 1 + m, d): one phase computation for every use
    phase = torch.addmm(p.b, X, p.W.T, beta=TWO_PI, alpha=TWO_PI)  # 2 pi (W x + b)
    cos, sin = torch.cos(phase), torch.sin(phase)
    # lifted pairs, with the goal (when it has a loss of its own) as one more pair g -> g
    if goal_centred:  # Phi = Psi - Psi(g)
        z = torch.empty((2 * n, D), dtype=x.dtype)
        torch.sub(X[: 2 * n], goal, out=z[:, :d])
        torch.sub(cos[: 2 * n], cos[2 * n], out=z[:, d:]).mul_(c)
        zx, zy = z[:n], z[n:]
    else:
        z = torch.cat([X[: 2 * n + 1], cos[: 2 * n + 1] * c], dim=1)
        rows = torch.arange(n + 1 if with_goal_row else n)
        zx = z[torch.where(rows < n, rows, 2 * n)]
        zy = z[torch.where(rows < n, rows + n, 2 * n)]
    U = zx @ p.B  # (n', r)
    R = torch.addmm(zy, U, p.A.T, alpha=-1.0)  # residual Phi(y) - K Phi(x)
    # dL/dR: the Koopman term on every coordinate, the state term on the first d of the pair rows
    G = R * (2.0 * w.koopman / (n * D))
    if with_goal_row:
        torch.mul(R[n], 2.0 * w.goal / D, out=G[n])
    G[:n, :d] += (2.0 * w.state / (n * d)) * R[:n, :d]
    R_pairs = R[:n].reshape(-1)
    terms = {"koopman": torch.dot(R_pairs, R_pairs) / (n * D), "state": (R[:n, :d] ** 2).sum() / (n * d)}
    if with_goal_row:
        terms["goal"] = torch.dot(R[n], R[n]) / D
    # back through R = zy - (zx B) A^T, with V = -dL/d(zx B)
    U.neg_()
    torch.mm(G.T, U, out=p.gA)
    V = G @ p.A  # (n', r)
    V.neg_()
    torch.mm(zx.T, V, out=p.gB)
    dzx = V @ p.B[d:].T  # dL/dzx, feature columns only
    # through z = c cos(phase) [- c cos(phase_g)]; the common factor -c is applied to gW and gb at the end
    dphase = torch.empty_like(phase)
    torch.mul(sin[:n], dzx[:n], out=dphase[:n])
    torch.mul(sin[n : 2 * n], G[:n, d:], out=dphase[n : 2 * n])
    if goal_centred:  # Psi(g) enters every lifted pair with a minus sign
        torch.mul(sin[2 * n], dzx[:n].sum(dim=0).add_(G[:n, d:].sum(dim=0)), out=dphase[2 * n]).neg_()
    elif with_goal_row:
        torch.mul(sin[2 * n], G[n, d:] + dzx[n], out=dphase[2 * n])
    else:
        dphase[2 * n] = 0.0
    # divergence: trace(df/dx) = trace(A_x B_x^T) + s . q, s = -2 pi c sin(phase), q_j = sum_i (B_f A_x^T)_ji W_ji
    A_x, B_x, B_f = p.A[:d], p.B[:d], p.B[d:]
    Mq = B_f @ A_x.T  # (nu, d)
    q = (Mq * p.W).sum(dim=1)
    s = sin[2 * n + 1 :] * (-TWO_PI * c)  # (m, nu)
    trace = (A_x * B_x).sum() + s @ q
    t = trace - d if w.divergence_of is DivergenceOf.FIELD else trace
    terms["divergence"] = (t * t).mean()
    e = (2.0 * w.divergence / m) * t  # dL/dtrace
    e_sum = e.sum().item()
    h = s.T @ e  # dL/dq (nu,)
    torch.outer(e * TWO_PI, q, out=dphase[2 * n + 1 :]).mul_(cos[2 * n + 1 :])  # ds/dphase = -2 pi c cos
    p.gA[:d].add_(B_x, alpha=e_sum)
    p.gB[:d].add_(A_x, alpha=e_sum)
    hW = h[:, None] * p.W  # dL/dMq
    p.gB[d:].addmm_(hW, A_x)
    p.gA[:d].addmm_(hW.T, B_f)
    # through phase = 2 pi (X W^T + b), with the factor -c left over from above
    p.gW.copy_((X.T @ dphase).T).mul_(-TWO_PI * c).addcmul_(h[:, None], Mq)  # X^T dphase: the fast layout
    torch.sum(dphase, dim=0, out=p.gb).mul_(-TWO_PI * c)
    loss = w.koopman * terms["koopman"] + w.state * terms["state"] + w.divergence * terms["divergence"]
    if with_goal_row:
        loss = loss + w.goal * terms["goal"]
    return loss, terms


class AdamW:
    """AdamW (Loshchilov & Hutter 2019, Algorithm 2) on one flat parameter vector: a few operations per step.

    The same update as ``torch.optim.AdamW`` (betas 0.9/0.999, eps 1e-8, decoupled weight decay).
    """

    def __init__(
        self,
        params: torch.Tensor,
        lr: float,
        weight_decay: float,
        betas: tuple[float, float] = (0.9, 0.999),
        eps: float = 1e-8,
    ) -> None:
        self.params, self.lr, self.wd, self.betas, self.eps = params, lr, weight_decay, betas, eps
        self.m = torch.zeros_like(params)
        self.v = torch.zeros_like(params)
        self.denom = torch.empty_like(params)
        self.t = 0

    @torch.no_grad()
    def step(self, grad: torch.Tensor, lr_scale: float = 1.0) -> None:
        self.t += 1
        b1, b2 = self.betas
        lr = self.lr * lr_scale
        c1, c2 = 1.0 - b1**self.t, 1.0 - b2**self.t
        self.params.mul_(1.0 - lr * self.wd)
        self.m.lerp_(grad, 1.0 - b1)
        self.v.mul_(b2).addcmul_(grad, grad, value=1.0 - b2)
        torch.div(self.v, c2, out=self.denom).sqrt_().add_(self.eps)
        self.params.addcdiv_(self.m, self.denom, value=-lr / c1)
