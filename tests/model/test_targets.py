"""The learning core's acceptance bars, at the shipped defaults, on two seeds.

Fit bars: the best reference-implementation run measured on this hardware (Zshape), the paper's
figures (Leaf_1, Sine) and the paper's 30-shape mean / human variability (Multi_Models_4).
Convergence bars: 500 random starts from the demonstrations' box with each side moved out by 10%, within
1 unit of the goal after 100 learned steps and after 100 x 40 Euler steps: all 500; the certificate
(100 x 100 grid, both integrators) passes; the goal a fixed point within 0.01; rho(K) < 1.
"""

import pytest

from koopguide.base import data
from koopguide.model.evaluate import evaluate
from koopguide.model.learn import trainer
from koopguide.model.learn.export import training_config

BARS = {  # shape: (max SEA, max DTWD)
    "Zshape": (191.0, 1832.0),
    "Leaf_1": (123.0, 1365.0),
    "Sine": (169.0, 1595.0),
    "Multi_Models_4": (169.0, 1972.0),
}


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("shape", list(BARS))
def test_default_training_meets_fit_and_convergence_bars(shape, seed):
    demos = data.load_lasa(shape)
    t = trainer.train(demos, training_config(None), seed)
    field = t.field()
    m = evaluate(field, demos)
    max_sea, max_dtwd = BARS[shape]
    assert m["sea"] <= max_sea, m["sea"]
    assert m["dtwd"] <= max_dtwd, m["dtwd"]
    assert m["converged"] == 500, (m["converged"], m["final_distance_max"])
    assert m["converged_euler"] == 500, (m["converged_euler"], m["final_distance_max_euler"])
    assert t.certificate["passed"] and t.certificate["grid"] == [100, 100]
    assert t.certificate["learned"]["converged"] == t.certificate["euler"]["converged"] == 10000
    assert m["goal_fixed_point_err"] <= 0.01
    assert m["rho"] < 1.0
    assert t.info["rho_trained"] < 1.0  # stable as trained, not only after the spectral projection
