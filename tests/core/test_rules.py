"""Update rules beyond the paper's (issue 8): regularized, Kalman, Broyden, initial-state compensation.

Two kinds of checks: fast ones on a synthetic linear plant (e = J_true(p − p*) + S·δ + noise,
any J_true, no quadrocopter), and the arena checks of the issue (3D triple flip, a design
model with 50 % wrong inertia, a fivefold start-state error). The 20-seed numbers behind
the arena thresholds are in docs/rules.md.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from aerobat import VehicleConfig, hummingbird
from aerobat.core.design import Design, design
from aerobat.core.learning import learn
from aerobat.core.maneuver import ErrorSpec, ParameterSpec, bounds_arrays, check_parameters
from aerobat.core.plant import Trial
from aerobat.core.rules import (
    RULES,
    BroydenJacobian,
    BroydenRule,
    ConstantSchedule,
    InitialStateCompensation,
    IscModel,
    KalmanRule,
    PaperRule,
    RegularizedRule,
    RuleChoice,
    ScheduleChoice,
    filter_factors,
    make_rule,
)
from aerobat.plants import Arena, ArenaParams
from aerobat.quadrotor.isc import (
    early_trajectory_deviation,
    initial_state_sensitivity,
    quadrotor_isc,
    start_state_deviation,
)
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import NominalModel

# ------------------------------------------------------------------ synthetic plant


@dataclass(frozen=True)
class LinearManeuver:
    """A maneuver whose 'program' is its parameter vector and whose final state is its error."""

    n: int = 4
    lower: float = -5.0
    upper: float = 5.0
    name: str = "linear"
    parameters: tuple[ParameterSpec, ...] = field(init=False)
    errors: tuple[ErrorSpec, ...] = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "parameters", tuple(
            ParameterSpec(name=f"p{k}", description="", unit="", lower=self.lower, upper=self.upper, scale=1.0)
            for k in range(self.n)))
        object.__setattr__(self, "errors", tuple(ErrorSpec(name=f"e{k}", unit="", scale=1.0) for k in range(self.n)))

    def guess(self) -> np.ndarray:
        return np.zeros(self.n)

    def program(self, params: np.ndarray) -> np.ndarray:
        problem = check_parameters(self.parameters, params)
        if problem:
            raise ValueError(problem)
        return np.array(params, dtype=float)

    def error(self, final_state: np.ndarray) -> np.ndarray:
        return np.asarray(final_state, dtype=float)

    def is_valid(self, params: np.ndarray) -> bool:
        return check_parameters(self.parameters, params) is None

    def spec(self) -> dict[str, Any]:
        return {"kind": "linear", "n": self.n}


class LinearPlant:
    """e = J_true (p − p*) + S δ + v; δ (the 'start state') and v Gaussian; optional lost trials."""

    name = "linear"

    def __init__(self, J_true, p_star, *, noise=0.05, S=None, start_std=0.0, lost_every=0, absurd_every=0,
                 seed=0) -> None:
        self.J = np.asarray(J_true, dtype=float)
        self.p_star = np.asarray(p_star, dtype=float)
        self.noise = noise
        self.S = np.zeros((self.J.shape[0], 2)) if S is None else np.asarray(S, dtype=float)
        self.start_std = start_std
        self.lost_every = lost_every
        self.absurd_every = absurd_every
        self.rng = np.random.default_rng(seed)
        self.count = 0
        self.flown: list[np.ndarray] = []

    def fly(self, program) -> Trial:
        self.count += 1
        p = np.asarray(program, dtype=float)
        self.flown.append(p.copy())
        nan = np.full(self.J.shape[0], np.nan)
        if self.lost_every and self.count % self.lost_every == 0:
            return Trial("no_trigger", "lost", nan, np.empty(0), np.empty((0, 1)), np.full(self.S.shape[1], np.nan))
        delta = self.start_std * self.rng.standard_normal(self.S.shape[1])
        e = self.J @ (p - self.p_star) + self.S @ delta + self.noise * self.rng.standard_normal(self.J.shape[0])
        if self.absurd_every and self.count % self.absurd_every == 0:
            e = e + 1e6
        return Trial("ok", "", e, np.empty(0), np.empty((0, 1)), delta)


def linear_design(m: LinearManeuver, J: np.ndarray, p0: np.ndarray | None = None) -> Design:
    s = np.linalg.svd(J, compute_uv=False)
    return Design(
        maneuver=m, p_guess=np.zeros(m.n), p_nominal=np.zeros(m.n) if p0 is None else p0,
        residual=np.zeros(m.n), residual_norm=0.0, converged=True, status="converged", message="",
        jacobian=J, correction=np.linalg.pinv(J), correction_kind="inverse", singular_values=s,
        condition_number=float(s[0] / s[-1]), rank=m.n, duration_s=0.0, compute_s=0.0, evaluations=0,
    )


LIN = LinearManeuver()
J_LIN = np.array([[2.0, 0.3, 0.0, 0.1], [0.0, 1.5, 0.2, 0.0], [0.1, 0.0, 1.0, 0.3], [0.0, 0.2, 0.0, 0.5]])
P_STAR = np.array([1.0, -0.8, 0.5, 1.2])
D_LIN = linear_design(LIN, J_LIN)
SYNTHETIC = ["paper", "tsvd", "damped", "kalman", "broyden"]


def dist(session) -> np.ndarray:
    return np.array([np.linalg.norm(it.params - P_STAR) for it in session.measured])


# ------------------------------------------------------------------ factory, pieces


def test_factory_builds_every_rule_by_name():
    assert set(SYNTHETIC) == set(RULES.names())
    kinds = {"paper": PaperRule, "tsvd": RegularizedRule, "damped": RegularizedRule, "kalman": KalmanRule,
             "broyden": BroydenRule}
    for name, cls in kinds.items():
        rule = make_rule(name, D_LIN)
        assert isinstance(rule, cls) and rule.name == name
        json.dumps(rule.state())
    wrapped = make_rule("kalman+isc", D_LIN, isc=IscModel(np.zeros((4, 2)), lambda t, p: t.start_state))
    assert isinstance(wrapped, InitialStateCompensation) and wrapped.name == "kalman+isc"
    half = RuleChoice("paper", schedule=ScheduleChoice("constant", value=0.5))
    assert isinstance(make_rule(half, D_LIN).schedule, ConstantSchedule)
    with pytest.raises(ValueError, match="unknown update rule"):
        make_rule("newton", D_LIN)
    with pytest.raises(ValueError, match="sensitivity"):
        make_rule("tsvd+isc", D_LIN)
    with pytest.raises(ValueError, match="suffix"):
        make_rule("tsvd+foo", D_LIN)


def test_filter_factors():
    s = np.array([10.0, 1.0, 0.1, 1e-5])
    np.testing.assert_array_equal(filter_factors(s, 0.5, "tsvd", 1e-4), [1, 1, 0, 0])
    f = filter_factors(s, 0.5, "damped", 1e-4)
    assert f[0] > 0.99 and f[1] == pytest.approx(0.8) and f[2] == pytest.approx(0.01 / 0.26) and f[3] == 0.0


@pytest.mark.parametrize("name", SYNTHETIC)
def test_every_rule_converges_on_a_linear_plant(name):
    s = learn(LIN, D_LIN, LinearPlant(J_LIN, P_STAR, seed=3), iterations=30, rule=make_rule(name, D_LIN))
    assert s.status == "completed"
    d = dist(s)
    assert d[0] > 1.5
    assert d[-10:].mean() < 0.1, d


@pytest.mark.parametrize("name", SYNTHETIC)
def test_lost_and_rejected_trials_do_not_drive_updates(name):
    plant = LinearPlant(J_LIN, P_STAR, lost_every=3, absurd_every=7, seed=4)
    s = learn(LIN, D_LIN, plant, iterations=25, rule=make_rule(name, D_LIN))
    assert s.status == "completed"
    statuses = [it.status for it in s.iterations]
    assert "no_trigger" in statuses and "rejected" in statuses
    for k, it in enumerate(s.iterations[:-1]):
        if it.status != "ok":  # retried with the same parameters: no step was taken
            assert it.gamma == 0.0
            np.testing.assert_array_equal(s.iterations[k + 1].params, it.params)
    assert dist(s)[-5:].mean() < 0.15


@pytest.mark.parametrize("name", SYNTHETIC)
def test_parameters_stay_within_bounds_and_keep_learning_at_one(name):
    # p* beyond the upper bound of p0: the best reachable point has p0 at its bound and
    # the other parameters compensating as far as they can
    m = LinearManeuver(lower=-1.0, upper=1.0)
    d = linear_design(m, J_LIN)
    p_star = np.array([1.6, -0.5, 0.4, 0.3])
    plant = LinearPlant(J_LIN, p_star, noise=0.02, seed=5)
    s = learn(m, d, plant, iterations=30, rule=make_rule(name, d))
    lower, upper = bounds_arrays(m.parameters)
    flown = np.array(plant.flown)
    assert np.all(flown >= lower - 1e-12) and np.all(flown <= upper + 1e-12)
    # the constrained optimum: p0 = 1 and the rest minimizing ‖J (p − p*)‖
    from scipy.optimize import lsq_linear
    best = lsq_linear(J_LIN, J_LIN @ p_star, bounds=(lower, upper)).x
    final_error = np.linalg.norm(J_LIN @ (s.final_params - p_star))
    optimal_error = np.linalg.norm(J_LIN @ (best - p_star))
    if name == "paper":
        # the paper's rule scales the whole step (Sect. 4.2): with p0 pinned it settles where
        # its unconstrained step no longer pushes outwards, not at the constrained optimum
        assert final_error > optimal_error + 0.02
    else:
        assert final_error < optimal_error + 0.05, (final_error, optimal_error)


@pytest.mark.parametrize("name", ["tsvd", "damped", "kalman", "broyden", "kalman+isc", "tsvd+isc"])
def test_state_is_json_and_resumes_exactly(name):
    S = np.array([[1.0, 0.0], [0.0, 2.0], [0.5, 0.5], [0.0, 0.0]])
    isc = {"isc": IscModel(S, lambda trial, p: trial.start_state)} if name.endswith("+isc") else {}
    plant = LinearPlant(J_LIN, P_STAR, S=S, start_std=0.1, seed=6)
    rule = make_rule(name, D_LIN, **isc)
    s = learn(LIN, D_LIN, plant, iterations=8, rule=rule)
    state = json.loads(json.dumps(rule.state()))
    fresh = make_rule(name, D_LIN, **isc)
    fresh.load_state(state)
    trial = plant.fly(LIN.program(s.final_params))
    a, ga = rule.propose(9, s.final_params, trial.final_state, trial)
    b, gb = fresh.propose(9, s.final_params, trial.final_state, trial)
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)
    assert ga == pytest.approx(gb)


def test_kalman_gain_falls_like_one_over_n_and_stops_chasing_noise():
    rule = make_rule("kalman", D_LIN, drift=0.0, noise=np.full(4, 0.2))
    s = learn(LIN, D_LIN, LinearPlant(J_LIN, P_STAR, noise=0.2, seed=7), iterations=40, rule=rule)
    gains = np.array([it.gamma for it in s.measured])
    assert gains[0] > 0.99
    np.testing.assert_allclose(gains[9], 1 / 10, rtol=0.05)
    np.testing.assert_allclose(gains[39], 1 / 40, rtol=0.05)
    # parameters stop moving with the noise: late steps are tiny against the noise-driven first ones
    steps = np.linalg.norm(np.diff(np.array([it.params for it in s.measured]), axis=0), axis=1)
    assert steps[-10:].mean() < 0.1 * steps[1:4].mean()
    assert dist(s)[-1] < 0.15


def test_kesten_steps_stay_full_while_the_error_keeps_its_sign():
    # the true plant responds at 40 % of the model: the paper's 1/i steps crawl, Kesten's
    # per-direction steps stay at γ = 1 while each error component keeps its sign
    J_true = 0.4 * J_LIN
    paper = learn(LIN, D_LIN, LinearPlant(J_true, P_STAR, noise=0.01, seed=8), iterations=12)
    kesten = learn(LIN, D_LIN, LinearPlant(J_true, P_STAR, noise=0.01, seed=8), iterations=12,
                   rule=make_rule("tsvd", D_LIN, noise=np.full(4, 0.01)))
    assert dist(kesten)[-1] < 0.2 * dist(paper)[-1]
    assert kesten.measured[5].gamma > 0.5  # the paper: 1/6


def test_broyden_learns_a_wrong_jacobian():
    # the true response along one (rotated) direction is a quarter of the model's: C·J_true has
    # an eigenvalue 0.25. Fixed-J rules crawl along it; the secant update learns it.
    rng = np.random.default_rng(0)
    q = np.linalg.qr(rng.standard_normal((4, 4)))[0][:, 0]
    J_true = J_LIN @ (np.eye(4) - 0.75 * np.outer(q, q))
    noise = {"noise": np.full(4, 0.01)}
    runs = {}
    for label, rule in (("paper", make_rule("paper", D_LIN)), ("tsvd", make_rule("tsvd", D_LIN, **noise)),
                        ("broyden", make_rule("broyden", D_LIN, **noise)),
                        ("kalman+broyden", make_rule("kalman", D_LIN, broyden=True, **noise))):
        s = learn(LIN, D_LIN, LinearPlant(J_true, P_STAR, noise=0.01, seed=9), iterations=10, rule=rule)
        runs[label] = dist(s)
        if "broyden" in label:
            assert rule.jacobian.updates >= 2
    print({k: np.round(v[[2, 6, 9]], 3) for k, v in runs.items()})
    assert runs["broyden"][6] < 0.5 * runs["tsvd"][6] < 0.5 * runs["paper"][6]
    assert runs["kalman+broyden"][9] < 0.1


def test_broyden_safeguards():
    Js0 = np.diag([10.0, 1.0, 0.1])
    jac = BroydenJacobian(Js0, mode="full", validate_after=2)
    noise = np.full(3, 0.1)
    assert jac.update(np.array([1e-4, 0, 0]), np.array([1.0, 0, 0]), noise).startswith("skipped")  # noise only
    assert jac.update(np.array([1.0, 0, 0]), np.array([30.0, 0, 0]), noise) == "updated"
    assert jac.Js[0, 0] <= 10.0 * (1 + 0.5) + 1e-9  # limited update size
    # the nominal J predicts the next pairs better: back to J⁰
    jac.update(np.array([0.0, 1.0, 0]), np.array([0.0, 1.0, 0]), noise)
    jac.update(np.array([1.0, 0.0, 0]), np.array([10.0, 0.0, 0]), noise)
    assert jac.resets == 1 and np.array_equal(jac.Js, Js0)
    diag = BroydenJacobian(Js0, mode="diagonal", max_gain=3.0)
    diag.update(np.array([0.0, 10.0, 0]), np.array([0.0, 100.0, 0]), noise)
    assert diag.alpha[1] <= 3.0 and np.allclose(diag.alpha[[0, 2]], 1.0)


def isc_runs(inner: str, wrap: bool, center: bool = True, seeds: int = 6) -> float:
    """Mean parameter distance from p* over trials 11–20 with start-state scatter S·δ."""
    S = np.array([[1.0, 0.0], [0.0, 2.0], [0.5, 0.5], [0.0, 0.0]])
    finals = []
    for seed in range(seeds):
        plant = LinearPlant(J_LIN, P_STAR, noise=0.01, S=S, start_std=0.3, seed=seed)
        schedule = ScheduleChoice("constant", value=0.5) if inner == "paper" else None
        rule = make_rule(RuleChoice(inner, schedule=schedule), D_LIN)
        if wrap:
            rule = InitialStateCompensation(rule, S, lambda trial, p: trial.start_state, center=center)
        finals.append(np.mean(dist(learn(LIN, D_LIN, plant, iterations=20, rule=rule))[-10:]))
    return float(np.mean(finals))


def test_initial_state_compensation_steadies_a_fixed_gain_rule():
    # γ = 0.5 forgets fast, so every trial's start-state scatter moves the parameters
    plain, compensated = isc_runs("paper", False), isc_runs("paper", True)
    assert compensated < 0.6 * plain, (plain, compensated)


def test_initial_state_compensation_and_an_averaging_rule():
    # the mean of centred compensated errors equals the mean of raw ones: a rule that averages
    # (Kalman, 1/n gain) gains nothing unless the mean start deviation is known (here: zero)
    plain = isc_runs("kalman", False)
    centred = isc_runs("kalman", True)
    known_mean = isc_runs("kalman", True, center=False)
    assert 0.8 * plain < centred < 1.25 * plain, (plain, centred)
    assert known_mean < 0.3 * plain, (plain, known_mean)


def test_compensation_is_centred_on_the_mean_start_deviation():
    # a constant start offset is part of the offset learning must absorb, not noise
    S = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0], [0.0, 0.0]])
    rule = InitialStateCompensation(make_rule("kalman", D_LIN), S, lambda trial, p: trial.start_state + 0.5)
    plant = LinearPlant(J_LIN, P_STAR, noise=0.01, S=S, start_std=0.05, seed=1)
    s = learn(LIN, D_LIN, plant, iterations=20, rule=rule)
    raw = np.array([it.error for it in s.measured])
    assert np.abs(raw[-10:].mean(axis=0)).max() < 0.05
    state = json.loads(json.dumps(rule.state()))
    assert state["deviation_count"] == 20


# ------------------------------------------------------------------ quadrocopter helpers

CONFIG = hummingbird()
FLIP3 = MultiFlip(vehicle=CONFIG.vehicle, flips=3, dims=3)
POSITION = [0, 2, 5]


@pytest.fixture(scope="module")
def design3():
    return design(FLIP3, NominalModel(CONFIG))


def position_errors(session) -> np.ndarray:
    return np.array([np.linalg.norm(it.error[POSITION]) for it in session.measured])


def first_below(pos: np.ndarray, threshold: float = 0.12) -> int:
    hits = np.nonzero(pos < threshold)[0]
    return int(hits[0]) + 1 if hits.size else len(pos) + 1


def test_initial_state_sensitivity_is_physical(design3):
    S = initial_state_sensitivity(FLIP3, NominalModel(CONFIG), design3.p_nominal)
    assert S.shape == (9, 12)
    T = design3.duration_s
    # a start offset carries straight through; a start velocity drifts for the whole maneuver
    assert S[0, 1] == pytest.approx(1.0, abs=1e-6) and S[2, 2] == pytest.approx(1.0, abs=1e-6)
    assert S[0, 4] == pytest.approx(T, rel=0.05) and S[1, 4] == pytest.approx(1.0, abs=1e-6)
    # a small roll at the start ends as a roll error and tilts the thrust sideways
    assert S[4, 6] == pytest.approx(1.0, abs=0.05)
    assert abs(S[0, 6]) > 1.0
    nominal = FLIP3.initial_state()
    measured = nominal.copy()
    measured[13:17] = np.nan  # thrusts: never measured
    measured[17:20] = 5.0  # revolution counter: meaningless at the start
    measured[0] += 0.01
    measured[6:10] = -measured[6:10]  # q and −q: the same attitude
    dev = start_state_deviation(measured, nominal)
    np.testing.assert_allclose(dev, [0.01] + [0.0] * 11, atol=1e-12)


@pytest.fixture(scope="module")
def default_sessions(design3):
    isc = quadrotor_isc(FLIP3, CONFIG, design3.p_nominal)
    out = {}
    for seed in (1, 2, 3):
        for name in ("paper", BEST):
            options = {"isc": isc} if name.endswith("+isc") else {}
            rule = make_rule(name, design3, **options)
            out[name, seed] = learn(FLIP3, design3, Arena(CONFIG, seed=seed), iterations=30, rule=rule)
    return out


BEST = "kalman"


def test_best_rule_on_the_3d_triple_flip(default_sessions):
    firsts, fractions, last10 = [], [], {"paper": [], BEST: []}
    for (name, _seed), s in default_sessions.items():
        assert s.status == "completed"
        pos = position_errors(s)
        last10[name].append(pos[-10:].mean())
        if name == BEST:
            k = first_below(pos)
            firsts.append(k)
            fractions.append(np.mean(pos[k:] < 0.12))
    print(f"{BEST}: first below 0.12 m {firsts}, later fraction {np.round(fractions, 2)}, "
          f"last-10 {np.mean(last10[BEST]):.4f} vs paper+TSVD {np.mean(last10['paper']):.4f}")
    assert np.median(firsts) <= 4
    assert np.mean(fractions) >= 0.8
    # three seeds are a noisy sample of the 20-seed comparison in docs/rules.md
    assert np.mean(last10[BEST]) <= 1.1 * np.mean(last10["paper"])


def test_rules_handle_lost_triggers_and_bounds_on_the_arena(design3):
    params = ArenaParams().replace(links__command_drop_probability=0.3)
    lower, upper = bounds_arrays(FLIP3.parameters)
    lost = 0
    for name in ("tsvd", "damped", "kalman", "broyden"):
        s = learn(FLIP3, design3, Arena(CONFIG, params, seed=2), iterations=8, rule=make_rule(name, design3))
        assert s.status == "completed", name
        lost += sum(it.status == "no_trigger" for it in s.iterations)
        for it in s.iterations:
            assert np.all(it.params >= lower) and np.all(it.params <= upper)
        assert position_errors(s)[-3:].mean() < 0.2, name
    assert lost >= 4


def wrong_inertia(factor: float) -> VehicleConfig:
    v = CONFIG.vehicle
    wrong = dataclasses.replace(v, inertia_xx_kg_m2=v.inertia_xx_kg_m2 * factor,
                                inertia_yy_kg_m2=v.inertia_yy_kg_m2 * factor,
                                inertia_zz_kg_m2=v.inertia_zz_kg_m2 * factor)
    return VehicleConfig(vehicle=wrong, controller=CONFIG.controller, name="wrong inertia")


def test_design_with_half_the_inertia():
    # designed on a model with half the true inertia (maneuver and Jacobian), flown on the
    # arena built with the correct nominal vehicle. The paper's rule loses trials to its
    # constraint handling (Sect. 4.2: the recover collective sits at β̄ and whole steps are
    # scaled down); the bounded projection of the new rules does not. On this arena the
    # Broyden update itself rarely fires (a parameter sits on a bound) — see docs/rules.md.
    cfg = wrong_inertia(0.5)
    flip = MultiFlip(vehicle=cfg.vehicle, flips=3, dims=3)
    d = design(flip, NominalModel(cfg))
    for seed in (1, 2):
        paper = position_errors(learn(flip, d, Arena(CONFIG, seed=seed), iterations=12, rule=make_rule("paper", d)))
        broyden = position_errors(learn(flip, d, Arena(CONFIG, seed=seed), iterations=12,
                                        rule=make_rule("broyden", d)))
        print(f"seed {seed}: first below 0.12 m: paper {first_below(paper)}, broyden {first_below(broyden)}; "
              f"mean of trials 3-10: paper {paper[2:10].mean():.3f} m, broyden {broyden[2:10].mean():.3f} m")
        assert first_below(broyden) <= 5
        assert first_below(paper) >= first_below(broyden) + 2
        assert broyden[2:10].mean() < 0.75 * paper[2:10].mean()


@pytest.mark.slow
def test_initial_state_compensation_with_fivefold_start_error(design3):
    # start-state error ×5 (the arena's hover residual: 7.5 cm/s per axis, 15 mrad tilt). The
    # raw final error is then dominated by each trial's own start (≈0.24 m rms): no update
    # rule can remove that after the fact. What learning controls is the error its
    # parameters make from the mean start, e − S(δ − δ̄) ("start-corrected"); with a rule
    # that forgets fast (γ = 0.5) compensation halves it. Averaging rules see no measurable
    # change (docs/rules.md, 20 seeds).
    params = ArenaParams().replace(**START5)
    isc = quadrotor_isc(FLIP3, CONFIG, design3.p_nominal)
    S, dev = isc.sensitivity, isc.deviation
    corrected: dict[str, list[float]] = {"plain": [], "isc": []}
    raw: dict[str, list[float]] = {"plain": [], "isc": []}
    for seed in range(1, 7):
        for label, name in (("plain", "paper"), ("isc", "paper+isc")):
            options = {"isc": isc} if label == "isc" else {}
            choice = RuleChoice.parse(name, schedule=ScheduleChoice("constant", value=0.5))
            rule = make_rule(choice, design3, **options)
            # open loop, as the compensation is measured in docs/rules.md: the arena's default onboard
            # feedback (tracking, since the feedback work) removes most of the start error itself
            s = learn(FLIP3, design3, Arena(CONFIG, params, seed=seed, feedback="none"), iterations=30, rule=rule)
            devs = np.array([dev(it.trial, it.params) for it in s.measured])
            devs -= devs.mean(axis=0)
            errors = np.array([it.error for it in s.measured])
            corrected[label].append(np.linalg.norm((errors - devs @ S.T)[-10:][:, POSITION], axis=1).mean())
            raw[label].append(position_errors(s)[-10:].mean())
    print(f"last 10, start-corrected: {np.mean(corrected['plain']):.4f} → {np.mean(corrected['isc']):.4f} m; "
          f"raw: {np.mean(raw['plain']):.4f} → {np.mean(raw['isc']):.4f} m")
    assert np.mean(corrected["isc"]) < 0.7 * np.mean(corrected["plain"])
    assert np.mean(raw["isc"]) < np.mean(raw["plain"]) + 0.01


START5 = {"disturbances__start_velocity_std_m_s": 0.075, "disturbances__start_tilt_std_rad": 0.015}


def test_early_trajectory_deviation_sees_a_start_offset(design3):
    arena = Arena(CONFIG, ArenaParams.ideal(), seed=1)
    trial = arena.fly(FLIP3.program(design3.p_nominal))
    dev = early_trajectory_deviation(FLIP3, CONFIG, trial, design3.p_nominal)
    assert np.all(np.abs(dev[:3]) < 2e-3) and np.all(np.abs(dev[6:9]) < 2e-3)
    shifted = dataclasses.replace(trial, states=trial.states + np.r_[[0.05, 0, 0], np.zeros(17)])
    dev2 = early_trajectory_deviation(FLIP3, CONFIG, shifted, design3.p_nominal)
    assert dev2[0] - dev[0] == pytest.approx(0.05, abs=1e-9)
