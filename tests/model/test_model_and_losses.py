import math

import numpy as np
import pytest
import torch

from koopguide.model.learn import losses, trainer
from koopguide.model.learn.model import FourierKoopman


def make_model(goal_centred: bool, seed: int = 0, nu: int = 64, rank: int = 8) -> FourierKoopman:
    gen = torch.Generator().manual_seed(seed)
    goal = torch.tensor([1.5, -2.0], dtype=torch.float64)
    model = FourierKoopman(2, nu, rank, goal, goal_centred, gen)
    with torch.no_grad():  # larger frequencies than Xavier so the features really curve over [-10, 10]
        model.W.mul_(8.0)
    return model


@torch.no_grad()
def next_state_fd_trace(model: FourierKoopman, x: torch.Tensor, h: float = 1e-6) -> torch.Tensor:
    out = []
    for p in x:
        tr = 0.0
        for i in range(model.dim):
            e = torch.zeros(model.dim, dtype=x.dtype)
            e[i] = h
            fp = model.step((p + e)[None])[0, i]
            fm = model.step((p - e)[None])[0, i]
            tr += float((fp - fm) / (2 * h))
        out.append(tr)
    return torch.tensor(out, dtype=x.dtype)


@pytest.mark.parametrize("goal_centred", [False, True])
def test_analytic_jacobian_trace_matches_finite_differences(goal_centred):
    model = make_model(goal_centred)
    x = torch.tensor([[0.3, -4.0], [7.5, 2.2], [-9.0, 9.0]], dtype=torch.float64)
    np.testing.assert_allclose(model.jacobian_trace(x).detach(), next_state_fd_trace(model, x), rtol=1e-6, atol=1e-6)


def test_divergence_loss_of_field_is_trace_minus_dimension():
    model = make_model(False)
    x = torch.tensor([[1.0, 2.0], [3.0, -1.0]], dtype=torch.float64)
    trace = model.jacobian_trace(x)
    field = losses.divergence_loss(model, x, losses.DivergenceOf.FIELD)
    nxt = losses.divergence_loss(model, x, losses.DivergenceOf.NEXT_STATE)
    assert field.item() == pytest.approx(torch.mean((trace - 2) ** 2).item())
    assert nxt.item() == pytest.approx(torch.mean(trace**2).item())


def test_goal_centred_lifting_makes_the_goal_an_exact_fixed_point_for_any_weights():
    model = make_model(True, seed=3)
    g = model.goal
    assert torch.equal(model.lift(g), torch.zeros(1, 2 + model.nu, dtype=torch.float64))
    assert torch.allclose(model.step(g), g, atol=0, rtol=0)
    assert losses.goal_loss(model).item() == 0.0


def test_pair_losses_are_koopman_linearity_and_state_prediction():
    model = make_model(False)
    x = torch.tensor([[0.0, 1.0], [2.0, -3.0]], dtype=torch.float64)
    y = x + 0.5
    k, s = losses.pair_losses(model, x, y)
    lifted_residual = model.lift(y) - (model.lift(x) @ model.B) @ model.A.T
    assert k.item() == pytest.approx(torch.mean(lifted_residual**2).item())
    assert s.item() == pytest.approx(torch.mean((model.step(x) - y) ** 2).item())


def test_multistep_loss_with_horizon_one_equals_the_koopman_loss():
    model = make_model(True)
    w = torch.tensor([[[0.0, 1.0], [0.5, 0.7]], [[3.0, 3.0], [2.0, 2.5]]], dtype=torch.float64)
    assert losses.multistep_loss(model, w).item() == pytest.approx(losses.koopman_loss(model, w[:, 0], w[:, 1]).item())


def test_spectral_projection_caps_rho_and_leaves_inner_eigenvalues_alone():
    rng = np.random.default_rng(0)
    A, B = rng.normal(size=(40, 6)), rng.normal(size=(40, 6)) * 0.5
    lam = np.linalg.eigvals(B.T @ A)
    assert np.abs(lam).max() > 1.0
    A2 = trainer.project_spectrum(A, B, 0.9)
    lam2 = np.linalg.eigvals(B.T @ A2)
    assert np.abs(lam2).max() == pytest.approx(0.9, abs=1e-9)
    inside = np.sort_complex(lam[np.abs(lam) <= 0.9])
    kept = np.sort_complex(lam2[np.abs(lam2) < 0.9 - 1e-9])
    np.testing.assert_allclose(kept, inside, atol=1e-8)
    assert trainer.project_spectrum(A2, B, 0.95) is A2  # already inside: unchanged


def test_training_is_deterministic_for_a_seed_and_differs_across_seeds(zshape):
    from tests.support.models import small_config

    cfg = small_config(optim={"steps": 60}, convergence=None)  # weights only: no certificate needed
    a = trainer.train(zshape, cfg, seed=5)
    b = trainer.train(zshape, cfg, seed=5)
    c = trainer.train(zshape, cfg, seed=6)
    for name in ("W", "b", "A", "B"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert not np.array_equal(a.A, c.A)


def test_invalid_training_settings_are_refused_at_load_with_the_values():
    from koopguide.base.config import ConfigError
    from tests.support.models import small_config

    with pytest.raises(
        ConfigError, match=r"stability.max_spectral_radius: 1.5 is out of range \(expected a number in \(0, 1\)\)"
    ):
        small_config(stability={"max_spectral_radius": 1.5})
    with pytest.raises(ConfigError, match=r"optim.lr: -1.0 is out of range \(expected a number in \(0, 10\]\)"):
        small_config(optim={"lr": -1.0})
    with pytest.raises(
        ConfigError, match=r"convergence.grid: 50 is out of range \(expected a number in \[100, 2000\]\)"
    ):
        small_config(convergence={"grid": 50})
    with pytest.raises(
        ConfigError, match=r"convergence.outside: 1.0 is out of range \(expected a number in \(0, 1\)\)"
    ):
        small_config(convergence={"outside": 1.0})


def test_xavier_bounds_as_reference():
    model = make_model(False, nu=100, rank=4)
    bound = math.sqrt(6.0 / (102 + 4))
    assert model.A.abs().max().item() <= bound


def test_multistep_training_path_runs_and_reports_its_term(zshape):
    from tests.support.models import small_config

    cfg = small_config(
        model={"nu": 64, "rank": 8}, optim={"steps": 20}, loss={"horizon": 4, "multistep": 0.5}, convergence=None
    )
    seen = []
    t = trainer.train(zshape, cfg, seed=0, progress=lambda k, n, terms: seen.append(terms), progress_every=10)
    assert len(seen) == 2 and all("multistep" in terms and terms["multistep"] > 0 for terms in seen)
    assert np.all(np.isfinite(t.A)) and t.info["rho"] <= 0.995 + 1e-9


@pytest.mark.parametrize("goal_centred", [True, False])
@pytest.mark.parametrize("of", list(losses.DivergenceOf))
@pytest.mark.parametrize("goal_weight", [0.0, 0.3])
def test_hand_written_gradient_equals_autograd_of_the_losses(goal_centred, of, goal_weight):
    from koopguide.model.learn.gradients import FlatParams, LossWeights, loss_and_gradient

    model = make_model(goal_centred, seed=2)
    gen = torch.Generator().manual_seed(7)
    x = 4.0 * torch.randn((6, 2), generator=gen, dtype=torch.float64)
    y = x + 0.5 * torch.randn((6, 2), generator=gen, dtype=torch.float64)
    pts = 4.0 * torch.randn((3, 2), generator=gen, dtype=torch.float64)
    w = LossWeights(koopman=1.0, state=0.2, divergence=0.05, goal=goal_weight, divergence_of=of)
    k, s = losses.pair_losses(model, x, y)
    expected = w.koopman * k + w.state * s + w.divergence * losses.divergence_loss(model, pts, of)
    if not goal_centred and goal_weight > 0:
        expected = expected + goal_weight * losses.goal_loss(model)
    expected.backward()
    flat = FlatParams(*(t.detach().clone() for t in (model.W, model.b, model.A, model.B)))
    loss, terms = loss_and_gradient(flat, model.goal, goal_centred, x, y, pts, w)
    assert loss.item() == pytest.approx(expected.item(), rel=1e-12)
    assert terms["koopman"].item() == pytest.approx(k.item(), rel=1e-12)
    for mine, name in zip((flat.gW, flat.gb, flat.gA, flat.gB), "WbAB", strict=True):
        ref = getattr(model, name).grad
        assert ref.abs().max() > 1e-6  # every parameter really receives a gradient here
        np.testing.assert_allclose(mine, ref, rtol=1e-10, atol=1e-12 * float(ref.abs().max()))


def test_flat_adamw_matches_torch_adamw():
    from koopguide.model.learn.gradients import AdamW

    gen = torch.Generator().manual_seed(0)
    p0 = torch.randn(50, generator=gen, dtype=torch.float64)
    grads = [torch.randn(50, generator=gen, dtype=torch.float64) for _ in range(5)]
    mine, ref = p0.clone(), torch.nn.Parameter(p0.clone())
    opt_mine = AdamW(mine, lr=0.01, weight_decay=0.1)
    opt_ref = torch.optim.AdamW([ref], lr=0.01, weight_decay=0.1)
    for g in grads:
        opt_mine.step(g)
        ref.grad = g.clone()
        opt_ref.step()
    np.testing.assert_allclose(mine, ref.detach(), rtol=1e-12, atol=1e-14)
