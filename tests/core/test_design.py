"""Nominal design (issue 4): the paper's flips converge, match the reference, and fail loudly when infeasible."""

from __future__ import annotations

import math

import numpy as np
import pytest

from aerobat import hummingbird
from aerobat.core.correction import correction_matrix
from aerobat.core.design import DesignFailed, design
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import NominalModel, simulate
from aerobat.quadrotor.vehicle import VehicleConfig, VehicleParams

CONFIG = hummingbird()
MODEL = NominalModel(CONFIG)
REFERENCE_P0 = np.array([21.14, 0.249, 0.410, 21.17, 0.259])  # ../shared/design.md
# p⁰ of the 3D triple flip as designed before the performance work of issue 18 (commit 37db7a2):
# faster kernels, batched and remembered evaluations must land on the same solution
PINNED_P0_3D = np.array([21.147414905322183, 0.2489405172107463, 0.40965469406191607, 21.281144061832844,
                         0.2944397583640787, 8.21327673052149e-05, 0.005610005735469527, -0.0021228918136138486,
                         -0.009274212359579277])
PINNED_P0_2D = np.array([21.147459390404254, 0.2489529815133276, 0.40965493125636276, 21.281139372106892,
                         0.2944406463477793])


def flip(**kw):
    return MultiFlip(vehicle=CONFIG.vehicle, **kw)


def test_guess_follows_eqs_37_to_39():
    m = flip(flips=3, dims=2)
    g = m.guess()
    a = CONFIG.vehicle.max_roll_acceleration_rad_s2
    c = math.radians(1800)
    assert g[0] == pytest.approx(0.9 * 21.58)
    assert g[2] == pytest.approx(6 * math.pi / c - c / a)
    assert g[1] == pytest.approx(9.81 * (2 * c / a + g[2]) / (2 * g[0]))
    assert g[4] == g[1] and g[3] == g[0]


@pytest.mark.parametrize("flips, rate_deg", [(3, 1800.0), (1, 800.0)])
def test_2d_flips_converge(flips, rate_deg):
    m = flip(flips=flips, max_rate_rad_s=math.radians(rate_deg), dims=2)
    d = design(m, MODEL)
    assert d.converged, d.message
    assert d.residual_norm < 1e-6
    final = simulate(m.program(d.p_nominal), CONFIG).final_state
    assert m.error(final)[4] == pytest.approx(0.0, abs=1e-6)
    if flips == 3:
        assert 1.3 <= d.duration_s <= 1.7


def test_triple_flip_ends_at_six_pi():
    m = flip(flips=3, dims=2)
    d = design(m, MODEL)
    from aerobat.quadrotor.dynamics import rotation_angles

    final = simulate(m.program(d.p_nominal), CONFIG).final_state
    assert rotation_angles(final)[0] == pytest.approx(6 * math.pi, abs=1e-6)


def test_reference_p0_without_ramps_within_one_percent():
    m = flip(flips=3, dims=2, ramp_collective_s=0.0, coast_collective="min")
    d = design(m, MODEL)
    assert d.converged
    np.testing.assert_allclose(d.p_nominal, REFERENCE_P0, rtol=0.01)
    stage_sum = m.stages(d.p_nominal).total_s
    assert stage_sum == pytest.approx(1.35, abs=0.01)


def test_3d_triple_flip_jacobian_full_rank_and_ill_conditioned():
    m = flip(flips=3, dims=3)
    d = design(m, MODEL)
    assert d.converged, d.message
    assert d.rank == 9
    assert 1e4 < d.condition_number < 1e6  # one nearly unobservable direction (design.md: ~8e4)
    # the weakest direction mixes the lateral/yaw parameters p6, p7, p8
    Js = (d.jacobian / np.array([e.scale for e in m.errors])[:, None]) * np.array([p.scale for p in m.parameters])
    weakest = np.linalg.svd(Js)[2][-1]
    assert np.sum(weakest[6:9] ** 2) > 0.9


@pytest.mark.parametrize("dims, pinned", [(3, PINNED_P0_3D), (2, PINNED_P0_2D)])
def test_triple_flip_p0_is_pinned(dims, pinned):
    d = design(flip(flips=3, dims=dims), MODEL)
    assert d.converged, d.message
    np.testing.assert_allclose(d.p_nominal, pinned, rtol=0, atol=1e-9)


def test_design_matches_the_public_jacobian_at_p0():
    """The design's remembered, batched evaluations give exactly what a fresh Jacobian computes."""
    from aerobat.core.design import finite_difference_jacobian

    m = flip(flips=3, dims=3)
    d = design(m, MODEL)
    J, e = finite_difference_jacobian(m, MODEL, d.p_nominal)
    assert J.tobytes() == d.jacobian.tobytes()
    assert e.tobytes() == d.residual.tobytes()


def test_correction_is_a_right_inverse():
    m = flip(flips=3, dims=3)
    d = design(m, MODEL, correction="inverse")
    np.testing.assert_allclose(d.jacobian @ d.correction, np.eye(9), atol=1e-6)
    ps = np.array([p.scale for p in m.parameters])
    es = np.array([e.scale for e in m.errors])
    tsvd = correction_matrix(d.jacobian, ps, es, kind="tsvd")
    # truncation drops exactly one direction: J C is a rank-8 projector
    assert np.linalg.matrix_rank(d.jacobian @ tsvd, tol=1e-6) == 8
    wide = d.jacobian[:5]
    pinv = correction_matrix(wide, ps, es[:5])
    np.testing.assert_allclose(wide @ pinv, np.eye(5), atol=1e-8)
    # with equal parameter scales (e.g. all switch times) the scaled pseudo-inverse is exactly eq 48
    equal = correction_matrix(wide, np.full(9, 0.02), es[:5])
    np.testing.assert_allclose(equal, wide.T @ np.linalg.inv(wide @ wide.T), rtol=1e-6, atol=1e-10)


def test_infeasible_flip_fails_naming_the_limit():
    weak = VehicleConfig(vehicle=VehicleParams(collective_reduced_max_m_s2=11.0), controller=CONFIG.controller)
    m = MultiFlip(vehicle=weak.vehicle, flips=3, dims=3)
    d = design(m, NominalModel(weak))
    assert not d.converged
    assert d.status == "not_converged"
    assert "β̄" in d.message and "collective_reduced_max_m_s2" in d.message
    with pytest.raises(DesignFailed, match="design failed"):
        design(m, NominalModel(weak), raise_on_failure=True)


def test_invalid_maneuver_arguments():
    with pytest.raises(ValueError, match="flips"):
        flip(flips=0)
    with pytest.raises(ValueError, match="max_rate_rad_s"):
        flip(max_rate_rad_s=1000.0)
    with pytest.raises(ValueError, match="dims"):
        flip(dims=4)
    m = flip(dims=2)
    with pytest.raises(ValueError, match="p1"):
        m.program(np.array([20.0, -0.1, 0.3, 20.0, 0.2]))


def test_the_declared_design_options_have_the_signatures_defaults():
    import dataclasses
    import inspect

    from aerobat.core.design import _DesignArguments

    signature = inspect.signature(design).parameters
    for f in dataclasses.fields(_DesignArguments):
        assert signature[f.name].default == f.default, f.name


def test_a_parameter_on_its_bound_is_pinned_within_a_ten_thousandth_of_its_scale():
    from aerobat.core.maneuver import ParameterSpec

    spec = ParameterSpec(name="p2", description="coast duration", unit="s", lower=0.0, upper=5.0, scale=0.02)
    assert spec.pinned(0.0) == "lower" and spec.pinned(1.9e-6) == "lower" and spec.pinned(2.1e-6) == ""
    assert spec.pinned(5.0 - 1e-6) == "upper" and spec.pinned(2.5) == ""
    assert ParameterSpec(name="p5", description="free", unit="rad").pinned(-1e9) == ""  # no bound, never pinned
