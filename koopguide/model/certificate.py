"""The convergence certificate: every start of a dense grid reaches the goal, for both integrators.

Array conventions: states ``(N, d)`` in model units; distances in model units; velocities in model
units per learned step (divide by ``substeps`` for units per raw sample).

The two integrators are the ones the issue and the guidance service use:

- ``learned``: ``x <- f~(x)``, 100 learned steps;
- ``euler``: ``x <- x + (f~(x) - x) / substeps``, up to ``100 * substeps`` raw steps.

Early exit (exact, not a heuristic): with a Lyapunov limit, ``ball_max(r)`` bounds ``gamma`` on the
ball of radius ``r`` around the goal. If ``ball_max(r) <= q < 1`` a state at distance ``r`` stays in
that ball and its distance shrinks at least by ``q`` per learned step and by ``1 - (1 - q) / substeps``
per raw step (:mod:`koopguide.model.lyapunov`), so once that bound over the remaining steps is within the
tolerance the start is counted as converged with the bound as its end distance.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import asdict, dataclass
from typing import Annotated

import numpy as np

from koopguide.base.config import Range, check
from koopguide.model.field import FlowField

CERTIFICATE_VERSION = 1


@dataclass(frozen=True)
class IntegratorOutcome:
    converged: int  # starts ending within the tolerance of the goal
    starts: int
    worst_end_distance: float  # model units (an upper bound for starts that exited early)
    raw_steps: int  # integration steps taken at most


def grid_starts(lo: np.ndarray, hi: np.ndarray, per_axis: int) -> np.ndarray:
    """``per_axis ** d`` starts on a regular grid over ``[lo, hi]`` (corners included): ``(N, d)``."""
    axes = [np.linspace(lo[k], hi[k], per_axis) for k in range(len(lo))]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(lo))


def ball_profile(field: FlowField) -> tuple[np.ndarray, np.ndarray]:
    """``(radii, gamma_max)``: the largest ratio ``gamma`` anywhere within each radius of the goal."""
    limit = field.limit
    if limit is None:
        return np.array([0.0]), np.array([np.inf])
    cell = np.linalg.norm((limit.hi - limit.lo) / (np.asarray(limit.table.shape) - 1))
    axes = [np.linspace(limit.lo[k], limit.hi[k], n) for k, n in enumerate(limit.table.shape)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))
    dist = np.linalg.norm(grid - field.goal, axis=1) - cell  # every cell the ball touches has a node here
    order = np.argsort(dist)
    radii = np.maximum(dist[order], 0.0)
    gmax = np.maximum.accumulate(limit.table.ravel()[order])
    # beyond the table the ratio is `outside`; a ball that leaves the table also sees it
    inner = np.min(np.minimum(np.abs(field.goal - limit.lo), np.abs(limit.hi - field.goal)))
    gmax = np.where(radii >= inner, np.maximum(gmax, limit.outside), gmax)
    return radii, gmax


def run_to_goal(
    field: FlowField, X0: np.ndarray, integrator: str, learned_steps: int, tolerance: float
) -> tuple[np.ndarray, int]:
    """End distances ``(N,)`` (or exact upper bounds) after the integrator's full horizon; steps taken."""
    if integrator == "learned":
        h, n = 1.0, learned_steps
    elif integrator == "euler":
        h, n = 1.0 / field.substeps, learned_steps * field.substeps
    else:
        raise ValueError(f"unknown integrator {integrator!r}; use 'learned' or 'euler'")
    radii, gmax = ball_profile(field)
    X = np.array(X0, dtype=np.float64)
    active = np.arange(len(X))
    end = np.full(len(X), np.inf)
    taken = 0
    for k in range(n):
        if k % 10 == 0 and np.isfinite(gmax[0]):
            r = np.linalg.norm(X - field.goal, axis=1)
            q = gmax[np.clip(np.searchsorted(radii, r, side="right") - 1, 0, len(radii) - 1)]
            per_step = 1.0 - h * (1.0 - q)
            bound = r * np.where(q < 1.0, per_step, 1.0) ** (n - k)
            done = (q < 1.0) & (bound <= tolerance) & (r <= radii[-1])
            end[active[done]] = bound[done]
            X, active = X[~done], active[~done]
            if len(X) == 0:
                break
        X = X + h * (field.step(X) - X)
        taken = k + 1
    if len(X):
        d = np.linalg.norm(X - field.goal, axis=1)
        end[active] = np.where(np.isfinite(d), d, np.inf)
    return end, taken


def outcome(end: np.ndarray, taken: int, tolerance: float) -> IntegratorOutcome:
    return IntegratorOutcome(
        converged=int(np.sum(end <= tolerance)), starts=len(end), worst_end_distance=float(np.max(end)), raw_steps=taken
    )


def field_digest(field: FlowField) -> str:
    """SHA-256 of the weights, goal and limit table: binds a certificate to the field it was run on."""
    h = hashlib.sha256()
    for arr in (field.W, field.b, field.A, field.B, field.goal):
        h.update(np.ascontiguousarray(arr, dtype="<f8").tobytes())
    if field.limit is not None:
        h.update(np.ascontiguousarray(field.limit.table, dtype="<f8").tobytes())
        h.update(np.asarray([*field.limit.lo, *field.limit.hi, field.limit.outside], dtype="<f8").tobytes())
    return h.hexdigest()


def certify(
    field: FlowField,
    lo: np.ndarray,
    hi: np.ndarray,
    per_axis: int = 100,
    tolerance: float = 1.0,
    learned_steps: int = 100,
    fixed_point_tolerance: float = 0.01,
) -> dict:
    """Run both integrators from a ``per_axis ** d`` grid over ``[lo, hi]``; the certificate as plain data."""
    return certify_detail(field, lo, hi, per_axis, tolerance, learned_steps, fixed_point_tolerance)[0]


def certify_detail(
    field: FlowField,
    lo: np.ndarray,
    hi: np.ndarray,
    per_axis: int,
    tolerance: float,
    learned_steps: int,
    fixed_point_tolerance: float,
    learned_run: tuple[np.ndarray, int] | None = None,
) -> tuple[dict, np.ndarray]:
    """:func:`certify` and the starts ``(M, d)`` that failed either integrator (for repairs).

    ``learned_run``: the learned-step integrator's ``run_to_goal`` result on this field and grid, if
    already computed (it is deterministic, so it is not run twice).
    """
    X0 = grid_starts(lo, hi, per_axis)
    if learned_run is None:
        learned_run = run_to_goal(field, X0, "learned", learned_steps, tolerance)
    end_l, taken_l = learned_run
    end_e, taken_e = run_to_goal(field, X0, "euler", learned_steps, tolerance)
    learned, euler = outcome(end_l, taken_l, tolerance), outcome(end_e, taken_e, tolerance)
    failing = X0[(end_l > tolerance) | (end_e > tolerance)]
    speed = np.linalg.norm(field.velocity(X0), axis=1)
    rho = field.spectral_radius()
    fixed = float(np.linalg.norm(field.step(field.goal) - field.goal))
    passed = (
        learned.converged == learned.starts
        and euler.converged == euler.starts
        and rho < 1.0
        and fixed <= fixed_point_tolerance
        and bool(np.all(np.isfinite(speed)))
    )
    cert = {
        "version": CERTIFICATE_VERSION,
        "passed": bool(passed),
        "grid": [per_axis] * len(lo),
        "box_lo": np.asarray(lo, float).tolist(),
        "box_hi": np.asarray(hi, float).tolist(),
        "tolerance": float(tolerance),
        "learned_steps": int(learned_steps),
        "euler_substeps": int(field.substeps),
        "learned": asdict(learned),
        "euler": asdict(euler),
        "max_speed_per_learned_step": float(np.max(speed)),
        "max_speed_per_raw_sample": float(np.max(speed) / field.substeps),
        "rho": rho,
        "goal_fixed_point_err": fixed,
        "field_sha256": field_digest(field),
    }
    return cert, failing


def certificate_ok(field: FlowField) -> tuple[bool, str]:
    """Whether ``field`` carries a passed certificate that belongs to it, and why not if it does not.

    For the guidance service: refuse to run an uncertified model unless its config allows it.
    """
    cert = field.meta.get("certificate")
    if not isinstance(cert, dict):
        return False, "the model file carries no convergence certificate (trained before certificates?)"
    if not cert.get("passed"):
        learned, euler = cert.get("learned", {}), cert.get("euler", {})
        return False, (
            f"the model failed its convergence certificate: learned steps "
            f"{learned.get('converged')}/{learned.get('starts')}, euler "
            f"{euler.get('converged')}/{euler.get('starts')} starts reached the goal"
        )
    if cert.get("field_sha256") != field_digest(field):
        return False, "the certificate does not match this model's weights (edited after training?)"
    rho = field.spectral_radius()
    if not rho < 1.0:
        return False, f"spectral radius of K is {rho:.4f} >= 1"
    return True, (
        f"certified: {cert['learned']['converged']}/{cert['learned']['starts']} grid starts converge "
        f"for both integrators (worst end distance "
        f"{max(cert['learned']['worst_end_distance'], cert['euler']['worst_end_distance']):.3g})"
    )


def summary_lines(cert: dict) -> list[str]:
    """The certificate as a few human-readable lines (``koopguide eval``)."""
    grid = "x".join(str(n) for n in cert["grid"])
    lines = [
        f"certificate  {'PASSED' if cert['passed'] else 'FAILED'}  ({grid} grid over "
        f"{[round(v, 2) for v in cert['box_lo']]} .. {[round(v, 2) for v in cert['box_hi']]}, "
        f"tolerance {cert['tolerance']:g})"
    ]
    for name, label in (
        ("learned", f"{cert['learned_steps']} learned steps"),
        ("euler", f"Euler, {cert['learned_steps'] * cert['euler_substeps']} raw steps"),
    ):
        o = cert[name]
        lines.append(
            f"  {label:<26} {o['converged']}/{o['starts']} converged, worst end distance {o['worst_end_distance']:.3g}"
        )
    lines.append(
        f"  max |velocity| over the box {cert['max_speed_per_learned_step']:.3g} per learned step "
        f"({cert['max_speed_per_raw_sample']:.3g} per raw sample)"
    )
    return lines


@dataclass(frozen=True)
class FunnelSettings:
    """How the Lyapunov limit is built and certified (``limit`` and ``certificate`` in train.yaml)."""

    outside: Annotated[
        float, Range(0.0, 1.0, lo_open=True, hi_open=True)
    ]  # ratio |f~(x) - g| / |x - g| allowed away from the demonstrations (< 1)
    tube_width: Annotated[
        float, Range(0.0, 1.0)
    ]  # fraction of the demonstrations' box diagonal: where the fit is left alone
    margin: Annotated[
        float, Range(0.0, 1.0)
    ]  # relative and absolute slack over the learned field's own ratio on the demos
    table_nodes: Annotated[int, Range(16, 1 << 20)]  # total nodes of the ratio table (per axis: its d-th root)
    table_enlarge: Annotated[
        float, Range(0.0, 2.0)
    ]  # the table covers the demos' box, each side moved out by this fraction
    grid: Annotated[
        int, Range(100, 2000)
    ]  # certificate starts per axis in 2-D; in d dimensions ceil(grid^(2/d)) per axis (>= grid^2 starts)
    enlarge: Annotated[float, Range(0.0, 2.0)]  # certificate box: the demos' box, each side moved out by this fraction
    tolerance: Annotated[
        float, Range(0.0, 1e9, lo_open=True, hi_open=True)
    ]  # model units: a start converges if it ends this close to the goal
    learned_steps: Annotated[
        int, Range(1, 100000)
    ]  # horizon of the learned-step integrator (x 'substeps' raw Euler steps)
    repairs: Annotated[int, Range(0, 20)]  # carve-and-recertify rounds before falling back to global contraction

    def __post_init__(self) -> None:
        check(
            self.enlarge <= self.table_enlarge,
            "convergence.enlarge",
            self.enlarge,
            f"<= table_enlarge ({self.table_enlarge})",
        )


def enlarged_box(bounds: tuple[np.ndarray, np.ndarray], per_side: float) -> tuple[np.ndarray, np.ndarray]:
    """The box ``bounds`` with each side moved out by ``per_side`` of its length."""
    lo, hi = (np.asarray(v, dtype=np.float64) for v in bounds)
    return lo - per_side * (hi - lo), hi + per_side * (hi - lo)


def certify_and_repair(
    field: FlowField, samples: np.ndarray, bounds: tuple[np.ndarray, np.ndarray], cfg: FunnelSettings
) -> tuple[FlowField, dict]:
    """Fit the Lyapunov limit to ``field``, certify it, and repair failures until it passes.

    Repairs carve the limit down to ``outside`` around the tails of the failing trajectories (where they
    stall); after ``cfg.repairs`` rounds the limit becomes ``outside`` everywhere, a global contraction
    that passes by construction (``|x_k - g| <= outside^k |x_0 - g|``). The certificate records the rounds.
    """
    from koopguide.model import lyapunov

    lo_t, hi_t = enlarged_box(bounds, cfg.table_enlarge)
    per_axis = max(2, round(cfg.table_nodes ** (1.0 / field.dim)))
    width = cfg.tube_width * float(np.linalg.norm(bounds[1] - bounds[0]))
    limit = lyapunov.build_limit(
        field.learned_step, samples, field.goal, lo_t, hi_t, (per_axis,) * field.dim, cfg.outside, width, cfg.margin
    )
    lo_c, hi_c = enlarged_box(bounds, cfg.enlarge)
    rounds: list[dict] = []
    per_axis_c = math.ceil(cfg.grid ** (2.0 / field.dim) - 1e-9)
    X0 = grid_starts(lo_c, hi_c, per_axis_c)
    limited = field
    for attempt in range(cfg.repairs + 2):
        limited = limited.with_limit(limit)
        final = attempt == cfg.repairs + 1
        learned_run = None
        if not final:  # the cheap integrator first: no need to run Euler on a limit about to be repaired
            learned_run = run_to_goal(limited, X0, "learned", cfg.learned_steps, cfg.tolerance)
            failing = X0[learned_run[0] > cfg.tolerance]
            if len(failing):
                rounds.append({"learned": int(len(X0) - len(failing)), "euler": None})
        if final or not len(failing):
            cert, failing = certify_detail(
                limited, lo_c, hi_c, per_axis_c, cfg.tolerance, cfg.learned_steps, 0.01, learned_run
            )
            rounds.append({"learned": cert["learned"]["converged"], "euler": cert["euler"]["converged"]})
            if cert["passed"] or final:
                break
        if attempt == cfg.repairs:
            limit = lyapunov.contracting(limit)
            continue
        tails = limited.rollout(failing, cfg.learned_steps)[:, cfg.learned_steps // 2 :].reshape(-1, field.dim)
        limit = lyapunov.carve(limit, tails, width)
    cert["repairs"] = rounds
    cert["tube_width"] = width
    return limited, cert
