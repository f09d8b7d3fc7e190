"""Model kernels of aerobat.quadrotor.dynamics.

Controller inversion (eqs 14–21), plant (eqs 8–12), motors, attitude output.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from aerobat.quadrotor.dynamics import (
    N_PLANT,
    N_STATE,
    OMEGA,
    POS,
    QUAT,
    RATE_INT,
    THRUST,
    VEL,
    controller_thrusts,
    controller_vector,
    euler_zyx,
    hover_state,
    plant_constants,
    plant_derivative,
    plant_vector,
    rotation_angles,
    rotation_matrices,
)
from aerobat.quadrotor.playback import rk4_plant_step
from aerobat.quadrotor.vehicle import ControllerParams, VehicleParams

V = VehicleParams()


def test_state_layout():
    slices = [POS, VEL, QUAT, OMEGA, THRUST, RATE_INT]
    covered = np.concatenate([np.arange(N_STATE)[s] for s in slices])
    np.testing.assert_array_equal(covered, np.arange(N_STATE))  # contiguous, no gaps, no overlaps
    assert [s.stop - s.start for s in slices] == [3, 3, 4, 3, 4, 3]


def test_hover_state():
    x = hover_state(V, position_m=(1.0, -2.0, 3.0))
    np.testing.assert_array_equal(x[POS], [1.0, -2.0, 3.0])
    np.testing.assert_array_equal(x[VEL], 0.0)
    np.testing.assert_array_equal(x[QUAT], [1.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(x[OMEGA], 0.0)
    np.testing.assert_allclose(x[THRUST], 0.468 * 9.81 / 4, rtol=1e-15)
    np.testing.assert_array_equal(x[RATE_INT], 0.0)


# ------------------------------------------------- eqs 14–21 invert eq 10


def _eq10(f: np.ndarray, arm: float, kappa: float) -> tuple[float, float, float, float]:
    """Eq 10: total thrust and moments (τ_p, τ_q, τ_r) of motor thrusts f1..f4."""
    return (
        f[0] + f[1] + f[2] + f[3],
        arm * (f[1] - f[3]),
        arm * (f[2] - f[0]),
        kappa * (f[0] - f[1] + f[2] - f[3]),
    )


PERMUTATIONS = list(itertools.permutations((1, 2, 3, 4)))
finite = dict(allow_nan=False, allow_infinity=False, allow_subnormal=False)


@settings(max_examples=300, deadline=None)
@given(
    collective=st.floats(0.0, 40.0, **finite),
    cmd_rates=st.tuples(*[st.floats(-40.0, 40.0, **finite)] * 3),
    gyro=st.tuples(*[st.floats(-40.0, 40.0, **finite)] * 3),
    gains=st.tuples(*[st.floats(0.0, 300.0, **finite)] * 3),
    mass=st.floats(0.05, 5.0, **finite),
    arm=st.floats(0.05, 1.0, **finite),
    inertia=st.tuples(*[st.floats(1e-4, 0.1, **finite)] * 3),
    kappa=st.floats(0.005, 0.05, **finite),
    order=st.sampled_from(PERMUTATIONS),
    compiled=st.booleans(),
)
# always covered: identity and non-identity wiring, Table 1 constants, both kernels
@example(
    collective=9.81,
    cmd_rates=(12.0, -3.0, 1.0),
    gyro=(2.0, 5.0, -7.0),
    gains=(100.0, 100.0, 10.0),
    mass=0.468,
    arm=0.17,
    inertia=(0.0023, 0.0023, 0.0046),
    kappa=0.016,
    order=(1, 2, 3, 4),
    compiled=True,
)
@example(
    collective=15.0,
    cmd_rates=(-20.0, 4.0, 0.5),
    gyro=(1.0, -2.0, 30.0),
    gains=(100.0, 100.0, 10.0),
    mass=0.468,
    arm=0.17,
    inertia=(0.0023, 0.0025, 0.0046),
    kappa=0.016,
    order=(2, 4, 1, 3),
    compiled=False,
)
def test_controller_inverts_eq_10(
    collective, cmd_rates, gyro, gains, mass, arm, inertia, kappa, order, compiled
):
    """Eqs 17–20 invert eq 10.

    The thrusts' eq 10 moments are I·a + ω×Iω with a = P⊙(ω̂ − ω), and Σf = m·collective.
    """
    params = ControllerParams(
        rate_gain_p_per_s=gains[0],
        rate_gain_q_per_s=gains[1],
        rate_gain_r_per_s=gains[2],
        mass_kg=mass,
        arm_length_m=arm,
        inertia_xx_kg_m2=inertia[0],
        inertia_yy_kg_m2=inertia[1],
        inertia_zz_kg_m2=inertia[2],
        drag_constant_m=kappa,
        motor_order=order,
    )
    ctrl = controller_vector(params)
    cmd = np.array([collective, *cmd_rates])
    out = np.full(4, np.nan)
    fn = controller_thrusts if compiled else controller_thrusts.py_func
    fn(cmd, gyro[0], gyro[1], gyro[2], ctrl, out)
    assert np.all(np.isfinite(out))  # every physical slot written
    # the controller's motor i lands in physical slot order[i]: read back in controller numbering
    f = np.array([out[order[i] - 1] for i in range(4)])

    w = np.array(gyro)
    inertia_v = np.array(inertia)
    a = np.array(gains) * (np.array(cmd_rates) - w)
    desired = inertia_v * a + np.cross(w, inertia_v * w)
    total, tp, tq, tr = _eq10(f, arm, kappa)
    # rounding scales: eq 10 takes differences of thrusts of size max|f|; I·a + ω×Iω sums terms of
    # size |I a| and |ω||Iω| (which can cancel, e.g. (I_zz − I_yy) q r with I_zz = I_yy)
    fscale = np.max(np.abs(f))
    mscale = np.abs(inertia_v * a) + np.linalg.norm(w) * np.linalg.norm(inertia_v * w)
    # (+1e-15 N absolute floor: tiny values underflow; far below any physical thrust)
    assert abs(total - mass * collective) <= 1e-9 * max(mass * collective, fscale) + 1e-15
    for i, (got, lever) in enumerate(((tp, arm), (tq, arm), (tr, kappa))):
        scale = max(abs(desired[i]), lever * fscale, mscale[i])
        assert abs(got - desired[i]) <= 1e-9 * scale + 1e-15, (
            i,
            got,
            desired,
        )


def test_controller_hover_gives_equal_thrusts():
    ctrl = controller_vector(ControllerParams())
    out = np.empty(4)
    controller_thrusts(np.array([9.81, 0.0, 0.0, 0.0]), 0.0, 0.0, 0.0, ctrl, out)
    np.testing.assert_allclose(out, V.hover_rotor_thrust_n, rtol=1e-15)


def test_controller_roll_command_signs():
    """p̂ > p asks for +τ_p: motor 2 (+y) up, motor 4 (−y) down.

    Pitch: motor 3 up, 1 down; yaw: motors 1, 3 up.
    """
    ctrl = controller_vector(ControllerParams())
    out = np.empty(4)
    controller_thrusts(np.array([9.81, 1.0, 0.0, 0.0]), 0.0, 0.0, 0.0, ctrl, out)
    h = V.hover_rotor_thrust_n
    # τ_p = Ixx · P_p · 1 = 0.23 N m → f2 − f4 = τ_p / l, split evenly
    dp = 0.0023 * 100.0 / 0.17 / 2
    np.testing.assert_allclose(out, [h, h + dp, h, h - dp], rtol=1e-12)
    controller_thrusts(np.array([9.81, 0.0, 1.0, 0.0]), 0.0, 0.0, 0.0, ctrl, out)
    np.testing.assert_allclose(out, [h - dp, h, h + dp, h], rtol=1e-12)
    controller_thrusts(np.array([9.81, 0.0, 0.0, 1.0]), 0.0, 0.0, 0.0, ctrl, out)
    dy = 0.0046 * 10.0 / 0.016 / 4
    np.testing.assert_allclose(out, [h + dy, h - dy, h + dy, h - dy], rtol=1e-12)


def test_miswired_motor_order_reverses_the_physical_moment():
    """motor_order (3, 2, 1, 4): motor 1's command goes to slot 3 — the pitch moment flips sign."""
    good = controller_vector(ControllerParams())
    bad = controller_vector(ControllerParams(motor_order=(3, 2, 1, 4)))
    np.testing.assert_array_equal(bad[9:13], [2.0, 1.0, 0.0, 3.0])
    cmd = np.array([9.81, 0.3, 1.0, -0.2])
    f_good = np.empty(4)
    f_bad = np.empty(4)
    controller_thrusts(cmd, 0.0, 0.0, 0.0, good, f_good)
    controller_thrusts(cmd, 0.0, 0.0, 0.0, bad, f_bad)
    total_g, tp_g, tq_g, tr_g = _eq10(f_good, 0.17, 0.016)
    total_b, tp_b, tq_b, tr_b = _eq10(f_bad, 0.17, 0.016)
    assert tq_g == pytest.approx(0.0023 * 100.0 * 1.0, rel=1e-12)
    assert tq_b == pytest.approx(-tq_g, rel=1e-12)
    assert (total_b, tp_b) == pytest.approx((total_g, tp_g), rel=1e-12)
    assert tr_b == pytest.approx(tr_g, rel=1e-12)  # slots 1 and 3 share the yaw sign


# --------------------------------------------------------- plant, eqs 8–12


def _deriv(
    x: np.ndarray, ft: np.ndarray, plant: np.ndarray | None = None, t: float = 0.0
) -> np.ndarray:
    dx = np.full(N_STATE, np.nan)
    plant_derivative(t, x, ft, plant_vector(V) if plant is None else plant, dx)
    assert np.all(np.isfinite(dx))
    return dx


def test_plant_vector_layout():
    p = plant_vector(V)
    assert p.shape == (N_PLANT,)
    assert np.all(p[25:] == 0.0)  # no aerodynamics, wind or gusts in the paper's model


def test_hover_is_an_equilibrium():
    x = hover_state(V)
    dx = _deriv(x, x[THRUST].copy())
    # exactly balanced up to rounding of l·f2 − l·f4 (≈1e-16 N m / I_xx)
    np.testing.assert_allclose(dx, 0.0, atol=1e-12)


def test_free_fall_and_tilted_thrust():
    x = hover_state(V)
    x[THRUST] = 0.0
    dx = _deriv(x, np.zeros(4))
    np.testing.assert_allclose(dx[VEL], [0.0, 0.0, -9.81], atol=1e-15)
    # f̃ = 0 is clipped to f_min: motors fall toward f_min — they start at 0, so they rise with P_up
    np.testing.assert_allclose(dx[THRUST], 80.0 * 0.08, rtol=1e-15)
    # rolled by φ about x (body→world R = Rx(φ)): thrust axis is (0, −sin φ, cos φ)
    phi = 0.3
    x = hover_state(V)
    x[QUAT] = (math.cos(phi / 2), math.sin(phi / 2), 0.0, 0.0)
    dx = _deriv(x, x[THRUST].copy())
    np.testing.assert_allclose(
        dx[VEL], [0.0, -9.81 * math.sin(phi), 9.81 * math.cos(phi) - 9.81], atol=1e-14
    )
    # pitched by θ about y: thrust axis (sin θ, 0, cos θ)
    theta = -0.4
    x[QUAT] = (math.cos(theta / 2), 0.0, math.sin(theta / 2), 0.0)
    dx = _deriv(x, x[THRUST].copy())
    np.testing.assert_allclose(
        dx[VEL], [9.81 * math.sin(theta), 0.0, 9.81 * math.cos(theta) - 9.81], atol=1e-14
    )


def test_plant_moments_follow_eq_10():
    x = hover_state(V)
    x[THRUST] = (1.0, 1.5, 1.2, 0.7)
    dx = _deriv(x, x[THRUST].copy())
    np.testing.assert_allclose(
        dx[OMEGA],
        [
            0.17 * (1.5 - 0.7) / 0.0023,
            0.17 * (1.2 - 1.0) / 0.0023,
            0.016 * (1.0 - 1.5 + 1.2 - 0.7) / 0.0046,
        ],
        rtol=1e-12,
        atol=1e-12,
    )
    np.testing.assert_allclose(dx[VEL], [0.0, 0.0, 4.4 / 0.468 - 9.81], rtol=1e-12)


def test_gyroscopic_coupling():
    """ω̇ = I⁻¹(τ − ω×Iω) with τ = 0: for I = diag(a, a, 2a), ṗ = −q r, q̇ = p r, ṙ = 0."""
    x = hover_state(V)
    x[OMEGA] = (2.0, 3.0, 5.0)
    dx = _deriv(x, x[THRUST].copy())
    np.testing.assert_allclose(dx[OMEGA], [-15.0, 10.0, 0.0], rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(dx[RATE_INT], [2.0, 3.0, 5.0])


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def test_quaternion_kinematics_use_body_rates():
    rng = np.random.default_rng(7)
    for _ in range(20):
        x = hover_state(V)
        q = rng.normal(size=4)
        x[QUAT] = q / np.linalg.norm(q)
        x[OMEGA] = rng.normal(scale=10.0, size=3)
        dx = _deriv(x, x[THRUST].copy())
        np.testing.assert_allclose(
            dx[QUAT], 0.5 * _qmul(x[QUAT], np.r_[0.0, x[OMEGA]]), rtol=1e-12, atol=1e-14
        )
        # ...which is Ṙ = R [ω]×
        R = rotation_matrices(x)
        h = 1e-7
        xp = x.copy()
        xp[QUAT] = x[QUAT] + h * dx[QUAT]
        wx = np.array([[0, -x[12], x[11]], [x[12], 0, -x[10]], [-x[11], x[10], 0]])
        np.testing.assert_allclose(
            (rotation_matrices(xp) - R) / h, R @ wx, atol=1e-5 * np.abs(x[OMEGA]).max()
        )


def test_compiled_and_python_plant_agree():
    rng = np.random.default_rng(1)
    plant = plant_vector(
        V,
        com_offset_m=(0.01, -0.02, 0.0),
        thrust_gains=(1.0, 0.95, 1.05, 1.0),
        body_drag_n_s2_m2=0.01,
        rotor_drag_s_m=0.05,
        rotational_damping_n_m_s=(1e-3, 1e-3, 2e-3),
        wind_m_s=(1.0, -0.5, 0.2),
        gust_amplitude_m_s=(0.3, 0.1, 0.0),
        gust_frequency_hz=0.7,
    )
    for _ in range(10):
        x = rng.normal(size=N_STATE)
        x[QUAT] /= np.linalg.norm(x[QUAT])
        ft = rng.uniform(-1.0, 4.0, size=4)
        a = np.empty(N_STATE)
        b = np.empty(N_STATE)
        plant_derivative(0.3, x, ft, plant, a)
        plant_derivative.py_func(0.3, x, ft, plant, b)
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


# ------------------------------------------------------- motor asymmetry


def _hold(x: np.ndarray, ft: np.ndarray, times: list[float], h: float = 1e-4) -> np.ndarray:
    """Integrate the plant with motor commands ``ft`` held; states at ``times`` (multiples of h)."""
    plant = plant_vector(V)
    k = plant_constants(plant)
    work = [np.empty(N_STATE) for _ in range(5)]
    x = x.copy()
    out = []
    step = 0
    for t_target in times:
        n_target = round(t_target / h)
        while step < n_target:
            rk4_plant_step(step * h, x, ft, plant, k, h, *work)
            step += 1
        out.append(x.copy())
    return np.array(out)


def test_motor_step_up_and_down_use_p_up_and_p_down():
    """f(t) = f_cmd − Δ e^{−P t}: P_f,up = 80/s going up, P_f,dn = 60/s going down (Table 1)."""
    x = hover_state(V)
    f0 = V.hover_rotor_thrust_n  # 1.14777 N
    ft = np.array(
        [2.0, 0.5, 2.5, 0.3]
    )  # motors 1, 3 step up; 2, 4 step down (all inside [f_min, f_max])
    times = [0.005, 0.01, 0.02, 0.05, 0.1]
    states = _hold(x, ft, times)
    for t, s in zip(times, states, strict=True):
        rate = np.where(ft > f0, 80.0, 60.0)
        expected = ft - (ft - f0) * np.exp(-rate * t)
        np.testing.assert_allclose(s[THRUST], expected, rtol=1e-6)
        # the asymmetry is real: with the other rate the thrust is visibly different
        swapped = ft - (ft - f0) * np.exp(-np.where(ft > f0, 60.0, 80.0) * t)
        assert np.all(np.abs(s[THRUST] - swapped) > 1e-4 * np.abs(expected))


def test_motor_commands_are_clipped_to_thrust_limits():
    x = hover_state(V)
    f0 = V.hover_rotor_thrust_n
    ft = np.array([10.0, -3.0, 2.8, 0.08])  # above f_max, below f_min, exactly at the limits
    (s,) = _hold(x, ft, [0.03])
    target = np.array([2.8, 0.08, 2.8, 0.08])
    rate = np.array([80.0, 60.0, 80.0, 60.0])
    np.testing.assert_allclose(s[THRUST], target - (target - f0) * np.exp(-rate * 0.03), rtol=1e-6)


# ------------------------------------------------------- attitude output


def _quat_zyx(phi: float, theta: float, psi: float) -> np.ndarray:
    qx = np.array([math.cos(phi / 2), math.sin(phi / 2), 0.0, 0.0])
    qy = np.array([math.cos(theta / 2), 0.0, math.sin(theta / 2), 0.0])
    qz = np.array([math.cos(psi / 2), 0.0, 0.0, math.sin(psi / 2)])
    return _qmul(_qmul(qz, qy), qx)  # R = Rz(ψ) Ry(θ) Rx(φ), body→world


@settings(max_examples=200, deadline=None)
@given(phi=st.floats(-3.1, 3.1), theta=st.floats(-1.5, 1.5), psi=st.floats(-3.1, 3.1))
def test_euler_zyx_inverts_the_zyx_quaternion(phi, theta, psi):
    x = hover_state(V)
    x[QUAT] = _quat_zyx(phi, theta, psi)
    np.testing.assert_allclose(euler_zyx(x), [phi, theta, psi], atol=1e-9)
    R = rotation_matrices(x)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-14)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-14)


def test_rotation_matrix_of_known_rotations():
    x = hover_state(V)
    x[QUAT] = _quat_zyx(0.0, 0.0, math.pi / 2)  # yaw 90°: body x points along world y
    np.testing.assert_allclose(rotation_matrices(x) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)
    x[QUAT] = _quat_zyx(math.pi / 2, 0.0, 0.0)  # roll 90°: body z (thrust) points along world −y
    np.testing.assert_allclose(rotation_matrices(x) @ [0.0, 0.0, 1.0], [0.0, -1.0, 0.0], atol=1e-15)
    # batch shapes
    states = np.stack([hover_state(V)] * 5).reshape(5, 1, N_STATE)
    assert rotation_matrices(states).shape == (5, 1, 3, 3)
    assert euler_zyx(states).shape == (5, 1, 3)


@pytest.mark.parametrize(
    ("axis", "rate"), [(0, 2.0), (1, 1.5), (2, 3.0), (0, -2.0), (1, -1.0), (2, -0.5)]
)
def test_positive_body_rate_gives_positive_euler_angle(axis, rate):
    """From hover, a body rate about x, y or z alone increases φ, θ or ψ (eq 13 convention)."""
    x = hover_state(V)
    x[10 + axis] = rate
    (s,) = _hold(x, x[THRUST].copy(), [0.1], h=1e-3)
    euler = euler_zyx(s)
    expected = np.zeros(3)
    expected[axis] = rate * 0.1
    np.testing.assert_allclose(euler, expected, atol=1e-12)
    np.testing.assert_allclose(s[RATE_INT], expected, atol=1e-12)
    np.testing.assert_allclose(rotation_angles(s), expected, atol=1e-12)
    assert np.sign(euler[axis]) == np.sign(rate)


@pytest.mark.parametrize("turns", [-3, -1, 0, 1, 3])
def test_rotation_angles_unwrap_whole_turns(turns):
    x = hover_state(V)
    phi = 0.05
    x[QUAT] = _quat_zyx(phi, -0.02, 0.01)
    # ∫p dt differs from φ by whole turns plus a little drift that must be rounded away
    x[RATE_INT] = (phi + 2 * math.pi * turns + 0.3, -0.02 - 0.2, 0.01)
    np.testing.assert_allclose(
        rotation_angles(x), [phi + 2 * math.pi * turns, -0.02, 0.01], atol=1e-12
    )
