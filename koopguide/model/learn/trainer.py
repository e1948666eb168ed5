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
from typing import Annotated

import numpy as np
import torch

from koopguide.base import data as demo_data
from koopguide.base.config import Range
from koopguide.model.certificate import FunnelSettings, certify_and_repair
from koopguide.model.field import FlowField
from koopguide.model.learn.gradients import AdamW, FlatParams, LossWeights, loss_and_gradient
from koopguide.model.learn.losses import DivergenceOf, koopman_loss, multistep_loss
from koopguide.model.learn.model import FourierKoopman
from koopguide.model.lyapunov import RatioLimit

Weight = Annotated[float, Range(0.0, 1e6)]  # a loss weight (beta) [-]


class LRSchedule(enum.Enum):
    CONSTANT = "constant"
    COSINE = "cosine"  # cosine decay to zero over the step budget


@dataclass(frozen=True)
class ModelConfig:
    nu: Annotated[int, Range(1, 65536)]  # number of Fourier features (lifted dimension is nu + d)
    rank: Annotated[int, Range(1, 4096)]  # rank r of K = A B^T
    goal_centred: bool  # lift with Phi(x) = Psi(x) - Psi(g): the goal is an exact fixed point


@dataclass(frozen=True)
class LossConfig:
    koopman: Weight  # beta_k, weight of the one-step linearity loss
    state: Weight  # weight of the re-lifted one-step state prediction loss |f(x) - y|^2
    divergence: Weight  # beta_d
    goal: Weight  # beta_g (the goal loss vanishes identically when goal_centred)
    divergence_of: DivergenceOf  # field (F = f - x) or next_state (f, as the reference code)
    divergence_points: Annotated[int, Range(1, 100000)]  # random training points per batch for the divergence loss
    horizon: Annotated[int, Range(1, 1000)]  # multi-step horizon T in learned steps (1 = one-step loss only)
    multistep: Weight  # weight of the multi-step loss (used when horizon > 1)


@dataclass(frozen=True)
class OptimConfig:
    steps: Annotated[int, Range(1, 10**7)]  # optimizer steps (the paper: 225 epochs x 11 batches ~= 2,475)
    batch_size: Annotated[int, Range(1, 10**7)]  # pairs per step; >= the number of pairs means full batch
    lr: Annotated[float, Range(0.0, 10.0, lo_open=True)]  # AdamW learning rate
    weight_decay: Annotated[float, Range(0.0, 10.0)]  # AdamW weight decay
    schedule: LRSchedule
    target_noise: Annotated[float, Range(0.0, 10.0)]  # Gaussian noise on targets, as a fraction of the mean step length


@dataclass(frozen=True)
class StabilityConfig:
    max_spectral_radius: (
        Annotated[float, Range(0.0, 1.0, lo_open=True, hi_open=True)] | None
    )  # after training, eigenvalues of K above this are scaled onto it


@dataclass(frozen=True)
class TrainConfig:
    subsample_every: Annotated[int, Range(1, 100000)]  # raw samples per learned step (LASA default 40)
    tangent_blend: Annotated[
        float, Range(0.0, 1.0)
    ]  # 0: target = next sub-sampled point (paper); 1: x + every * demo velocity
    threads: Annotated[int, Range(0, 1024)]  # torch CPU threads (0: leave torch's default)
    model: ModelConfig
    loss: LossConfig
    optim: OptimConfig
    stability: StabilityConfig
    convergence: FunnelSettings | None  # Lyapunov limit + certificate (None: raw field, uncertified)


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
    limit: RatioLimit | None = None  # the Lyapunov limit (koopguide.model.lyapunov), if certified
    certificate: dict | None = None  # koopguide.model.certificate.certify output, if checked
    flow: FlowField | None = None  # the certified numpy field, as built during certification

    def field(self) -> FlowField:
        """The numpy field this training produced (limited if it has a limit)."""
        if self.flow is not None:
            return self.flow
        return FlowField(self.W, self.b, self.A, self.B, self.goal, self.goal_centred, self.substeps, limit=self.limit)


ProgressFn = Callable[[int, int, dict[str, float]], None]


def train(
    demos: demo_data.Demonstrations,
    cfg: TrainConfig,
    seed: int,
    progress: ProgressFn | None = None,
    progress_every: int = 250,
) -> TrainedField:
    """Fit a flow field to ``demos``; deterministic for a given ``seed`` (and thread count)."""
    if cfg.threads > 0:
        torch.set_num_threads(cfg.threads)
    started, cpu_started = time.perf_counter(), time.process_time()
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
    params = FlatParams(*(t.detach() for t in (model.W, model.b, model.A, model.B)))
    for t, view in zip((model.W, model.b, model.A, model.B), (params.W, params.b, params.A, params.B), strict=True):
        t.data = view  # the module reads the flat parameters (the multi-step term's autograd path)
    goal_t = model.goal
    weights = LossWeights(cfg.loss.koopman, cfg.loss.state, cfg.loss.divergence, cfg.loss.goal, cfg.loss.divergence_of)
    steps = cfg.optim.steps
    opt = AdamW(params.flat, cfg.optim.lr, cfg.optim.weight_decay)

    n_pairs = x.shape[0]
    batch = min(cfg.optim.batch_size, n_pairs)
    draws = _Draws(rng, gen, x, y, noisy, noise_sigma, batch, cfg.loss.divergence_points)
    losses = torch.empty(steps, dtype=dtype)
    with torch.no_grad():
        for k in range(1, steps + 1):
            xb, yb, pts = draws.next()
            loss, terms_t = loss_and_gradient(params, goal_t, cfg.model.goal_centred, xb, yb, pts, weights)
            if win is not None:
                loss = loss + _multistep_into(params, model, win, rng, batch, cfg.loss.multistep, terms_t)
            cosine = cfg.optim.schedule is LRSchedule.COSINE
            opt.step(params.grad, 0.5 * (1.0 + math.cos(math.pi * (k - 1) / steps)) if cosine else 1.0)
            losses[k - 1] = loss
            if k % 100 == 0 or k == steps:
                _check_finite(losses, k)
            if progress is not None and (k % progress_every == 0 or k == steps):
                progress(k, steps, {"loss": loss.item(), **{name: v.item() for name, v in terms_t.items()}})

        final_k = koopman_loss(model, x, y).item()
    W, b, A, B = (t.to(torch.float64).numpy().copy() for t in (params.W, params.b, params.A, params.B))
    rho_before = spectral_radius(A, B)
    if cfg.stability.max_spectral_radius is not None:
        A = project_spectrum(A, B, cfg.stability.max_spectral_radius)
    fit_seconds, fit_cpu = time.perf_counter() - started, time.process_time() - cpu_started
    limit, cert, limited = None, None, None
    if cfg.convergence is not None:
        raw = FlowField(W, b, A, B, demos.goal, cfg.model.goal_centred, cfg.subsample_every)
        samples = np.concatenate([t[::5] for t in demos.trajectories])
        limited, cert = certify_and_repair(raw, samples, demos.bounds, cfg.convergence)
        limit = limited.limit
    info = {
        "seed": seed,
        "steps": steps,
        "pairs": int(n_pairs),
        "fit_seconds": fit_seconds,
        "certify_seconds": time.perf_counter() - started - fit_seconds,
        "fit_cpu_seconds": fit_cpu,  # this process's CPU time: other jobs inflate it less than wall time
        "certify_cpu_seconds": time.process_time() - cpu_started - fit_cpu,
        "train_seconds": time.perf_counter() - started,
        "final_koopman_loss": final_k,
        "rho_trained": rho_before,
        "rho": spectral_radius(A, B),
        "torch_version": str(torch.__version__),
    }
    return TrainedField(
        W=W,
        b=b,
        A=A,
        B=B,
        goal=demos.goal.copy(),
        goal_centred=cfg.model.goal_centred,
        substeps=cfg.subsample_every,
        info=info,
        limit=limit,
        certificate=cert,
        flow=limited,
    )


class _Draws:
    """Each step's batch, made in blocks of steps: pairs (reshuffled each epoch), their targets with noise
    (standard normal x ``noise_sigma``, not on a demonstration's last pair) and the divergence points."""

    BLOCK = 256  # steps per block

    def __init__(self, rng, gen, x, y, noisy, noise_sigma: float, batch: int, div_points: int) -> None:
        self.rng, self.gen, self.x, self.y, self.noisy = rng, gen, x, y, noisy
        self.noise_sigma, self.batch, self.m = noise_sigma, batch, div_points
        self.n = x.shape[0]
        self.order, self.cursor = rng.permutation(self.n), 0
        self.pos = self.BLOCK

    def _refill(self) -> None:
        idx = np.empty((self.BLOCK, self.batch), dtype=np.int64)
        for j in range(self.BLOCK):
            if self.cursor + self.batch > self.n:  # a new epoch: reshuffle
                self.order, self.cursor = self.rng.permutation(self.n), 0
            idx[j] = self.order[self.cursor : self.cursor + self.batch]
            self.cursor += self.batch
        idx_t = torch.as_tensor(idx)
        noise = torch.randn((self.BLOCK, self.batch, self.x.shape[1]), generator=self.gen, dtype=self.x.dtype)
        self.xb = self.x[idx_t]
        self.yb = torch.addcmul(self.y[idx_t], noise, self.noisy[idx_t], value=self.noise_sigma)
        self.pts = self.x[torch.as_tensor(self.rng.integers(0, self.n, size=(self.BLOCK, self.m)))]
        self.pos = 0

    def next(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(x (batch, d), y (batch, d), divergence points (m, d))`` of the next step."""
        if self.pos == self.BLOCK:
            self._refill()
        j = self.pos
        self.pos += 1
        return self.xb[j], self.yb[j], self.pts[j]


def _multistep_into(
    params: FlatParams, model: FourierKoopman, win, rng, batch: int, weight: float, terms
) -> torch.Tensor:
    """Add ``weight`` x the multi-step loss's gradient (by autograd) to ``params.grad``; return the weighted term."""
    wb = win[torch.as_tensor(rng.integers(0, win.shape[0], size=min(batch, win.shape[0])))]
    with torch.enable_grad():
        for t in model.parameters():
            t.grad = None
        loss_m = multistep_loss(model, wb)
        (weight * loss_m).backward()
    for t, g in zip((model.W, model.b, model.A, model.B), (params.gW, params.gb, params.gA, params.gB), strict=True):
        g.add_(t.grad)
    terms["multistep"] = loss_m.detach()
    return weight * loss_m.detach()


def _check_finite(losses: torch.Tensor, k: int) -> None:
    """Raise if any loss up to step ``k`` is not finite, naming the first such step."""
    bad = ~torch.isfinite(losses[:k])
    if bool(bad.any()):
        first = int(torch.nonzero(bad)[0, 0])
        raise FloatingPointError(f"training diverged at step {first + 1}: loss {losses[first].item()}")


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
