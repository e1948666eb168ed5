"""Flow disturbances: the fields' defining properties, and noise integrated with Euler-Maruyama."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitl.config import DoubleGyreConfig, VortexConfig
from sitl.flow import Flow, OrnsteinUhlenbeck2D, double_gyre_velocity, lamb_oseen_velocity, uniform_velocity
from tests.support.sitl_gcs import sim_config


def gyre(mu=0.0):
    return DoubleGyreConfig(
        origin_ned_m=(0.0, 0.0),
        amplitude_mps=0.1,
        epsilon=0.25,
        omega_radps=2 * math.pi / 10,
        scale_m=1.5,
        dissipation_per_s=mu,
    )


def divergence(field, n, e, h=1e-5):
    dvn_dn = (field(n + h, e)[0] - field(n - h, e)[0]) / (2 * h)
    dve_de = (field(n, e + h)[1] - field(n, e - h)[1]) / (2 * h)
    return dvn_dn + dve_de


@pytest.mark.parametrize("t", [0.0, 1.3, 2.5, 7.7])
def test_double_gyre_without_dissipation_is_divergence_free(t):
    cfg = gyre()
    rng = np.random.default_rng(3)
    points = rng.uniform((0.0, 0.0), (3.0, 1.5), size=(200, 2))
    div = [divergence(lambda n, e: double_gyre_velocity(n, e, t, cfg), n, e) for n, e in points]
    speeds = [math.hypot(*double_gyre_velocity(n, e, t, cfg)) for n, e in points]
    assert max(abs(d) for d in div) < 1e-8
    assert max(speeds) > 0.2  # a real flow: peak ~ pi A (1 + 2 eps)
    assert max(speeds) <= math.pi * 0.1 * (1 + 2 * 0.25) + 1e-9


def test_double_gyre_dissipation_adds_minus_two_mu_divergence():
    cfg = gyre(mu=0.05)
    assert divergence(lambda n, e: double_gyre_velocity(n, e, 3.0, cfg), 0.7, 0.4) == pytest.approx(-0.1, abs=1e-7)


def test_double_gyre_walls_are_streamlines():
    cfg = gyre()
    for x in np.linspace(0, 3.0, 13):
        assert abs(double_gyre_velocity(x, 0.0, 1.0, cfg)[1]) < 1e-12  # no flow across y = 0
        assert abs(double_gyre_velocity(x, 1.5, 1.0, cfg)[1]) < 1e-12  # nor across y = s


def test_lamb_oseen_vortex_is_tangential_with_the_profile():
    cfg = VortexConfig(center_ned_m=(2.0, 1.0), circulation_m2ps=0.2, core_radius_m=0.3)
    for r in (0.05, 0.3, 1.0):
        for angle in (0.0, 1.0, 2.5):
            dn, de = r * math.cos(angle), r * math.sin(angle)
            vn, ve = lamb_oseen_velocity(2.0 + dn, 1.0 + de, cfg)
            assert vn * dn + ve * de == pytest.approx(0.0, abs=1e-12)  # no radial component
            expected = 0.2 / (2 * math.pi * r) * (1 - math.exp(-(r**2) / 0.3**2))
            assert math.hypot(vn, ve) == pytest.approx(expected)
    vn, ve = lamb_oseen_velocity(2.5, 1.0, cfg)  # north of the centre, Gamma > 0
    assert ve < 0  # counter-clockwise seen from above: westward on the north side
    assert lamb_oseen_velocity(2.0, 1.0, cfg) == (0.0, 0.0)


def test_uniform_current_direction_is_where_the_water_goes():
    vn, ve = uniform_velocity(0.1, 90.0)
    assert vn == pytest.approx(0.0, abs=1e-15) and ve == pytest.approx(0.1)


@pytest.mark.parametrize("dt", [0.01, 0.05])
def test_gusts_are_euler_maruyama_with_the_stationary_std_at_any_step(dt):
    process = OrnsteinUhlenbeck2D(std_mps=0.02, time_constant_s=0.5)
    rng = np.random.default_rng(11)
    samples = []
    for k in range(round(2000.0 / dt)):
        process.advance(dt, rng)
        if k % round(0.5 / dt) == 0:
            samples.append((process.vn, process.ve))
    std = np.std(np.array(samples)[200:], axis=0)
    # sigma sqrt(2 dt / tau) per step keeps the stationary std at sigma, not dependent on dt
    assert std == pytest.approx([0.02, 0.02], rel=0.12)


def test_flow_components_sum():
    kinds = ["uniform", "vortex", "double_gyre"]
    cfg = sim_config({"flow": {"kinds": kinds}}).flow
    flow = Flow(cfg, np.random.default_rng(0))
    n, e, t = 1.1, 0.7, 4.0
    parts = [
        uniform_velocity(cfg.uniform.speed_mps, cfg.uniform.direction_deg),
        lamb_oseen_velocity(n, e, cfg.vortex),
        double_gyre_velocity(n, e, t, cfg.double_gyre),
    ]
    assert flow.velocity(n, e, t) == pytest.approx(tuple(map(sum, zip(*parts, strict=True))))
    calm = Flow(sim_config().flow, np.random.default_rng(0))
    assert calm.calm and calm.velocity(n, e, t) == (0.0, 0.0)
