import numpy as np
import pytest

from koopguide.base import data
from koopguide.base.data import DemoDataError


def test_all_30_lasa_shapes_load_with_7_demos_ending_at_the_origin():
    assert len(data.LASA_SHAPES) == 30
    for name in data.LASA_SHAPES:
        demos = data.load_lasa(name)
        assert len(demos.trajectories) == 7
        for traj in demos.trajectories:
            assert traj.shape == (1000, 2)
            assert np.allclose(traj[-1], 0.0)
            assert np.abs(traj).max() <= 50.0 + 1e-9


def test_unknown_lasa_shape_is_named_with_a_hint():
    with pytest.raises(DemoDataError, match="did you mean Zshape"):
        data.load_lasa("zshape")


def test_subsampling_every_40_gives_25_points_24_pairs_168_pairs_and_keeps_the_end():
    demos = data.load_lasa("Zshape")
    pts = data.subsample(demos.trajectories[0], 40)
    assert pts.shape == (25, 2)
    np.testing.assert_array_equal(pts[-1], demos.trajectories[0][-1])
    np.testing.assert_array_equal(pts[0], demos.trajectories[0][39])
    X, Y, last = data.pairs(demos, 40)
    assert X.shape == Y.shape == (168, 2)
    assert last.sum() == 7 and np.allclose(Y[last], 0.0)
    np.testing.assert_array_equal(X[1:24], Y[:23])  # consecutive pairs chain within a demo


def test_windows_chain_consecutive_subsampled_points():
    demos = data.load_lasa("Sine")
    W = data.windows(demos, 40, horizon=5)
    assert W.shape == (7 * (25 - 5), 6, 2)
    X, Y, _ = data.pairs(demos, 40)
    np.testing.assert_array_equal(W[0, 0], X[0])
    np.testing.assert_array_equal(W[0, 1], Y[0])


def test_csv_with_header_and_3d_npy_and_folder(tmp_path):
    t = np.linspace(0, 1, 200)
    traj3 = np.column_stack([np.cos(t), np.sin(t), t])
    (tmp_path / "a.csv").write_text("x,y,z\n" + "\n".join(",".join(f"{v:.6f}" for v in row) for row in traj3))
    np.save(tmp_path / "b.npy", np.stack([traj3, traj3 * 0.9]))
    demos = data.load_demos(tmp_path)
    assert demos.dim == 3 and len(demos.trajectories) == 3
    np.testing.assert_allclose(demos.trajectories[0], traj3, atol=1e-6)


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        ("1,2\n3,4,5\n6,7\n", "ragged row with 3 columns"),
        ("1,2\n3,nan\n5,6\n", "non-finite value nan at sample 1"),
        ("1\n2\n3\n", "dimension 1 < 2"),
        ("1,2\n", "too short: 1 sample"),
        ("1,2\n3,abc\n", "line 2: not a number"),
        ("", "empty file"),
    ],
)
def test_bad_csv_gets_one_clear_error_naming_the_file(tmp_path, content, problem):
    path = tmp_path / "demo.csv"
    path.write_text(content)
    with pytest.raises(DemoDataError, match=problem) as exc:
        data.load_demos(path)
    assert str(path) in str(exc.value)


def test_mixed_dimensions_across_files_are_refused(tmp_path):
    np.save(tmp_path / "a.npy", np.zeros((50, 2)))
    np.save(tmp_path / "b.npy", np.zeros((50, 3)))
    with pytest.raises(DemoDataError, match=r"b\.npy: has dimension 3.*a\.npy has dimension 2"):
        data.load_demos(tmp_path)


def test_too_short_for_subsampling_names_the_demo(tmp_path):
    np.save(tmp_path / "short.npy", np.cumsum(np.ones((30, 2)), axis=0))
    demos = data.load_demos(tmp_path / "short.npy")
    with pytest.raises(DemoDataError, match=r"too short: 30 samples, need >= 41"):
        data.pairs(demos, 40)


def test_unreadable_npy_and_missing_path(tmp_path):
    bad = tmp_path / "x.npy"
    bad.write_bytes(b"not numpy at all")
    with pytest.raises(DemoDataError, match=r"not a readable \.npy"):
        data.load_demos(bad)
    with pytest.raises(DemoDataError, match="no such file or folder"):
        data.load_demos(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DemoDataError, match=r"holds no \.csv or \.npy"):
        data.load_demos(tmp_path / "empty")
