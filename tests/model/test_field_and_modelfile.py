import pickle
import subprocess
import sys
import zipfile

import numpy as np
import pytest
import torch

import koopguide
from koopguide import ModelFileError
from koopguide.base import modelfile
from koopguide.model.learn.export import save
from koopguide.model.learn.model import FourierKoopman
from tests.support.models import small_config


@pytest.fixture(scope="module")
def saved(tmp_path_factory, small_trained, zshape):
    path = tmp_path_factory.mktemp("m") / "zshape.pt"
    save(path, small_trained, zshape, small_config())
    return path


def test_round_trip_and_numpy_field_matches_the_torch_model(saved, small_trained):
    field = koopguide.load_field(saved)
    assert field.dim == 2 and field.substeps == 40 and field.nu == 256 and field.rank == 16
    np.testing.assert_array_equal(field.goal, small_trained.goal)
    model = FourierKoopman(2, 256, 16, torch.as_tensor(small_trained.goal), True, torch.Generator())
    with torch.no_grad():
        for name in ("W", "b", "A", "B"):
            getattr(model, name).copy_(torch.as_tensor(getattr(small_trained, name)))
    X = np.random.default_rng(1).uniform(-50, 50, (64, 2))
    expected = model.step(torch.as_tensor(X)).detach().numpy()
    exact = koopguide.FlowField(field.W, field.b, field.A, field.B, field.goal, True, 40, precision="float64")
    np.testing.assert_allclose(exact.step(X), expected, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(field.learned_step(X), expected, atol=1e-4)  # float32 Fourier block
    # the certified field is the Lyapunov-limited step: never farther from the goal than gamma(x) |x - g|
    gamma = field.limit.ratio(X)
    dist = np.linalg.norm(X - field.goal, axis=1)
    assert np.all(np.linalg.norm(field.step(X) - field.goal, axis=1) <= gamma * dist + 1e-9)
    free = np.linalg.norm(expected - field.goal, axis=1) < 0.95 * gamma * dist  # where the limit does not bind
    np.testing.assert_allclose(field.step(X)[free], expected[free], atol=0.1)  # table error only
    assert free.sum() > 10


def test_torch_reads_the_file_with_weights_only(saved):
    payload = torch.load(saved, weights_only=True)
    assert payload["format"] == "koopguide-field" and payload["format_version"] == 2
    weights, meta = modelfile.read(saved)
    for name, arr in weights.items():
        np.testing.assert_array_equal(payload["weights"][name].numpy(), arr)
    assert meta["data"]["source"] == "lasa:Zshape" and len(meta["data"]["sha256"]) == 64
    assert meta["hyperparameters"]["model"]["nu"] == 256


def test_queries_accept_one_state_or_a_batch(saved):
    field = koopguide.load_field(saved)
    x = np.array([-30.0, 40.0])
    assert field.step(x).shape == (2,)
    assert field.step(np.stack([x, x])).shape == (2, 2)
    np.testing.assert_allclose(field.velocity(x), field.step(x) - x)
    X = np.random.default_rng(3).uniform(-60, 60, (50, 2))  # inside and outside the query table
    batch = field.velocity(X)
    np.testing.assert_allclose(np.array([field.velocity(p) for p in X]), batch, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match=r"expected a state of shape \(2,\) or \(N, 2\), got \(3,\)"):
        field.step(np.zeros(3))


def test_rollouts_euler_and_koopman(saved):
    field = koopguide.load_field(saved)
    x0 = np.array([[-30.0, 40.0], [10.0, 5.0]])
    whole = field.rollout(x0, 3)
    assert whole.shape == (2, 4, 2)
    np.testing.assert_allclose(whole[:, 1], field.step(x0))
    np.testing.assert_allclose(whole[:, 2], field.step(field.step(x0)))
    fine = field.rollout(x0, 40, substeps=40)
    np.testing.assert_allclose(fine[:, 1], x0 + field.velocity(x0) / 40)
    koop = field.rollout(x0, 5, method="koopman")
    np.testing.assert_allclose(koop[:, 1], field.learned_step(x0), atol=1e-4)  # the same map, before the limit
    # the linear lifted system is stable: a long Koopman rollout decays onto the goal
    far = field.rollout(x0, 3000, method="koopman")[:, -1]
    np.testing.assert_allclose(far, np.broadcast_to(field.goal, far.shape), atol=1e-6)
    with pytest.raises(ValueError, match="unknown rollout method 'rk4'"):
        field.rollout(x0, 2, method="rk4")
    with pytest.raises(ValueError, match="substeps must be a positive integer, got 0"):
        field.rollout(x0, 2, substeps=0)


def test_eigenvalues_are_the_full_spectrum_of_K(saved):
    field = koopguide.load_field(saved)
    lam = field.eigenvalues()
    assert lam.shape == (field.nu + 2,) and np.iscomplexobj(lam)
    K = field.A @ field.B.T
    dense = np.linalg.eigvals(K)
    top = np.sort(np.abs(dense))[::-1][: field.rank]
    np.testing.assert_allclose(np.abs(lam[: field.rank]), top, rtol=1e-6, atol=1e-9)
    assert np.abs(lam).max() < 1.0


def test_query_side_does_not_import_torch(saved):
    code = (
        "import sys, koopguide; f = koopguide.load_field(sys.argv[1]); f.velocity(f.goal + 1); "
        "print('torch' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code, str(saved)], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_corrupt_truncated_wrong_kind_and_newer_files_are_refused(tmp_path, saved):
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"\x00\x01 definitely not a model" * 10)
    with pytest.raises(ModelFileError, match="not a torch zip archive"):
        koopguide.load_field(garbage)

    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(saved.read_bytes()[: saved.stat().st_size // 2])
    with pytest.raises(ModelFileError, match=str(truncated)):
        koopguide.load_field(truncated)

    other = tmp_path / "other.pt"
    torch.save({"state_dict": {"w": torch.zeros(3)}}, other)
    with pytest.raises(ModelFileError, match="wrong kind of file"):
        koopguide.load_field(other)

    weights, meta = modelfile.read(saved)
    newer = tmp_path / "newer.pt"
    torch.save(
        {
            "format": "koopguide-field",
            "format_version": 99,
            "weights": {k: torch.as_tensor(v) for k, v in weights.items()},
            "meta": meta,
        },
        newer,
    )
    with pytest.raises(ModelFileError, match="format version 99 is newer"):
        koopguide.load_field(newer)

    mismatched = tmp_path / "mismatched.pt"
    modelfile.write(mismatched, {**weights, "A": weights["A"][:, :3]}, meta)
    with pytest.raises(ModelFileError, match=r"weight A has shape \(258, 3\), expected \(258, 16\)"):
        koopguide.load_field(mismatched)

    with pytest.raises(ModelFileError, match="model file not found"):
        koopguide.load_field(tmp_path / "nope.pt")


class _Evil:
    def __reduce__(self):
        return (print, ("pwned",))


def test_arbitrary_pickled_objects_are_refused_not_executed(tmp_path):
    path = tmp_path / "evil.pt"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("evil/data.pkl", pickle.dumps({"format": "koopguide-field", "x": _Evil()}))
    with pytest.raises(ModelFileError, match=r"refusing to load builtins\.print"):
        koopguide.load_field(path)


class _RawTensor:
    """Pickles as torch's tensor rebuild call with any offset, size and stride (as a hostile file could)."""

    def __init__(self, numel: int, size: tuple, stride: tuple, offset: int = 0) -> None:
        self.storage = torch.arange(float(numel), dtype=torch.float64).untyped_storage()
        self.size, self.stride, self.offset = size, stride, offset

    def __reduce__(self):
        import collections

        typed = torch.storage.TypedStorage(wrap_storage=self.storage, dtype=torch.float64, _internal=True)
        return (
            torch._utils._rebuild_tensor_v2,
            (typed, self.offset, self.size, self.stride, False, collections.OrderedDict()),
        )


def _with_weight(tmp_path, saved, name: str, tensor) -> object:
    weights, meta = modelfile.read(saved)
    payload = {
        "format": "koopguide-field",
        "format_version": 1,
        "weights": {k: torch.as_tensor(v) for k, v in weights.items()},
        "meta": meta,
    }
    payload["weights"][name] = tensor
    path = tmp_path / f"hostile_{name}.pt"
    torch.save(payload, path)
    return path


def test_negative_stride_tensor_is_refused_without_crashing(tmp_path, saved):
    path = _with_weight(tmp_path, saved, "b", _RawTensor(256, (256,), (-1,), offset=255))
    code = (
        "import sys, koopguide\n"
        "try:\n    koopguide.load_field(sys.argv[1])\n"
        "except koopguide.ModelFileError as e:\n    print(e)"
    )
    out = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr  # a segfault would be -11
    assert "invalid offset 255, size (256,) or stride (-1,)" in out.stdout


def test_huge_stride_zero_tensor_is_refused_before_allocating(tmp_path, saved):
    path = _with_weight(tmp_path, saved, "W", _RawTensor(4, (1_000_000, 1_000_000), (0, 0)))
    with pytest.raises(ModelFileError, match=r"size \(1000000, 1000000\) \(1000000000000 elements\) exceeds"):
        koopguide.load_field(path)
    expanded = _with_weight(tmp_path, saved, "b", _RawTensor(256, (256,), (0,)))
    with pytest.raises(ModelFileError, match=r"zero stride \(0,\)"):
        koopguide.load_field(expanded)


@pytest.mark.parametrize(
    ("entry", "value", "message"),
    [
        ("goal", [float("nan"), 0.0], r"goal holds non-finite values \[nan, 0.0\]"),
        ("bounds_lo", [-40.0, float("inf")], r"bounds_lo holds non-finite values \[-40.0, inf\]"),
        ("bounds_hi", [float("nan"), 3.0], r"bounds_hi holds non-finite values"),
        ("bounds_hi", None, r"bounds_hi has shape \(\), expected \(2,\)"),
        ("goal", [0.0, 0.0, 0.0], r"goal has shape \(3,\), expected \(2,\)"),
        ("substeps", 0, r"substeps must be an integer in \[1, 1000000\], got 0"),
        ("nu", -3, r"nu must be an integer in \[1, 65536\], got -3"),
    ],
)
def test_non_finite_or_inconsistent_metadata_is_refused(tmp_path, saved, entry, value, message):
    weights, meta = modelfile.read(saved)
    path = tmp_path / "bad_meta.pt"
    modelfile.write(path, weights, {**meta, entry: value})
    with pytest.raises(ModelFileError, match=message):
        koopguide.load_field(path)


def test_a_domain_with_lo_equal_to_hi_is_refused(tmp_path, saved):
    weights, meta = modelfile.read(saved)
    path = tmp_path / "flat.pt"
    modelfile.write(path, weights, {**meta, "bounds_lo": [-5.0, 2.0], "bounds_hi": [30.0, 2.0]})
    with pytest.raises(ModelFileError, match=r"lo < hi in every coordinate, got lo=\[-5.0, 2.0\] hi=\[30.0, 2.0\]"):
        koopguide.load_field(path)


def test_non_float_weights_are_refused(tmp_path, saved):
    path = _with_weight(tmp_path, saved, "b", torch.zeros(256, dtype=torch.int64))
    with pytest.raises(ModelFileError, match="weight b has dtype int64, expected floating point"):
        koopguide.load_field(path)


@pytest.mark.parametrize("dim", [2, 3])
def test_learned_step_on_a_grid_by_separable_phases_equals_the_pointwise_float64_map(dim):
    from koopguide.model.field import learned_step_on_grid

    rng = np.random.default_rng(dim)
    nu, rank = 96, 8
    field = koopguide.FlowField(
        rng.normal(scale=0.3, size=(nu, dim)),
        rng.normal(size=nu),
        rng.normal(scale=0.2, size=(nu + dim, rank)),
        rng.normal(scale=0.2, size=(nu + dim, rank)),
        goal=rng.normal(size=dim),
        goal_centred=True,
        substeps=40,
        precision="float64",
    )
    axes = [np.linspace(-20.0 + k, 15.0 - k, 7 + 2 * k) for k in range(dim)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, dim)
    np.testing.assert_allclose(learned_step_on_grid(field, axes), field.learned_step(nodes), rtol=0, atol=1e-10)
