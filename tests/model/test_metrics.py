import numpy as np
import pytest
import shapely
from dtw import dtw as dtw_python

from koopguide.base import data
from koopguide.model.evaluate import convergence_box, dtw_distance, evaluate, swept_error_area


def test_sea_of_a_unit_square_strip_is_its_area():
    demo = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    rep = np.array([[0.0, 1.0], [1.0, 1.0], [2.0, 1.0]])
    assert swept_error_area(demo, rep) == pytest.approx(2.0)


def test_sea_vertex_order_walks_the_boundary_not_a_bow_tie():
    # demo along x, reproduction crossing it: the quad (d0, d1, r1, r0) is a proper quadrilateral
    demo = np.array([[0.0, 0.0], [2.0, 0.0]])
    rep = np.array([[0.0, 1.0], [2.0, 2.0]])
    assert swept_error_area(demo, rep) == pytest.approx(3.0)  # trapezoid with parallel sides 1 and 2, width 2
    # the wrong order (d0, d1, r0, r1) is a self-intersecting bow-tie whose signed halves cancel here
    x = np.array([0.0, 2.0, 0.0, 2.0])
    y = np.array([0.0, 0.0, 1.0, 2.0])
    bow_tie = abs(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)) / 2
    assert bow_tie == pytest.approx(0.0)


def test_dtw_hand_computed_case():
    a = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    b = np.array([[0.0, 1.0], [2.0, 1.0]])
    # cost matrix rows a, cols b: [[1, sqrt5], [sqrt2, sqrt2], [sqrt5, 1]]; best path (0,0)->(1,0)->(2,1)
    assert dtw_distance(a, b) == pytest.approx(1 + np.sqrt(2) + 1)
    assert dtw_distance(a, a) == 0.0


def test_dtw_of_angle_demo_0_vs_demo_1_is_the_known_figure():
    demos = data.load_lasa("Angle")
    assert dtw_distance(demos.trajectories[0], demos.trajectories[1]) == pytest.approx(2006.13, abs=0.01)


def independent_sea(demo: np.ndarray, rep: np.ndarray) -> float:
    """SEA by shapely polygons, each quad built from the same vertex walk."""
    total = 0.0
    for t in range(len(demo) - 1):
        quad = shapely.Polygon([demo[t], demo[t + 1], rep[t + 1], rep[t]])
        total += abs(shapely.area(shapely.Polygon(quad.exterior.coords))) if quad.is_valid else _shoelace(quad)
    return total


def _shoelace(poly: shapely.Polygon) -> float:
    xy = np.asarray(poly.exterior.coords)[:-1]
    x, y = xy[:, 0], xy[:, 1]
    return abs(float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))) / 2


def test_eval_numbers_agree_with_independent_implementations(small_trained, zshape):
    from koopguide.model.field import FlowField

    t = small_trained
    # float64 throughout: the float32 Fourier block rounds one point and a batch differently (~1e-8)
    field = FlowField(t.W, t.b, t.A, t.B, t.goal, t.goal_centred, t.substeps, precision="float64")
    metrics = evaluate(field, zshape, starts=50)
    # independent reproduction: a plain Python loop of Euler steps, velocity / substeps
    reps = []
    for traj in zshape.trajectories:
        x, path = traj[0].copy(), [traj[0].copy()]
        for _ in range(len(traj) - 1):
            x = x + (field.step(x) - x) / field.substeps
            path.append(x.copy())
        reps.append(np.array(path))
    sea = np.mean([independent_sea(d, r) for d, r in zip(zshape.trajectories, reps, strict=True)])
    dtwd = np.mean(
        [dtw_python(d, r, step_pattern="symmetric1").distance for d, r in zip(zshape.trajectories, reps, strict=True)]
    )
    assert metrics["sea"] == pytest.approx(sea, rel=0.05)
    assert metrics["dtwd"] == pytest.approx(dtwd, rel=0.05)
    assert metrics["sea"] == pytest.approx(sea, rel=1e-9)  # in fact they agree to rounding
    assert metrics["dtwd"] == pytest.approx(dtwd, rel=1e-9)


def test_convergence_box_moves_each_side_out_by_ten_percent_about_the_centre():
    lo, hi = convergence_box((np.array([-40.0, 0.0]), np.array([0.0, 50.0])), 0.10)
    np.testing.assert_allclose(hi - lo, [48.0, 60.0])
    np.testing.assert_allclose((hi + lo) / 2, [-20.0, 25.0])


def test_batched_dtw_equals_dtw_python_pair_by_pair():
    from koopguide.model.evaluate import dtw_distances

    rng = np.random.default_rng(4)
    for n, m in ((1, 5), (9, 4), (30, 30)):
        a, b = rng.normal(size=(3, n, 2)).cumsum(axis=1), rng.normal(size=(3, m, 2)).cumsum(axis=1)
        expected = [dtw_python(x, y, step_pattern="symmetric1").distance for x, y in zip(a, b, strict=True)]
        np.testing.assert_allclose(dtw_distances(a, b), expected, rtol=1e-12)
