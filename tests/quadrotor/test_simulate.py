"""Playing programs on the model: hover, flips, agreement with scipy, sampled playback, batches."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from aerobat.quadrotor.dynamics import (
    N_STATE,
    OMEGA,
    POS,
    QUAT,
    RATE_INT,
    THRUST,
    VEL,
    controller_constants,
    controller_vector,
    derivative,
    euler_zyx,
    hover_state,
    plant_constants,
    plant_vector,
    rotation_angles,
    rotation_matrices,
    thrust_commands,
)
from aerobat.quadrotor.playback import run_continuous, run_continuous_lagged
from aerobat.quadrotor.program import Program, RampDown, Switch, load_program
from aerobat.quadrotor.simulate import (
    DEFAULT_MAX_STEP_S,
    DEFAULT_TICK_S,
    Trajectory,
    batch_threads,
    final_state_summary,
    set_batch_threads,
    simulate,
    simulate_batch,
)
from aerobat.quadrotor.vehicle import ControllerParams, ModelEffects, VehicleConfig, VehicleParams, hummingbird

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
CFG = hummingbird()
SIX_PI = 6.0 * math.pi


@pytest.fixture(scope="module")
def single_flip() -> Program:
    return load_program(EXAMPLES / "single_flip.toml")


@pytest.fixture(scope="module")
def triple_flip() -> Program:
    return load_program(EXAMPLES / "triple_flip_1800.toml")


# ------------------------------------------------------------------ hover


@pytest.mark.parametrize("mode", ["continuous", "sampled"])
@pytest.mark.parametrize("position", [(0.0, 0.0, 0.0), (1.0, -2.0, 3.0)])
def test_hover_program_holds_position(mode, position):
    """5 s of hover commands from hover_state move the vehicle < 1e-9 m (measured ≈3e-13 m)."""
    x0 = hover_state(CFG.vehicle, position_m=position)
    traj = simulate(Program(switches=(), duration_s=5.0), CFG, initial_state=x0, mode=mode)
    assert traj.times_s[0] == 0.0 and traj.times_s[-1] == 5.0
    drift = np.linalg.norm(traj.states[:, POS] - np.array(position), axis=1).max()
    assert drift < 1e-9, drift
    assert np.abs(traj.states[:, VEL]).max() < 1e-9
    assert np.abs(traj.states[:, QUAT] - [1.0, 0.0, 0.0, 0.0]).max() < 1e-12
    assert np.abs(traj.states[:, OMEGA]).max() < 1e-12
    np.testing.assert_allclose(traj.states[:, THRUST], CFG.vehicle.hover_rotor_thrust_n, rtol=1e-12)


def test_hover_example_file_holds_position():
    traj = simulate(load_program(EXAMPLES / "hover.toml"), CFG)
    assert traj.duration_s == 5.0
    assert np.abs(traj.states[:, POS]).max() < 1e-9


# ------------------------------------------------------- closed-loop physics


def test_constant_collective_climb_matches_motor_lag_solution():
    """Collective g + 3 from hover: each motor rises with P_up = 80/s, so
    v(t) = 3 (t − (1 − e^{−80 t})/80),  z(t) = 3 (t²/2 − t/80 + (1 − e^{−80 t})/6400)."""
    prog = Program(
        switches=(Switch(time_s=0.0, channel="collective", value=12.81),), duration_s=1.0
    )
    traj = simulate(prog, CFG)
    t = traj.times_s
    e = np.exp(-80.0 * t)
    np.testing.assert_allclose(traj.states[:, 5], 3.0 * (t - (1.0 - e) / 80.0), rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        traj.states[:, 2], 3.0 * (t * t / 2 - t / 80.0 + (1.0 - e) / 6400.0), rtol=0, atol=1e-9
    )
    np.testing.assert_allclose(traj.states[:, 0:2], 0.0, atol=1e-12)
    f = traj.states[:, THRUST]
    expected_f = (12.81 - 3.0 * e) * 0.468 / 4
    np.testing.assert_allclose(f, np.repeat(expected_f[:, None], 4, axis=1), rtol=1e-8)  # RK4: 2e-9


@pytest.mark.parametrize("mode", ["continuous", "sampled"])
def test_rate_commands_are_tracked_with_positive_angles(mode):
    """p̂ = 2 rad/s for 0.5 s: p → 2, φ ≈ 2·(0.5 − lag) > 0, and the tilted thrust pushes toward −y.
    The same for q̂ → θ > 0 (pushes toward +x) and r̂ → ψ > 0 (slower: P_r = 10/s)."""
    for axis, channel in enumerate(("rate_p", "rate_q", "rate_r")):
        prog = Program(switches=(Switch(time_s=0.0, channel=channel, value=2.0),), duration_s=0.5)
        final = simulate(prog, CFG, mode=mode).final_state
        angle = euler_zyx(final)[axis]
        if axis < 2:
            assert final[OMEGA][axis] == pytest.approx(2.0, abs=1e-6)
            assert 0.95 < angle < 1.0  # 2 · (0.5 − ~0.01 s controller lag)
        else:
            # linearized yaw loop with motor lag: s² + P_f s + P_f P_r = 0, poles −11.7, −68.3 /s
            s1, s2 = np.roots([1.0, 80.0, 800.0])
            step = 1 - (s1 * math.exp(s2 * 0.5) - s2 * math.exp(s1 * 0.5)) / (s1 - s2)
            assert final[OMEGA][axis] == pytest.approx(
                2.0 * step, abs=2e-3
            )  # 1.9931 (measured 1.9939)
            assert 0.78 < angle < 0.81  # ≈ 2 · (0.5 − 1/P_r − 1/P_f)
        others = np.delete(euler_zyx(final), axis)
        assert np.abs(others).max() < 5e-3
    roll = simulate(
        Program(switches=(Switch(time_s=0.0, channel="rate_p", value=2.0),), duration_s=0.5), CFG
    )
    pitch = simulate(
        Program(switches=(Switch(time_s=0.0, channel="rate_q", value=2.0),), duration_s=0.5), CFG
    )
    assert roll.final_state[1] < -0.3 and pitch.final_state[0] > 0.3


def test_acceleration_command_ramp_lags_by_one_over_gain():
    """accel_p = 10 rad/s² ramps p̂ = 10 t; the type-1 P loop lags a ramp by 1/P_p = 0.01 s."""
    prog = Program(switches=(Switch(time_s=0.0, channel="accel_p", value=10.0),), duration_s=0.5)
    traj = simulate(prog, CFG)
    assert traj.final_state[10] == pytest.approx(10.0 * (0.5 - 0.01), abs=1e-4)
    np.testing.assert_allclose(traj.commands[-1], [9.81, 5.0, 0.0, 0.0], atol=1e-12)


# ------------------------------------------------------------- triple flip


def test_triple_flip_keeps_rotation_orthonormal_and_counts_three_turns(triple_flip):
    traj = simulate(triple_flip, CFG)
    final = traj.final_state
    # the integrator renormalizes the raw quaternion every step
    norms = np.linalg.norm(traj.states[:, QUAT], axis=1)
    assert np.abs(norms - 1.0).max() < 1e-12
    R = rotation_matrices(final)
    assert np.linalg.norm(R.T @ R - np.eye(3)) < 1e-9
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
    angles = rotation_angles(final)
    assert abs(angles[0] - SIX_PI) < 0.1, angles  # measured 6π − 0.0113
    assert abs(angles[1]) < 0.01 and abs(angles[2]) < 0.01
    assert abs(euler_zyx(final)[0]) < 0.1
    # ∫p dt agrees with the unwrapped angle up to small pitch/yaw excursions (measured 4.5e-7 rad)
    assert final[RATE_INT][0] == pytest.approx(angles[0], abs=1e-3)
    # unwrapped roll passes 2π, 4π, 6π in order; it winds up slightly negative first (accel_p < 0
    # at the start, measured −0.255 rad) and overshoots 6π by 0.233 rad (measured) before the
    # recovery brings it back
    roll = rotation_angles(traj.states)[:, 0]
    crossings = [int(np.argmax(roll > k * math.pi)) for k in (1, 2, 3, 4, 5, 6)]
    assert crossings == sorted(crossings) and crossings[0] > 0
    assert -0.3 < roll.min() <= 0.0
    assert SIX_PI < roll.max() < SIX_PI + 0.3


def test_single_flip_is_one_turn_and_returns_to_start(single_flip):
    final = simulate(single_flip, CFG).final_state
    assert rotation_angles(final)[0] == pytest.approx(2 * math.pi, abs=0.01)
    # the example is a 2D design: it zeroes the y, z position error on this model (measured 4e-12 m)
    assert np.abs(final[1:3]).max() < 1e-6
    assert np.linalg.norm(final[VEL]) < 0.05


# ------------------------------------------- agreement with scipy solve_ivp


def _solve_ivp_reference(program: Program, config: VehicleConfig) -> np.ndarray:
    compiled = program.compile()
    plant = plant_vector(config.vehicle)
    ctrl = controller_vector(config.controller)
    constants, mix = plant_constants(plant), controller_constants(ctrl)

    def closed_loop(t, y, cmd, dx):
        derivative(t, y, thrust_commands(cmd, y[10], y[11], y[12], ctrl, mix), plant, constants, dx)

    x = hover_state(config.vehicle)
    bp = compiled.breakpoints_s
    for k in range(len(bp) - 1):
        t0, coeff = bp[k], compiled.coefficients[k]

        def rhs(t, y, t0=t0, coeff=coeff):
            tau = t - t0
            cmd = coeff[:, 0] + tau * (coeff[:, 1] + tau * coeff[:, 2])
            dx = np.empty(N_STATE)
            closed_loop(t, y, cmd, dx)
            return dx

        sol = solve_ivp(rhs, (t0, bp[k + 1]), x, method="DOP853", rtol=1e-10, atol=1e-12)
        assert sol.success, sol.message
        x = sol.y[:, -1].copy()
    return x


def test_compiled_rk4_agrees_with_solve_ivp(single_flip):
    reference = _solve_ivp_reference(single_flip, CFG)
    final = simulate(single_flip, CFG).final_state  # continuous, default 0.5 ms steps
    diff = np.linalg.norm(final[POS] - reference[POS])
    print(f"\nsingle flip: |RK4(0.5 ms) − DOP853| final position = {diff:.3e} m")
    # measured: 1.12e-6 m (RK4 with 0.5 ms steps); 1.7e-8 m with max_step_s = 1e-4
    assert diff < 1e-3
    assert diff < 1e-5  # tighter regression bound on the measured 1.1e-6 m
    assert (
        abs(rotation_angles(final)[0] - rotation_angles(reference)[0]) < 1e-5
    )  # measured 1.6e-6 rad
    fine = simulate(single_flip, CFG, max_step_s=1e-4).final_state
    assert np.linalg.norm(fine[POS] - reference[POS]) < diff  # converges toward the reference


def test_sampled_mode_differs_slightly_from_continuous(single_flip):
    continuous = simulate(single_flip, CFG, mode="continuous").final_state
    sampled = simulate(single_flip, CFG, mode="sampled").final_state
    diff = np.linalg.norm(sampled[POS] - continuous[POS])
    print(f"\nsingle flip: |800 Hz sampled − continuous| final position = {diff:.3e} m")
    # measured: 3.95e-3 m (mostly z: the zero-order hold delays every command by up to 1.25 ms)
    assert 0.0 < diff < 0.01
    assert diff > 1e-4  # the hold is a real effect, not rounding


# ---------------------------------------------------------- trajectories


def test_continuous_steps_land_on_breakpoints(single_flip):
    traj = simulate(single_flip, CFG)
    bp = single_flip.compile().breakpoints_s
    assert np.all(np.isin(bp, traj.times_s))
    steps = np.diff(traj.times_s)
    assert steps.max() <= DEFAULT_MAX_STEP_S * (1 + 1e-12) and steps.min() > 0
    assert traj.states.shape == (len(traj.times_s), N_STATE) and traj.commands.shape == (
        len(traj.times_s),
        4,
    )
    assert traj.mode == "continuous"
    # recorded commands are the program's (except at switch instants: the left limit is recorded)
    inner = ~np.isin(traj.times_s, bp)
    np.testing.assert_allclose(
        traj.commands[inner], single_flip.commands_at(traj.times_s[inner]), atol=1e-9
    )


def test_sampled_mode_samples_the_program_every_tick(single_flip):
    traj = simulate(single_flip, CFG, mode="sampled")
    n = math.ceil(single_flip.duration_s / DEFAULT_TICK_S)
    np.testing.assert_allclose(traj.times_s[:-1], np.arange(n) * DEFAULT_TICK_S, rtol=0, atol=1e-12)
    assert traj.times_s[-1] == single_flip.duration_s
    np.testing.assert_allclose(
        traj.commands[:-1], single_flip.commands_at(traj.times_s[:-1]), atol=1e-9
    )
    assert traj.mode == "sampled"
    substeps = simulate(single_flip, CFG, mode="sampled", substeps=4).final_state
    assert 0 < np.linalg.norm(substeps[POS] - traj.final_state[POS]) < 1e-5


def test_record_false_keeps_start_and_final(single_flip):
    full = simulate(single_flip, CFG)
    short = simulate(single_flip, CFG, record=False)
    assert short.states.shape == (2, N_STATE)
    np.testing.assert_array_equal(short.states[0], hover_state(CFG.vehicle))
    np.testing.assert_array_equal(short.final_state, full.final_state)
    np.testing.assert_array_equal(short.times_s, [0.0, single_flip.duration_s])


def test_compiled_program_input_equals_program_input(single_flip):
    a = simulate(single_flip, CFG)
    b = simulate(single_flip.compile(), CFG)
    np.testing.assert_array_equal(a.states, b.states)


def test_trajectory_helpers(single_flip):
    traj = simulate(single_flip, CFG)
    assert isinstance(traj, Trajectory)
    np.testing.assert_array_equal(traj.euler_zyx(), euler_zyx(traj.states))
    np.testing.assert_array_equal(traj.rotation_angles(), rotation_angles(traj.states))
    summary = final_state_summary(traj.final_state, traj.duration_s)
    assert summary["duration_s"] == single_flip.duration_s
    fs = summary["final_state"]
    assert fs["position_m"] == traj.final_state[POS].tolist()
    assert fs["rotation_angle_rad"][0] == pytest.approx(2 * math.pi, abs=0.01)


# --------------------------------------------------------- reproducibility


@pytest.mark.parametrize("mode", ["continuous", "sampled"])
def test_identical_calls_are_bit_identical(single_flip, mode):
    a = simulate(single_flip, CFG, mode=mode)
    b = simulate(single_flip, CFG, mode=mode)
    assert a.times_s.tobytes() == b.times_s.tobytes()
    assert a.states.tobytes() == b.states.tobytes()
    assert a.commands.tobytes() == b.commands.tobytes()


def _varied_programs(base: Program, n: int = 8) -> list[Program]:
    programs = []
    for i in range(n):
        switches = tuple(
            Switch(
                time_s=s.time_s * (1 + 0.01 * i),
                channel=s.channel,
                value=s.value * (1 + 0.02 * i) if s.channel != "accel_p" else s.value,
            )
            for s in base.switches
        )
        extra = (Switch(time_s=0.05 * i, channel="rate_r", value=0.1 * i),) if i % 2 else ()
        programs.append(
            Program(
                switches=switches + extra,
                duration_s=base.duration_s * (1 + 0.01 * i),
                ramp_down=RampDown(collective_s=0.1, rates_s=0.05 * (i % 3)),
            )
        )
    return programs


def test_batch_equals_separate_runs_bit_for_bit(single_flip):
    """Measured: bit-identical (the parallel batch kernel runs the same RK4 as simulate)."""
    programs = _varied_programs(single_flip)
    assert len({p.duration_s for p in programs}) == 8
    batch = simulate_batch(programs, CFG)
    separate = np.stack([simulate(p, CFG, record=False).final_state for p in programs])
    assert batch.shape == (8, N_STATE)
    assert batch.tobytes() == separate.tobytes()
    assert np.unique(batch[:, POS], axis=0).shape[0] == 8  # the programs really differ


@pytest.mark.parametrize("threads", [1, 3])
def test_batch_threads_change_nothing_but_the_threads(single_flip, threads):
    programs = _varied_programs(single_flip)
    default = simulate_batch(programs, CFG)
    set_batch_threads(threads)
    try:
        assert batch_threads() == threads
        assert simulate_batch(programs, CFG).tobytes() == default.tobytes()
    finally:
        set_batch_threads(None)
    assert batch_threads() >= 1


@pytest.mark.parametrize("threads", [0, -1, 1.5, True, "2"])
def test_bad_batch_threads(threads):
    with pytest.raises(ValueError, match="threads"):
        set_batch_threads(threads)


def test_batch_with_vehicles_states_and_plants(single_flip):
    heavy = VehicleParams(mass_kg=0.5)
    configs = [CFG, VehicleConfig(vehicle=heavy, controller=ControllerParams.nominal_for(heavy))]
    starts = np.stack(
        [hover_state(CFG.vehicle, (1.0, 0.0, 0.0)), hover_state(heavy, (0.0, 2.0, 0.0))]
    )
    plants = np.stack(
        [
            plant_vector(CFG.vehicle),
            plant_vector(heavy, wind_m_s=(1.0, 0.0, 0.0), body_drag_n_s2_m2=0.02),
        ]
    )
    batch = simulate_batch(
        [single_flip, single_flip], configs, initial_states=starts, plants=plants
    )
    for b in range(2):
        one = simulate(
            single_flip, configs[b], initial_state=starts[b], plant=plants[b], record=False
        )
        assert batch[b].tobytes() == one.final_state.tobytes()
    assert simulate_batch([], CFG).shape == (0, N_STATE)
    with pytest.raises(ValueError, match="got 2 programs but 1 vehicles"):
        simulate_batch([single_flip, single_flip], [CFG])


def test_batch_mixing_vehicles_with_and_without_latency_equals_separate_runs(single_flip):
    """Rows with rate-loop latency run the loop's lagged version, the others the plain one: same bits as simulate()."""
    lagging = dataclasses.replace(CFG, effects=ModelEffects(rate_latency_s=(0.004, 0.006, 0.0),
                                                            rotor_drag_axial_s_m=0.02))
    configs = [CFG, lagging, lagging, CFG, lagging]
    programs = _varied_programs(single_flip)[: len(configs)]
    for threads in (1, 2):
        set_batch_threads(threads)
        try:
            batch = simulate_batch(programs, configs)
        finally:
            set_batch_threads(None)
        for b, config in enumerate(configs):
            assert batch[b].tobytes() == simulate(programs[b], config, record=False).final_state.tobytes()
    assert not np.array_equal(batch[0], simulate(programs[0], lagging, record=False).final_state)


def test_the_lagged_loop_without_latency_flies_the_plain_loop(triple_flip):
    """One loop, two compiled versions: with every delay 0 the lagged version takes the rates of the state itself.

    They agree to rounding, not bit for bit: each version is optimised on its own (fastmath), so the compiler may
    fuse other multiply-adds in each. What is promised bit for bit is that a vehicle runs the same version wherever
    it is simulated (the batch tests above).
    """
    compiled = triple_flip.compile()
    bp, coeffs = compiled.breakpoints_s, compiled.coefficients
    packed = (hover_state(CFG.vehicle)[None], bp[None], coeffs[None], np.array([len(bp) - 1]),
              plant_vector(CFG.vehicle)[None], controller_vector(CFG.controller)[None], np.zeros((1, 3)),
              DEFAULT_MAX_STEP_S)
    flown = []
    for play in (run_continuous, run_continuous_lagged):
        out = np.empty((1, N_STATE))
        rec_t, rec_x, rec_u = np.empty(4000), np.empty((4000, N_STATE)), np.empty((4000, 4))
        count = play(*packed, out, np.zeros(1, dtype=np.int64), rec_t, rec_x, rec_u)
        flown.append((out[0], rec_t[:count], rec_x[:count], rec_u[:count]))
    (plain_final, plain_t, plain_x, plain_u), (lagged_final, lagged_t, lagged_x, lagged_u) = flown
    assert len(plain_t) > 100
    assert plain_t.tobytes() == lagged_t.tobytes()
    assert plain_u.tobytes() == lagged_u.tobytes()  # the program, sampled at the same times
    np.testing.assert_allclose(lagged_x, plain_x, rtol=0, atol=1e-12)  # 4e-16 here
    np.testing.assert_allclose(lagged_final, plain_final, rtol=0, atol=1e-12)
    assert not np.allclose(plain_final, hover_state(CFG.vehicle))  # a flip flown, not nothing


# ------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"mode": "discrete"}, r"mode = 'discrete': allowed 'continuous', 'sampled'"),
        ({"max_step_s": 0.0}, r"max_step_s = 0.0 must be finite and > 0"),
        ({"max_step_s": math.nan}, r"max_step_s = nan"),
        ({"tick_s": -1.0}, r"tick_s = -1.0 must be finite and > 0"),
        ({"substeps": 0}, r"substeps = 0 must be >= 1"),
        ({"initial_state": np.zeros(13)}, r"initial_state must have shape \(20,\), got \(13,\)"),
        ({"initial_state": np.full(N_STATE, np.inf)}, r"initial_state contains non-finite values"),
    ],
)
def test_bad_simulate_arguments(kwargs, pattern):
    with pytest.raises(ValueError, match=pattern):
        simulate(Program(switches=(), duration_s=0.1), CFG, **kwargs)


@pytest.mark.parametrize("max_step_s", [0.0, -1e-3, math.nan])
def test_batch_rejects_bad_max_step(single_flip, max_step_s):
    with pytest.raises(ValueError, match="max_step_s"):
        simulate_batch([single_flip], CFG, max_step_s=max_step_s)


def test_trajectory_named_accessors_are_views_of_the_state_columns():
    from aerobat.quadrotor.dynamics import N_STATE, STATE_NAMES
    from aerobat.quadrotor.maneuvers import MultiFlip
    from aerobat.quadrotor.simulate import NominalModel
    from aerobat.quadrotor.vehicle import hummingbird

    config = hummingbird()
    flip = MultiFlip(vehicle=config.vehicle, flips=1, dims=2)
    traj = NominalModel(config).trajectory(flip.program(flip.guess()))
    assert len(STATE_NAMES) == N_STATE == traj.states.shape[1]
    assert np.array_equal(traj.position_m, traj.states[:, 0:3])
    assert np.array_equal(traj.velocity_m_s, traj.states[:, 3:6])
    assert np.allclose(np.linalg.norm(traj.quaternion, axis=1), 1.0, atol=1e-9)
    assert np.array_equal(traj.body_rates_rad_s, traj.states[:, 10:13])
    assert traj.rotor_thrusts_n.shape == (len(traj.times_s), 4)
    assert "samples over" in repr(traj)
