"""Training a KoopMotion flow field: typed settings, the optimisation loop, and the trained result.

Array conventions: demonstrations as in :mod:`koopguide.base.data` (``(T, d)`` per trajectory); the
trained weights come out as float64 numpy arrays ``W (nu, d)``, ``b (nu,)``, ``A, B (nu + d, r)``.
"""

from __future__ import annotations

import enum
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from koopguide.base import data as demo_data
from koopguide.model.learn.losses import (
    DivergenceOf,
    divergence_loss,
    goal_loss,
    koopman_loss,
    multistep_loss,
    pair_losses,
)
from koopguide.model.learn.model import FourierKoopman


class LRSchedule(enum.Enum):
    CONSTANT = "constant"
    COSINE = "cosine"  # cosine decay to zero over the step budget


@dataclass(frozen=True)
class ModelConfig:
    nu: int  # number of Fourier features (lifted dimension is nu + d)
    rank: int  # rank r of K = A B^T
    goal_centred: bool  # lift with Phi(x) = Psi(x) - Psi(g): the goal is an exact fixed point


@dataclass(frozen=True)
class LossConfig:
    koopman: float  # beta_k, weight of the one-step linearity loss
    state: float  # weight of the re-lifted one-step state prediction loss |f(x) - y|^2
    divergence: float  # beta_d
    goal: float  # beta_g (the goal loss vanishes identically when goal_centred)
    divergence_of: DivergenceOf  # field (F = f - x) or next_state (f, as the reference code)
    divergence_points: int  # random training points per batch for the divergence loss
    horizon: int  # multi-step horizon T in learned steps (1 = one-step loss only)
    multistep: float  # weight of the multi-step loss (used when horizon > 1)


@dataclass(frozen=True)
class OptimConfig:
    steps: int  # optimizer steps (the paper: 225 epochs x 11 batches ~= 2,475)
    batch_size: int  # pairs per step; >= the number of pairs means full batch
    lr: float  # AdamW learning rate
    weight_decay: float  # AdamW weight decay
    schedule: LRSchedule
    target_noise: float  # Gaussian noise on targets, as a fraction of the mean step length


@dataclass(frozen=True)
class StabilityConfig:
    max_spectral_radius: float | None  # after training, eigenvalues of K above this are scaled onto it


@dataclass(frozen=True)
class TrainConfig:
    subsample_every: int  # raw samples per learned step (LASA default 40)
    tangent_blend: float  # 0: target = next sub-sampled point (paper); 1: x + every * demo velocity
    threads: int  # torch CPU threads (0: leave torch's default)
    model: ModelConfig
    loss: LossConfig
    optim: OptimConfig
    stability: StabilityConfig


@dataclass(frozen=True)
class TrainedField:
    """Everything a model file stores: weights (float64 numpy) and plain-data metadata."""

    W: np.ndarray
    b: np.ndarray
    A: np.ndarray
    B: np.ndarray
    goal: np.ndarray
    goal_centred: bool
    substeps: int
    info: dict  # losses, timing, seed, spectral radius before/after projection


ProgressFn = Callable[[int, int, dict[str, float]], None]


def train(demos: demo_data.Demonstrations, cfg: TrainConfig, seed: int,
          progress: ProgressFn | None = None, progress_every: int = 250) -> TrainedField:
    """Fit a flow field to ``demos``; deterministic for a given ``seed`` (and thread count)."""
    _check(cfg)
    if cfg.threads > 0:
        torch.set_num_threads(cfg.threads)
    started = time.perf_counter()
    gen = torch.Generator().manual_seed(seed)
    rng = np.random.default_rng(seed)
    dtype = torch.float32

    x_np, y_np, last_np = demo_data.pairs(demos, cfg.subsample_every, cfg.tangent_blend)
    x = torch.as_tensor(x_np, dtype=dtype)
    y = torch.as_tensor(y_np, dtype=dtype)
    # Target noise (not on each demonstration's final pair, which must land on the goal).
    mean_step = float(np.mean(np.linalg.norm(y_np - x_np, axis=1)))
    noise_sigma = cfg.optim.target_noise * mean_step
    noisy = torch.as_tensor(~last_np, dtype=dtype).unsqueeze(1)
    win = None
    if cfg.loss.horizon > 1 and cfg.loss.multistep > 0:
        win = torch.as_tensor(demo_data.windows(demos, cfg.subsample_every, cfg.loss.horizon), dtype=dtype)

    goal = torch.as_tensor(demos.goal, dtype=torch.float64)
    model = FourierKoopman(demos.dim, cfg.model.nu, cfg.model.rank, goal, cfg.model.goal_centred, gen).to(dtype)
    opt = _adamw(model, cfg.optim)
    steps = cfg.optim.steps
    if cfg.optim.schedule is LRSchedule.COSINE:
        sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda k: 0.5 * (1.0 + math.cos(math.pi * k / steps)))
    else:
        sched = None

    n_pairs = x.shape[0]
    batch = min(cfg.optim.batch_size, n_pairs)
    order = rng.permutation(n_pairs)
    cursor = 0
    terms: dict[str, float] = {}
    for k in range(1, steps + 1):
        if cursor + batch > n_pairs:  # a new epoch: reshuffle
            order, cursor = rng.permutation(n_pairs), 0
        idx = torch.as_tensor(order[cursor : cursor + batch])
        cursor += batch
        xb = x[idx]
        yb = y[idx] + noise_sigma * torch.randn((batch, demos.dim), generator=gen, dtype=dtype) * noisy[idx]
        loss_k, loss_s = pair_losses(model, xb, yb)
        loss = cfg.loss.koopman * loss_k + cfg.loss.state * loss_s
        pts = x[torch.as_tensor(rng.integers(0, n_pairs, size=cfg.loss.divergence_points))]
        loss_d = divergence_loss(model, pts, cfg.loss.divergence_of)
        loss = loss + cfg.loss.divergence * loss_d
        if not cfg.model.goal_centred and cfg.loss.goal > 0:
            loss_g = goal_loss(model)
            loss = loss + cfg.loss.goal * loss_g
        else:
            loss_g = None
        if win is not None:
            wb = win[torch.as_tensor(rng.integers(0, win.shape[0], size=min(batch, win.shape[0])))]
            loss_m = multistep_loss(model, wb)
            loss = loss + cfg.loss.multistep * loss_m
        else:
            loss_m = None
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        if sched is not None:
            sched.step()
        if not math.isfinite(loss.item()):
            raise FloatingPointError(f"training diverged at step {k}: loss {loss.item()}")
        if progress is not None and (k % progress_every == 0 or k == steps):
            terms = {"loss": loss.item(), "koopman": loss_k.item(), "state": loss_s.item(),
                     "divergence": loss_d.item()}
            if loss_g is not None:
                terms["goal"] = loss_g.item()
            if loss_m is not None:
                terms["multistep"] = loss_m.item()
            progress(k, steps, terms)

    with torch.no_grad():
        final_k = koopman_loss(model, x, y).item()
    W, b, A, B = (p.detach().to(torch.float64).numpy().copy() for p in (model.W, model.b, model.A, model.B))
    rho_before = spectral_radius(A, B)
    if cfg.stability.max_spectral_radius is not None:
        A = project_spectrum(A, B, cfg.stability.max_spectral_radius)
    info = {
        "seed": seed,
        "steps": steps,
        "pairs": int(n_pairs),
        "train_seconds": time.perf_counter() - started,
        "final_koopman_loss": final_k,
        "rho_trained": rho_before,
        "rho": spectral_radius(A, B),
        "torch_version": str(torch.__version__),
    }
    return TrainedField(W=W, b=b, A=A, B=B, goal=demos.goal.copy(), goal_centred=cfg.model.goal_centred,
                        substeps=cfg.subsample_every, info=info)


def _adamw(model: torch.nn.Module, optim: OptimConfig) -> torch.optim.Optimizer:
    """AdamW, fused on CPU where this torch has it (>= 2.4): same update, fewer kernel launches."""
    try:
        return torch.optim.AdamW(model.parameters(), lr=optim.lr, weight_decay=optim.weight_decay, fused=True)
    except (RuntimeError, TypeError, ValueError):
        return torch.optim.AdamW(model.parameters(), lr=optim.lr, weight_decay=optim.weight_decay)


def spectral_radius(A: np.ndarray, B: np.ndarray) -> float:
    """``rho(K)`` for ``K = A B^T``, from the ``r x r`` matrix ``B^T A`` (same non-zero spectrum)."""
    return float(np.max(np.abs(np.linalg.eigvals(B.T @ A))))


def project_spectrum(A: np.ndarray, B: np.ndarray, rho_max: float) -> np.ndarray:
    """Return ``A'`` so that ``K' = A' B^T`` has every eigenvalue inside ``|lambda| <= rho_max``.

    The core ``M = B^T A`` is diagonalised, ``M = V diag(lambda) V^-1``; eigenvalues above
    ``rho_max`` are scaled radially onto it, ``M' = V diag(lambda') V^-1``, and ``A' = A + B (B^T B)^-1
    (M' - M)`` changes ``A`` only inside the span of ``B`` (the smallest change that gives the new core).
    Eigenvalues already inside are left exactly as trained.
    """
    M = B.T @ A
    lam, V = np.linalg.eig(M)
    too_big = np.abs(lam) > rho_max
    if not too_big.any():
        return A
    lam_new = np.where(too_big, lam / np.abs(lam) * rho_max, lam)
    M_new = np.real(V @ np.diag(lam_new) @ np.linalg.inv(V))
    return A + B @ np.linalg.solve(B.T @ B, M_new - M)


def _check(cfg: TrainConfig) -> None:
    problems = []
    if cfg.subsample_every < 1:
        problems.append(f"subsample_every must be >= 1, got {cfg.subsample_every}")
    if cfg.model.nu < 1 or cfg.model.rank < 1:
        problems.append(f"model.nu and model.rank must be >= 1, got {cfg.model.nu} and {cfg.model.rank}")
    if cfg.optim.steps < 1 or cfg.optim.batch_size < 1:
        problems.append(f"optim.steps and optim.batch_size must be >= 1, got {cfg.optim.steps}, {cfg.optim.batch_size}")
    if cfg.optim.lr <= 0:
        problems.append(f"optim.lr must be > 0, got {cfg.optim.lr}")
    if cfg.loss.horizon < 1:
        problems.append(f"loss.horizon must be >= 1, got {cfg.loss.horizon}")
    if cfg.loss.divergence_points < 1:
        problems.append(f"loss.divergence_points must be >= 1, got {cfg.loss.divergence_points}")
    rho_max = cfg.stability.max_spectral_radius
    if rho_max is not None and not 0 < rho_max < 1:
        problems.append(f"stability.max_spectral_radius must be in (0, 1), got {cfg.stability.max_spectral_radius}")
    if problems:
        raise ValueError("invalid training configuration: " + "; ".join(problems))
