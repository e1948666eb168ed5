"""The learning CLI end to end: real processes, real files, real LASA data, a short training budget."""

import json
import subprocess
import sys

import numpy as np
import pytest

SMALL = "model:\n  nu: 256\n  rank: 16\noptim:\n  steps: 300\n"


def koopguide(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "koopguide", *args], capture_output=True, text=True, cwd=cwd, timeout=300
    )


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cli")  # the shipped defaults: the full budget, a few seconds
    out = koopguide("train", "--lasa", "Sine", "-o", str(tmp / "sine.pt"), "--seed", "3")
    assert out.returncode == 0, out.stderr
    return tmp, out


def test_train_reports_progress_with_loss_terms(trained):
    _, out = trained
    assert "step   600/600" in out.stderr and "koopman" in out.stderr and "divergence" in out.stderr
    assert "wrote" in out.stderr


def test_eval_json_has_the_documented_metrics(trained):
    tmp, _ = trained
    out = koopguide("eval", str(tmp / "sine.pt"), "--json", "--starts", "100")
    assert out.returncode == 0, out.stderr
    metrics = json.loads(out.stdout)  # stdout is pure JSON
    for key in ("sea", "dtwd", "converged", "rho", "goal_fixed_point_err"):
        assert key in metrics
    assert metrics["goal_fixed_point_err"] == 0.0
    assert metrics["rho"] < 1.0
    assert metrics["starts"] == 100 and metrics["converged"] >= 95


def test_train_writes_a_certificate_and_eval_prints_it(trained):
    tmp, out = trained
    assert "certificate  PASSED  (100x100 grid" in out.stderr
    ev = koopguide("eval", str(tmp / "sine.pt"), "--starts", "100")
    assert ev.returncode == 0, ev.stderr
    assert "certificate  PASSED" in ev.stdout and "certified    yes" in ev.stdout
    assert "10000/10000 converged" in ev.stdout  # both integrators, the whole grid
    metrics = json.loads(koopguide("eval", str(tmp / "sine.pt"), "--json", "--starts", "100").stdout)
    assert metrics["converged_euler"] == 100 and metrics["certificate"]["passed"] is True


def test_uncertified_model_is_refused_unless_allowed(tmp_path):
    cfg = tmp_path / "raw.yaml"
    cfg.write_text(SMALL + "convergence: null\n")
    target = tmp_path / "raw.pt"
    out = koopguide("train", "--lasa", "Sine", "-o", str(target), "--config", str(cfg), "--quiet")
    assert out.returncode == 2 and not target.exists()
    assert out.stderr.count("\n") == 1 and "refusing to write" in out.stderr and "--allow-uncertified" in out.stderr
    out = koopguide(
        "train", "--lasa", "Sine", "-o", str(target), "--config", str(cfg), "--quiet", "--allow-uncertified"
    )
    assert out.returncode == 0 and target.exists()
    assert "WARNING" in out.stderr and "UNCERTIFIED" in out.stderr
    ev = koopguide("eval", str(target), "--starts", "20")
    assert ev.returncode == 0 and "certified    NO: the model file carries no convergence certificate" in ev.stdout


def test_plot_writes_a_png(trained):
    tmp, _ = trained
    out = koopguide("plot", str(tmp / "sine.pt"), "-o", str(tmp / "sine.png"))
    assert out.returncode == 0, out.stderr
    assert (tmp / "sine.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    out = koopguide("plot", str(tmp / "sine.pt"), "--eigenfunctions", "--count", "3", "-o", str(tmp / "eig.png"))
    assert out.returncode == 0, out.stderr
    assert (tmp / "eig.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_leading_eigenfunction_is_multiplied_by_its_eigenvalue_along_the_koopman_rollout(trained):
    import numpy as np

    from koopguide import load_field

    tmp, _ = trained
    field = load_field(tmp / "sine.pt")
    X = np.random.default_rng(0).uniform(field.bounds[0], field.bounds[1], (20, 2))
    lam, phi = field.eigenfunctions(X, count=2)
    assert np.all(np.abs(lam) < 1.0) and abs(lam[0]) >= abs(lam[1])
    # phi(K z) = lam phi(z): one step of the lifted linear system, read through the same eigenvector
    z_next = field.lift(X) @ field.B @ (field.B.T @ field.A).T  # (B^T K z)^T = (B^T A B^T z)^T
    lam_all, Y = np.linalg.eig((field.B.T @ field.A).T)
    i = int(np.argmin(np.abs(lam_all - lam[0])))
    np.testing.assert_allclose(z_next @ Y[:, i], lam[0] * phi[:, 0], rtol=1e-8, atol=1e-10)


@pytest.mark.parametrize(
    ("config_text", "message"),
    [
        ("model:\n  nuu: 3\n", "model.nuu: unknown key"),
        ("optim:\n  steps: many\n", "optim.steps: expected an integer, got 'many'"),
        ("loss:\n  divergence_of: trace\n", "loss.divergence_of: 'trace' (str) is not one of 'field', 'next_state'"),
        ("model: [1, 2\n", "invalid YAML"),
    ],
)
def test_bad_config_is_one_line_error_and_exit_2(tmp_path, config_text, message):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(config_text)
    out = koopguide("train", "--lasa", "Sine", "-o", str(tmp_path / "x.pt"), "--config", str(cfg))
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("koopguide: error: ") and message in lines[0], out.stderr
    assert not (tmp_path / "x.pt").exists()


def test_bad_inputs_exit_2_with_one_line(tmp_path):
    (tmp_path / "junk.pt").write_bytes(b"junk")
    cases = [
        (("eval", str(tmp_path / "junk.pt")), "not a torch zip archive"),
        (("eval", str(tmp_path / "missing.pt")), "model file not found"),
        (("train", "--lasa", "Zhape", "-o", str(tmp_path / "m.pt")), "unknown LASA shape 'Zhape'"),
        (("train", "--demos", str(tmp_path / "none"), "-o", str(tmp_path / "m.pt")), "no such file or folder"),
    ]
    for args, message in cases:
        out = koopguide(*args)
        assert out.returncode == 2, (args, out.stderr)
        assert out.stderr.count("\n") == 1 and message in out.stderr, out.stderr


def test_train_on_user_csv_demos_in_3d(tmp_path):
    import numpy as np

    t = np.linspace(0, 1, 201)[:, None]
    for i in range(3):
        start = np.array([10.0 + i, -5.0, 3.0 - i])
        traj = start * (1 - t) ** 2  # straight-ish approach to the origin, slowing down
        np.savetxt(tmp_path / f"demo{i}.csv", traj, delimiter=",", header="x,y,z", comments="")
    cfg = tmp_path / "small.yaml"
    cfg.write_text("subsample_every: 20\n" + SMALL)
    out = koopguide("train", "--demos", str(tmp_path), "-o", str(tmp_path / "m3.pt"), "--config", str(cfg))
    assert out.returncode == 0, out.stderr
    out = koopguide("eval", str(tmp_path / "m3.pt"), "--json", "--starts", "50")
    assert out.returncode == 0, out.stderr
    metrics = json.loads(out.stdout)
    assert metrics["sea"] is None  # SEA is 2-D only
    assert metrics["converged"] == 50 and metrics["goal_fixed_point_err"] == 0.0


def test_helix_3d_trains_certifies_evaluates_and_plots(tmp_path):
    from koopguide.base.synthetic import helix

    demos = helix()
    assert demos.dim == 3 and len(demos.trajectories) == 5
    for traj in demos.trajectories:  # descends into the goal, starting and ending at rest
        assert np.allclose(traj[-1], 0.0) and traj[0, 2] > 30.0 and np.all(np.diff(traj[:, 2]) <= 1e-12)
        assert np.linalg.norm(traj[1] - traj[0]) < 1e-3 and np.linalg.norm(traj[-1] - traj[-2]) < 1e-3
    cfg = tmp_path / "small.yaml"
    cfg.write_text(SMALL)
    model = tmp_path / "helix.pt"
    out = koopguide("train", "--synthetic", "helix", "-o", str(model), "--config", str(cfg))
    assert out.returncode == 0, out.stderr
    assert "certificate  PASSED  (22x22x22 grid" in out.stderr  # >= 100^2 starts in 3-D
    metrics = json.loads(koopguide("eval", str(model), "--json", "--starts", "100").stdout)
    assert metrics["sea"] is None and metrics["dtwd"] > 0
    assert metrics["converged"] == metrics["converged_euler"] == 100
    assert metrics["certificate"]["learned"]["converged"] == 22**3
    out = koopguide("plot", str(model), "-o", str(tmp_path / "helix.png"))
    assert out.returncode == 0 and (tmp_path / "helix.png").read_bytes()[:4] == b"\x89PNG"
