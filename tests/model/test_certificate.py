"""The Lyapunov limit, the query grid and the convergence certificate (numpy side; no training needed)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import RegularGridInterpolator

from koopguide.model.certificate import (
    FunnelSettings,
    certificate_ok,
    certify,
    certify_and_repair,
    run_to_goal,
)
from koopguide.model.field import FlowField
from koopguide.model.grid_table import GridTable
from koopguide.model.lyapunov import RatioLimit, contracting, limit_step

SETTINGS = FunnelSettings(
    outside=0.9,
    tube_width=0.06,
    margin=0.1,
    table_nodes=4096,
    table_enlarge=0.25,
    grid=100,
    enlarge=0.10,
    tolerance=1.0,
    learned_steps=100,
    repairs=2,
)


def slow_field(goal=(0.0, 0.0), nu=16, rank=4, substeps=10) -> FlowField:
    """A goal-centred field whose learned step is almost the identity, ``f(x) = g + 0.995 (x - g)``:
    stable (rho 0.995) but far too slow to reach the goal in 100 steps from anywhere far."""
    d = len(goal)
    A = np.zeros((nu + d, rank))
    B = np.zeros((nu + d, rank))
    A[:d, :d] = 0.995 * np.eye(d)
    B[:d, :d] = np.eye(d)
    rng = np.random.default_rng(0)
    return FlowField(rng.normal(0, 0.05, (nu, d)), rng.random(nu), A, B, np.asarray(goal, float), True, substeps)


@pytest.mark.parametrize("dim", [2, 3])
def test_grid_table_matches_scipy_and_reproduces_affine_maps(dim):
    rng = np.random.default_rng(dim)
    shape = (7, 5, 4)[:dim]
    lo, hi = -rng.random(dim) * 10, rng.random(dim) * 10 + 1
    values = rng.normal(size=(*shape, 2))
    table = GridTable(lo, hi, values)
    X = lo + (hi - lo) * rng.random((300, dim))
    axes = [np.linspace(lo[k], hi[k], n) for k, n in enumerate(shape)]
    np.testing.assert_allclose(table.at(X), RegularGridInterpolator(axes, values)(X), atol=1e-12)
    np.testing.assert_allclose(table.at_one(X[0]), table.at(X[:1])[0], atol=1e-12)
    M, c = rng.normal(size=(dim, 2)), rng.normal(size=2)
    affine = GridTable(lo, hi, (table.nodes() @ M + c).reshape(*shape, 2))
    np.testing.assert_allclose(affine.at(X), X @ M + c, atol=1e-9)
    assert table.inside(X) is None and table.at_one(hi + 1) is None
    assert table.inside(np.vstack([X, hi + 1]))[-1] == np.False_


@settings(max_examples=60, deadline=None)
@given(
    x=st.lists(st.floats(-100, 100), min_size=2, max_size=2),
    y=st.lists(st.floats(-100, 100), min_size=2, max_size=2),
    gamma=st.floats(0.0, 2.0),
    h=st.floats(1e-3, 1.0),
)
def test_limited_step_contracts_for_both_integrators(x, y, gamma, h):
    goal = np.array([3.0, -2.0])
    X, Y = np.array([x]), np.array([y])
    out = limit_step(X, Y, goal, np.array([gamma]))
    e = np.linalg.norm(X - goal)
    assert np.linalg.norm(out - goal) <= gamma * e + 1e-9
    if np.linalg.norm(Y - goal) <= gamma * e:
        np.testing.assert_allclose(out, Y, rtol=1e-12, atol=1e-9)  # never changes a complying step
    euler = X + h * (out - X)  # KoopMotion's Euler step of velocity / substeps, h = 1 / substeps
    assert np.linalg.norm(euler - goal) <= (1.0 - h * (1.0 - gamma)) * e + 1e-9


def test_slow_field_is_repaired_until_every_grid_start_converges():
    field = slow_field()
    lo, hi = np.array([-40.0, -30.0]), np.array([10.0, 20.0])
    t = np.linspace(0, 1, 200)[:, None]
    samples = np.array([-35.0, 15.0]) * (1 - t)  # a "demonstration" along which the identity is kept
    raw_end, _ = run_to_goal(field, np.array([[-20.0, 10.0], [5.0, -5.0]]), "learned", 100, 1.0)
    assert np.all(raw_end > 2.0)  # far from the goal after 100 steps without the limit
    certified, cert = certify_and_repair(field, samples, (lo, hi), SETTINGS)
    assert cert["passed"] and cert["grid"] == [100, 100]
    assert cert["learned"]["converged"] == cert["euler"]["converged"] == 10000
    assert len(cert["repairs"]) >= 2 and cert["repairs"][0]["learned"] < 10000  # it had to repair
    assert cert["learned"]["worst_end_distance"] <= 1.0 and cert["euler"]["worst_end_distance"] <= 1.0
    certified.meta["certificate"] = cert
    ok, reason = certificate_ok(certified)
    assert ok, reason


def test_global_contraction_passes_by_construction_and_the_early_exit_bound_is_sound():
    field = slow_field(goal=(1.0, 2.0, -1.0), substeps=8)
    lo, hi = np.array([-20.0, -10.0, -15.0]), np.array([20.0, 25.0, 10.0])
    limit = contracting(RatioLimit(lo=lo - 5, hi=hi + 5, table=np.full((6, 6, 6), 0.5), outside=0.85))
    limited = field.with_limit(limit)
    cert = certify(limited, lo, hi, per_axis=12)
    assert cert["passed"] and cert["learned"]["converged"] == 12**3
    X0 = np.random.default_rng(0).uniform(lo, hi, (50, 3))
    for integrator, substeps in (("learned", None), ("euler", 8)):
        bound, _ = run_to_goal(limited, X0, integrator, 100, 1.0)
        n = 100 if substeps is None else 800
        exact = np.linalg.norm(limited.rollout(X0, n, substeps=substeps)[:, -1] - limited.goal, axis=1)
        assert np.all(exact <= bound + 1e-9) and np.all(bound <= 1.0)


def test_certificate_ok_explains_what_is_wrong():
    field = slow_field()
    assert certificate_ok(field) == (
        False,
        "the model file carries no convergence certificate (trained before certificates?)",
    )
    limit = RatioLimit(lo=np.array([-50.0, -50.0]), hi=np.array([50.0, 50.0]), table=np.full((5, 5), 0.8), outside=0.8)
    limited = field.with_limit(limit)
    cert = certify(limited, np.array([-40.0, -40.0]), np.array([40.0, 40.0]), per_axis=100)
    limited.meta["certificate"] = cert
    assert certificate_ok(limited)[0]
    tampered = FlowField(
        field.W,
        field.b * 1.01,
        field.A,
        field.B,
        field.goal,
        True,
        field.substeps,
        meta={"certificate": cert},
        limit=limit,
    )
    ok, reason = certificate_ok(tampered)
    assert not ok and "does not match this model's weights" in reason
    failed = dict(cert, passed=False, learned={**cert["learned"], "converged": 9000})
    limited.meta["certificate"] = failed
    ok, reason = certificate_ok(limited)
    assert not ok and "learned steps 9000/10000" in reason
