"""Onboard feedback (issue 15): the estimator, the law, the reference, the plants and the store, with numbers."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from aerobat.core.design import design
from aerobat.core.learning import learn
from aerobat.core.maneuver import ErrorKind, position_indices
from aerobat.errors import ConfigError
from aerobat.plants import Arena, ArenaParams, PlantChoice
from aerobat.quadrotor.dynamics import quaternion_from_rotation_vector
from aerobat.quadrotor.feedback import (
    OPEN_LOOP,
    Feedback,
    FeedbackGains,
    FeedbackScheme,
    apply_feedback,
    feedback_vector,
    onboard_propagate,
    onboard_receive,
    onboard_state,
    reference_at,
    reference_from_trajectory,
    relay_deviation,
)
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import NominalModel, simulate
from aerobat.quadrotor.vehicle import hummingbird

CONFIG = hummingbird()
FLIP = MultiFlip(vehicle=CONFIG.vehicle, flips=3, max_rate_rad_s=math.radians(1800), dims=3)
DESIGN = design(FLIP, NominalModel(CONFIG))
TRACKING = feedback_vector(Feedback(FeedbackScheme.TRACKING))


def _reference():
    nominal = simulate(FLIP.program(DESIGN.p_nominal), CONFIG)
    return reference_from_trajectory(nominal.times_s, nominal.states, 100.0), nominal


# ---------------------------------------------------------------- estimator and law


def test_the_estimator_integrates_a_constant_rate_exactly():
    state, history = onboard_state()
    rate = np.array([31.4, -2.0, 0.5])  # rad/s, a flip's rate
    dt = 1.0 / 800.0
    for k in range(800):
        onboard_propagate(state, history, k * dt, rate[0], rate[1], rate[2], dt)
    expected = quaternion_from_rotation_vector(rate * 1.0)
    assert abs(abs(float(np.dot(state[0:4], expected))) - 1.0) < 1e-12
    # the history holds the estimate at the start of each tick
    newest = history[(int(state[12]) - 1) % history.shape[0]]
    assert newest[0] == pytest.approx(799 * dt)
    before_last = quaternion_from_rotation_vector(rate * 799 * dt)
    assert abs(abs(float(np.dot(newest[1:5], before_last))) - 1.0) < 1e-12


def test_a_relayed_attitude_pulls_the_estimate_by_the_fusion_gain_at_its_sample_time():
    state, history = onboard_state()
    dt = 1.0 / 800.0
    for k in range(40):  # at rest: the estimate stays level
        onboard_propagate(state, history, k * dt, 0.0, 0.0, 0.0, dt)
    truth = quaternion_from_rotation_vector(np.array([0.02, -0.01, 0.0]))  # the vehicle is tilted
    gains = feedback_vector(Feedback(FeedbackScheme.ATTITUDE, FeedbackGains(attitude_fusion_gain=0.5)))
    onboard_receive(state, history, gains, 30 * dt, truth, np.zeros(3), np.zeros(3), False)
    halfway = quaternion_from_rotation_vector(np.array([0.01, -0.005, 0.0]))
    assert abs(abs(float(np.dot(state[0:4], halfway))) - 1.0) < 1e-9
    assert state[11] == 0.0  # no translation relayed


def test_on_the_reference_the_law_changes_nothing():
    ref, nominal = _reference()
    state, _ = onboard_state()
    scratch = np.empty(10)
    for tau in (0.0, 0.137, 0.5, 0.9, ref.duration_s - 0.01):
        reference_at(ref.samples, ref.dt_s, tau, scratch)
        state[0:4] = scratch[6:10]
        state[4:10] = 0.0
        state[10] = 1.0
        state[11] = 1.0  # a fresh relayed deviation of zero
        cmd = np.array([9.0, 1.0, -2.0, 0.3])
        before = cmd.copy()
        apply_feedback(cmd, state, TRACKING, ref.samples, tau, 1.0, scratch)
        assert np.allclose(cmd, before, atol=1e-9), tau


def test_the_law_turns_a_sideways_offset_into_a_tilt_back_and_a_low_vehicle_into_more_collective():
    ref, _ = _reference()
    state, _ = onboard_state()
    scratch = np.empty(10)
    state[10] = 0.0
    state[11] = 1.0
    state[4:7] = (0.0, 0.05, -0.03)  # 5 cm to +y, 3 cm low, at hover before the flip
    cmd = np.array([9.81, 0.0, 0.0, 0.0])
    apply_feedback(cmd, state, TRACKING, ref.samples, 0.0, 0.0, scratch)
    g = Feedback().gains
    assert cmd[0] == pytest.approx(9.81 + g.position_gain_per_s2 * 0.03)
    assert cmd[1] > 0.0  # roll right-hand about +x tilts the thrust towards −y
    assert abs(cmd[2]) < 1e-12 and abs(cmd[3]) < 1e-12
    stale = state.copy()
    cmd2 = np.array([9.81, 0.0, 0.0, 0.0])
    apply_feedback(cmd2, stale, TRACKING, ref.samples, 0.0, 1.0, scratch)  # a relayed estimate 1 s old
    assert cmd2[0] == 9.81 and cmd2[1] == 0.0


def test_the_reference_is_the_nominal_flight_relative_to_its_start():
    ref, nominal = _reference()
    assert ref.dt_s == pytest.approx(0.01)
    assert ref.samples.shape[0] == int(math.floor(nominal.times_s[-1] / 0.01 + 1e-9)) + 1
    scratch = np.empty(10)
    k = np.searchsorted(nominal.times_s, 0.5)
    reference_at(ref.samples, ref.dt_s, nominal.times_s[k], scratch)
    assert np.allclose(scratch[0:3], nominal.states[k, 0:3], atol=2e-4)
    assert abs(abs(float(np.dot(scratch[6:10], nominal.states[k, 6:10]))) - 1.0) < 1e-4


def test_the_supervisor_recovers_a_deviation_from_the_reference_exactly():
    ref, _ = _reference()
    start = 2.0
    origin = np.array([0.3, -0.2, 1.0])
    dp, dv = np.array([0.01, -0.02, 0.005]), np.array([0.1, 0.0, -0.05])
    scratch, out = np.empty(10), np.empty(6)
    log = np.zeros((12, 8))
    t_last = start + 0.6
    for k in range(12):
        t = t_last - (11 - k) * 0.005
        reference_at(ref.samples, ref.dt_s, t - start, scratch)
        log[k, 0] = t
        log[k, 1:4] = origin + scratch[0:3] + dp + dv * (t - t_last)
        log[k, 4:8] = scratch[6:10]
    assert relay_deviation(log, 12, start, origin, ref.samples, ref.dt_s, scratch, out)
    assert np.allclose(out[0:3], dp, atol=1e-12) and np.allclose(out[3:6], dv, atol=1e-9)


# ---------------------------------------------------------------- choices and the store


def test_feedback_choices_round_trip_and_refuse_nonsense():
    fb = Feedback("attitude", FeedbackGains(attitude_gain_per_s=7.0))
    assert Feedback.from_table(fb.to_table(), source="t") == fb
    choice = PlantChoice("arena", seed=3, feedback=fb)
    again = PlantChoice.from_table(choice.to_table(), source="t")
    assert again.feedback == fb and again == choice
    assert "feedback" not in PlantChoice("arena", feedback="none").to_table()  # as every older store holds it
    assert PlantChoice.from_table({"kind": "arena", "seed": 1}, source="t").feedback == OPEN_LOOP
    assert PlantChoice("arena").feedback.scheme is FeedbackScheme.TRACKING  # the best measured, by default
    with pytest.raises(ConfigError, match="feedback"):
        PlantChoice("arena", feedback="pid")
    with pytest.raises(ConfigError, match="attitude_gain_per_s"):
        FeedbackGains(attitude_gain_per_s=-1.0)


def test_a_resumed_session_with_feedback_repeats_an_uninterrupted_one_bit_for_bit(tmp_path):
    from aerobat.core.rules import RuleChoice
    from aerobat.experiments import resume_session, start_session
    from aerobat.store import Store

    small = MultiFlip(vehicle=CONFIG.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
    plan = design(small, NominalModel(CONFIG))
    plant = PlantChoice("arena", seed=5, feedback="tracking")
    with Store(tmp_path / "a.sqlite") as store:
        whole = start_session(store, small, model=CONFIG, plant=plant, rule=RuleChoice.parse("paper"),
                              iterations=5, design_result=plan)
        assert whole.run().completed
        part = start_session(store, small, model=CONFIG, plant=plant, rule=RuleChoice.parse("paper"),
                             iterations=5, design_result=plan)
        stops = iter([False, False, True])
        part.run(should_stop=lambda: next(stops, True))
    with Store(tmp_path / "a.sqlite") as store:
        resumed = resume_session(store, part.id)
        assert resumed.exact and resumed.plant_choice.feedback.scheme is FeedbackScheme.TRACKING
        assert resumed.run().completed
        a = [(it.params.tobytes(), it.error.tobytes()) for it in store.iterations(whole.id)]
        b = [(it.params.tobytes(), it.error.tobytes()) for it in store.iterations(part.id)]
        assert a == b


# ---------------------------------------------------------------- the arena, with numbers


def _quiet_arena(**changes) -> ArenaParams:
    p = ArenaParams()
    off = {name: dataclasses.replace(getattr(p, name), enabled=False)
           for name in ("true_vehicle", "aerodynamics", "disturbances", "drift")}
    off.update(changes)
    return dataclasses.replace(
        p, onboard=dataclasses.replace(p.onboard, gyro_scale_error=(0.0, 0.0, 0.0), gyro_bias_rad_s=(0.0, 0.0, 0.0)),
        motion_capture=dataclasses.replace(p.motion_capture, position_noise_m=0.0, attitude_noise_rad=0.0), **off)


def test_on_an_ideal_arena_feedback_neither_helps_nor_hurts():
    """True vehicle = model, perfect sensors: the reference is the flight, the law adds nothing real."""
    program = FLIP.program(DESIGN.p_nominal)
    finals = {}
    for scheme in ("none", "tracking"):
        trial = Arena(CONFIG, _quiet_arena(), seed=1, feedback=scheme).fly(program)
        finals[scheme] = FLIP.error(trial.final_state)
    idx = position_indices(FLIP.errors)
    none, tracking = np.linalg.norm(finals["none"][idx]), np.linalg.norm(finals["tracking"][idx])
    assert none < 0.04 and tracking < 0.04, (none, tracking)  # latency, settle tolerance, 800 Hz sampling


def test_tracking_takes_out_the_horizontal_scatter():
    """The same program flown 12 times from the supervisor's imperfect hover, with gusts and motor
    jitter: the horizontal spread of the end point falls from about 4 cm to 1 cm (the vertical one,
    set by thrust jitter in the stages where the law must stay out of the motors' way, does not)."""
    program = FLIP.program(DESIGN.p_nominal)
    names = [e.name for e in FLIP.errors]
    horizontal = [names.index("y"), names.index("x")]
    spread = {}
    for scheme in ("none", "tracking"):
        arena = Arena(CONFIG, seed=2, feedback=scheme)
        ends = np.array([FLIP.error(arena.fly(program).final_state)[horizontal] for _ in range(12)])
        spread[scheme] = float(np.linalg.norm(ends.std(axis=0)))
    assert spread["none"] > 0.03 and spread["tracking"] < 0.4 * spread["none"], spread


def test_learning_with_tracking_beats_the_open_loop_on_the_triple_flip():
    """5 seeds × 30 trials (issue 15's study uses 20 seeds; docs/results.md, 'Feedback')."""
    idx = position_indices(FLIP.errors)
    angles = [k for k, e in enumerate(FLIP.errors) if e.kind is ErrorKind.ANGLE]
    last, worst_angle = {}, {}
    for scheme in ("none", "tracking"):
        means, ang = [], []
        for seed in range(5):
            session = learn(FLIP, DESIGN, Arena(CONFIG, seed=seed, feedback=scheme), iterations=30)
            errors = [it.error for it in session.measured]
            means.append(np.mean([np.linalg.norm(e[idx]) for e in errors[-10:]]))
            ang.append(np.degrees(np.mean(np.abs(np.array([e[angles] for e in errors[-10:]])), axis=0)))
        last[scheme], worst_angle[scheme] = float(np.mean(means)), float(np.max(np.mean(ang, axis=0)))
    assert last["none"] > 0.06 and worst_angle["none"] > 1.5  # the starting point
    assert last["tracking"] < 0.04 and worst_angle["tracking"] < 1.0, (last, worst_angle)


def test_each_plant_defaults_to_its_best_measured_scheme():
    from aerobat.plants import PlantChoice
    from aerobat.quadrotor.feedback import FeedbackScheme

    # docs/results.md, Feedback: tracking wins on the arena and through Betaflight; on RotorPy, with
    # the default rule, the open loop does (tracking wins there only with the Broyden rule)
    assert PlantChoice("arena").feedback.scheme is FeedbackScheme.TRACKING
    assert PlantChoice("betaflight").feedback.scheme is FeedbackScheme.TRACKING
    assert PlantChoice("rotorpy").feedback.scheme is FeedbackScheme.NONE
    assert PlantChoice("rotorpy", feedback="tracking").feedback.scheme is FeedbackScheme.TRACKING
