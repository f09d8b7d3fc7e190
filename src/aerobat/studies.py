"""Studies: many independent designs or learning runs (Monte Carlo robustness, envelope maps).

Each study is a list of :class:`~aerobat.execution.Job` built from a seed, run by an
executor (local pool or Dask), and summarized. The job functions here are pure:
same specification and seed, same result, on any machine.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .config import ConfigError, check_range, dataclass_from_table, dataclass_to_table, read_toml
from .execution import Job, job_kind

__all__ = [
    "RobustnessRanges",
    "envelope_jobs",
    "load_ranges",
    "robustness_jobs",
    "sample_arena",
    "summarize_robustness",
]


# ------------------------------------------------------------------ sampling


@dataclass(frozen=True, kw_only=True)
class RobustnessRanges:
    """Uniform ranges from which each sampled vehicle's arena is drawn.

    Scales multiply the arena defaults (``docs/plants.md``); "± x" ranges are
    relative (0.05 = ±5 %). Units in field names.
    """

    mass_scale: tuple[float, float] = (0.98, 1.08)
    inertia_scale: tuple[float, float] = (1.00, 1.25)
    inertia_zz_scale: tuple[float, float] = (1.05, 1.35)
    drag_constant_scale: tuple[float, float] = (1.00, 1.30)
    motor_rate_up_per_s: tuple[float, float] = (62.0, 80.0)
    motor_rate_down_per_s: tuple[float, float] = (40.0, 55.0)
    thrust_gain_spread: float = 0.04
    com_offset_m: float = 0.006
    aerodynamics_scale: tuple[float, float] = (0.7, 1.3)
    noise_scale: tuple[float, float] = (0.7, 1.3)

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, tuple):
                lo, hi = value
                check_range(f"{f.name}[0]", lo, low=0.0)
                check_range(f"{f.name}[1]", hi, low=lo)
            else:
                check_range(f.name, value, low=0.0, high=0.5)


def load_ranges(path: str | Path) -> RobustnessRanges:
    """Read robustness ranges from a TOML file (a ``[ranges]`` table; omitted fields keep defaults)."""
    data = read_toml(path)
    unknown = sorted(set(data) - {"ranges"})
    if unknown:
        raise ConfigError(f"{path}: unknown table(s) {', '.join(unknown)}; allowed: [ranges]")
    return dataclass_from_table(RobustnessRanges, data.get("ranges", {}), source=f"{path}: [ranges]")


SAMPLED_PROPERTIES = (
    "mass_scale", "inertia_xx_scale", "inertia_yy_scale", "inertia_zz_scale", "drag_constant_scale",
    "motor_rate_up_per_s", "motor_rate_down_per_s", "thrust_gain_min", "com_offset_norm_m",
    "aerodynamics_scale", "noise_scale",
)


def sample_arena(ranges: RobustnessRanges, seed: int) -> tuple[dict[str, Any], dict[str, float]]:
    """One sampled vehicle: (arena table for :class:`ArenaParams`, the sampled properties)."""
    from .plants.arena.params import ArenaParams

    rng = np.random.default_rng(seed)

    def u(bounds: tuple[float, float]) -> float:
        return float(rng.uniform(bounds[0], bounds[1]))

    base = ArenaParams()
    ixx, iyy, izz = u(ranges.inertia_scale), u(ranges.inertia_scale), u(ranges.inertia_zz_scale)
    g = 1.0 + ranges.thrust_gain_spread * rng.uniform(-1, 1, 4)
    gains = (float(g[0]), float(g[1]), float(g[2]), float(g[3]))
    c = ranges.com_offset_m * rng.uniform(-1, 1, 2)
    com = (float(c[0]), float(c[1]), 0.0)
    aero = u(ranges.aerodynamics_scale)
    noise = u(ranges.noise_scale)
    props = {
        "mass_scale": u(ranges.mass_scale),
        "inertia_xx_scale": ixx,
        "inertia_yy_scale": iyy,
        "inertia_zz_scale": izz,
        "drag_constant_scale": u(ranges.drag_constant_scale),
        "motor_rate_up_per_s": u(ranges.motor_rate_up_per_s),
        "motor_rate_down_per_s": u(ranges.motor_rate_down_per_s),
        "thrust_gain_min": min(gains),
        "com_offset_norm_m": float(np.hypot(com[0], com[1])),
        "aerodynamics_scale": aero,
        "noise_scale": noise,
    }
    a, d, mc = base.aerodynamics, base.disturbances, base.motion_capture
    params = base.replace(
        true_vehicle=dataclasses.replace(
            base.true_vehicle, mass_scale=props["mass_scale"], inertia_scale=(ixx, iyy, izz),
            drag_constant_scale=props["drag_constant_scale"], motor_rate_up_per_s=props["motor_rate_up_per_s"],
            motor_rate_down_per_s=props["motor_rate_down_per_s"], thrust_gains=gains, com_offset_m=com),
        aerodynamics=dataclasses.replace(
            a, body_drag_n_s2_m2=a.body_drag_n_s2_m2 * aero, rotor_drag_s_m=a.rotor_drag_s_m * aero,
            rotational_damping_n_m_s=(a.rotational_damping_n_m_s[0] * aero, a.rotational_damping_n_m_s[1] * aero,
                                      a.rotational_damping_n_m_s[2] * aero)),
        disturbances=dataclasses.replace(
            d, wind_std_m_s=d.wind_std_m_s * noise, gust_amplitude_std_m_s=d.gust_amplitude_std_m_s * noise,
            thrust_gain_jitter=d.thrust_gain_jitter * noise, motor_gain_jitter=d.motor_gain_jitter * noise),
        motion_capture=dataclasses.replace(
            mc, position_noise_m=mc.position_noise_m * noise, attitude_noise_rad=mc.attitude_noise_rad * noise),
    )
    return dataclass_to_table(params), props


# ------------------------------------------------------------------ job kinds


def _design_from_table(maneuver: Any, table: dict[str, Any]):
    from .design import Design

    return Design(
        maneuver=maneuver,
        p_guess=np.asarray(table["p_guess"], dtype=float),
        p_nominal=np.asarray(table["p_nominal"], dtype=float),
        residual=np.asarray(table["residual"], dtype=float),
        residual_norm=float(table["residual_norm"]),
        converged=bool(table["converged"]),
        status=str(table["status"]),
        message=str(table["message"]),
        jacobian=np.asarray(table["jacobian"], dtype=float),
        correction=np.asarray(table["correction"], dtype=float),
        correction_kind=str(table["correction_kind"]),
        singular_values=np.asarray(table["singular_values"], dtype=float),
        condition_number=float(table["condition_number"]),
        rank=int(table["rank"]),
        duration_s=float(table["duration_s"]),
        compute_s=float(table["compute_s"]),
        evaluations=0,
    )


def position_indices(maneuver: Any) -> list[int]:
    """Indices of the position errors (unit m) of a maneuver's error vector."""
    return [k for k, e in enumerate(maneuver.errors) if e.unit == "m"]


def _learning_setup(spec: dict[str, Any]) -> tuple[Any, Any, Any, Any]:
    """(maneuver, design, nominal config, plant) of a learning job; the design travels in the spec."""
    from .maneuvers.registry import from_spec
    from .plants.arena import Arena
    from .plants.arena.params import ArenaParams
    from .vehicle import ControllerParams, VehicleConfig

    maneuver = from_spec(spec["maneuver"])
    design = _design_from_table(maneuver, spec["design"])
    vehicle = maneuver.vehicle  # type: ignore[attr-defined]
    config = VehicleConfig(vehicle=vehicle, controller=ControllerParams.nominal_for(vehicle))
    if spec.get("plant", "arena") == "rotorpy":
        from .plants.rotorpy import RotorPyPlant

        plant: Any = RotorPyPlant(config, seed=int(spec["seed"]))
    else:
        params = dataclass_from_table(ArenaParams, spec["arena"], source="job arena")
        plant = Arena(config, params, seed=int(spec["seed"]))
    return maneuver, design, config, plant


@job_kind("learn")
def learn_job(spec: dict[str, Any]) -> dict[str, Any]:
    """Design-free learning run: the design travels in the spec (computed once per study)."""
    from .learning import learn

    start = time.perf_counter()
    maneuver, design, _, plant = _learning_setup(spec)
    rule = None
    if spec.get("rule", "paper") != "paper":
        from .rules import make_rule

        rule = make_rule(spec["rule"], design)
    session = learn(maneuver, design, plant, iterations=int(spec["iterations"]), rule=rule)
    idx = position_indices(maneuver)
    errors = [float(np.linalg.norm(it.error[idx])) for it in session.measured]
    tol = float(spec.get("tolerance_m", 0.12))
    first_below = next((k + 1 for k, e in enumerate(errors) if e < tol), None)
    last = errors[-10:] if errors else [math.nan]
    return {
        "status": session.status,
        "message": session.message,
        "position_errors_m": errors,
        "first_error_m": errors[0] if errors else math.nan,
        "final_error_m": float(np.mean(last)),
        "trials_to_tolerance": first_below,
        "success": bool(session.status == "completed" and float(np.mean(last)) <= tol),
        "final_params": session.final_params.tolist(),
        "lost_trials": sum(1 for it in session.iterations if it.status == "no_trigger"),
        "properties": spec.get("properties", {}),
        "wall_s": time.perf_counter() - start,
    }


@job_kind("design")
def design_job(spec: dict[str, Any]) -> dict[str, Any]:
    """Nominal design of one maneuver: feasibility, duration, apex height, conditioning."""
    from .design import design
    from .dynamics import POS
    from .maneuvers.registry import from_spec
    from .simulate import NominalModel, simulate
    from .vehicle import ControllerParams, VehicleConfig

    maneuver = from_spec(spec["maneuver"])
    vehicle = maneuver.vehicle  # type: ignore[attr-defined]
    config = VehicleConfig(vehicle=vehicle, controller=ControllerParams.nominal_for(vehicle))
    result = design(maneuver, NominalModel(config))
    apex = math.nan
    lowest = math.nan
    if result.converged:
        traj = simulate(maneuver.program(result.p_nominal), config)
        apex = float(traj.states[:, POS][:, 2].max())
        lowest = float(traj.states[:, POS][:, 2].min())
    return {
        "status": result.status,
        "message": result.message,
        "converged": result.converged,
        "duration_s": result.duration_s if result.converged else math.nan,
        "apex_m": apex,
        "lowest_m": lowest,
        "condition_number": result.condition_number if result.converged else math.nan,
        "residual_norm": result.residual_norm,
        "p_nominal": result.p_nominal.tolist(),
    }


@job_kind("benchmark")
def benchmark_job(spec: dict[str, Any]) -> dict[str, Any]:
    from .timeoptimal import BenchmarkLimits, solve_translation

    limits = BenchmarkLimits(**spec.get("limits", {}))
    solution = solve_translation(float(spec["y_m"]), float(spec["z_m"]), limits=limits)
    return {"status": solution.status, "message": solution.message,
            "duration_s": solution.duration_s if solution.ok else math.nan}


# ------------------------------------------------------------------ studies


def robustness_jobs(maneuver: Any, design: Any, *, vehicles: int, iterations: int, seed: int,
                    ranges: RobustnessRanges | None = None, rule: str = "paper",
                    tolerance_m: float = 0.12) -> list[Job]:
    """One learning job per sampled vehicle; vehicle k's sample and arena seed derive from ``seed`` and k."""
    ranges = ranges or RobustnessRanges()
    design_table = {k: v for k, v in design.to_json_dict().items() if k != "maneuver"}
    jobs = []
    for k in range(vehicles):
        arena, props = sample_arena(ranges, seed * 1_000_003 + k)
        jobs.append(Job(key=f"vehicle-{k:05d}", kind="learn", spec={
            "maneuver": maneuver.spec(), "design": design_table, "arena": arena, "properties": props,
            "seed": seed * 1_000_003 + k, "iterations": iterations, "rule": rule, "tolerance_m": tolerance_m,
        }))
    return jobs


def envelope_jobs(base_spec: dict[str, Any], flips: list[int], rates_deg_s: list[float]) -> list[Job]:
    """One design job per (flip count, max rate) of a flip specification."""
    jobs = []
    for n in flips:
        for rate in rates_deg_s:
            spec = dict(base_spec, flips=int(n), max_rate_rad_s=math.radians(rate))
            jobs.append(Job(key=f"flips-{n}-rate-{rate:g}", kind="design", spec={"maneuver": spec}))
    return jobs


@dataclass(frozen=True)
class RobustnessSummary:
    vehicles: int
    completed: int
    success_rate: float
    median_trials_to_tolerance: float
    trials_to_tolerance: list[int | None]
    final_errors_m: list[float]
    predictors: list[tuple[str, float]] = field(default_factory=list)


def summarize_robustness(results: list[dict[str, Any]]) -> RobustnessSummary:
    """Success rate, trials-to-tolerance distribution, and which properties predict failure.

    A property's predictive strength is the (point-biserial) correlation between the
    property and failure, listed strongest first.
    """
    done = [r for r in results if r.get("status") != "error"]
    success = np.array([bool(r.get("success")) for r in done])
    ttt = [r.get("trials_to_tolerance") for r in done]
    reached = [t for t in ttt if t is not None]
    predictors: list[tuple[str, float]] = []
    if len(done) >= 3 and 0 < success.sum() < len(done):
        for name in SAMPLED_PROPERTIES:
            values = np.array([r["properties"].get(name, math.nan) for r in done], dtype=float)
            if np.all(np.isfinite(values)) and values.std() > 0:
                predictors.append((name, float(np.corrcoef(values, ~success)[0, 1])))
        predictors.sort(key=lambda p: -abs(p[1]))
    return RobustnessSummary(
        vehicles=len(results),
        completed=len(done),
        success_rate=float(success.mean()) if len(done) else math.nan,
        median_trials_to_tolerance=float(np.median(reached)) if reached else math.nan,
        trials_to_tolerance=ttt,
        final_errors_m=[float(r.get("final_error_m", math.nan)) for r in done],
        predictors=predictors,
    )


# ------------------------------------------------------------------ rules study

MODEL_FREE = ("cma", "bayesopt")


def _weighted_cost(maneuver: Any, error: np.ndarray) -> float:
    scales = np.array([e.scale for e in maneuver.errors])
    return float(np.linalg.norm(error / scales))


def _fly_measured(plant: Any, maneuver: Any, params: np.ndarray, max_retries: int = 20):
    """Fly until a trial is measured (lost triggers are retried, as learning does); None on crash."""
    for _ in range(max_retries):
        trial = plant.fly(maneuver.program(params))
        if trial.status == "ok":
            error = maneuver.error(trial.final_state)
            if np.all(np.isfinite(error)):
                return error
        elif trial.status in ("crashed", "aborted"):
            return None
    return None


def _model_free(method: str, maneuver: Any, design: Any, plant: Any, trials: int, seed: int) -> dict[str, Any]:
    """CMA-ES or Bayesian optimization of the weighted final-state error, one trial per evaluation.

    Both search in scaled coordinates (parameter / its scale) around p⁰ within the
    parameter bounds, with their libraries' default settings otherwise (CMA-ES: default
    population 4 + 3 ln n; Bayesian optimization: default GP and acquisition, p⁰ probed
    first). The search width is ours to choose: σ₀ = 0.25 scales for CMA-ES and a box of
    ±1.5 scales for Bayesian optimization — with σ₀ = 1 scale (±20 ms on the coast
    duration, ±36° of flip angle) the first triple-flip samples already crash.
    """
    from .maneuvers.base import bounds_arrays

    lower, upper = bounds_arrays(maneuver.parameters)
    scales = np.array([p.scale for p in maneuver.parameters])
    p0 = np.asarray(design.p_nominal, dtype=float)
    lo = np.maximum((lower - p0) / scales, -1.5)
    hi = np.minimum((upper - p0) / scales, 1.5)
    errors: list[np.ndarray] = []
    status = "completed"

    def evaluate(z: np.ndarray) -> float | None:
        params = np.clip(p0 + scales * np.asarray(z, dtype=float), lower, upper)
        error = _fly_measured(plant, maneuver, params)
        if error is None:
            return None
        errors.append(error)
        return _weighted_cost(maneuver, error)

    if method == "cma":
        import cma

        es = cma.CMAEvolutionStrategy(np.zeros(p0.size), 0.25, {"bounds": [list(lo), list(hi)], "seed": seed + 1,
                                                              "verbose": -9})
        while len(errors) < trials and not es.stop():
            candidates = es.ask()
            values = []
            for z in candidates:
                if len(errors) >= trials:
                    break
                v = evaluate(z)
                if v is None:
                    status = "crashed"
                    break
                values.append(v)
            if status != "completed" or len(values) < len(candidates):
                break
            es.tell(candidates, values)
    elif method == "bayesopt":
        from bayes_opt import BayesianOptimization

        names = [p.name for p in maneuver.parameters]
        optimizer = BayesianOptimization(f=None, pbounds={n: (float(a), float(b)) for n, a, b in zip(names, lo, hi,
                                                                                                   strict=True)},
                                         random_state=seed, verbose=0, allow_duplicate_points=True)
        point: dict[str, Any] = {n: 0.0 for n in names}
        while len(errors) < trials:
            v = evaluate(np.array([point[n] for n in names]))
            if v is None:
                status = "crashed"
                break
            optimizer.register(params=point, target=-v)
            point = optimizer.suggest()
    else:
        raise ValueError(f"unknown model-free method {method!r}")
    return {"errors": errors, "status": status}


@job_kind("rule_run")
def rule_run_job(spec: dict[str, Any]) -> dict[str, Any]:
    """One method (update rule or model-free baseline) learning one maneuver on one plant seed."""
    from .learning import learn

    start = time.perf_counter()
    maneuver, design, config, plant = _learning_setup(spec)
    method = spec["method"]
    trials = int(spec["trials"])
    if method in MODEL_FREE:
        outcome = _model_free(method, maneuver, design, plant, trials, int(spec["seed"]))
        errors, status = outcome["errors"], outcome["status"]
    else:
        from .rules import make_rule

        options: dict[str, Any] = {}
        if method.endswith("+isc"):
            from .rules_quadrotor import quadrotor_isc

            options["sensitivity"], options["deviation"] = quadrotor_isc(maneuver, config, design.p_nominal)
        session = learn(maneuver, design, plant, iterations=trials, rule=make_rule(method, design, **options))
        errors, status = [it.error for it in session.measured], session.status
    idx = position_indices(maneuver)
    pos = [float(np.linalg.norm(np.asarray(e)[idx])) for e in errors]
    tol = float(spec.get("tolerance_m", 0.12))
    first = next((k + 1 for k, e in enumerate(pos) if e < tol), None)
    later = pos[first:] if first is not None else []
    last = pos[-10:] if pos else [math.nan]
    diverged = bool(pos and np.mean(last) > pos[0])
    return {
        "method": method,
        "status": status,
        "position_errors_m": pos,
        "trials_to_tolerance": first,
        "share_below_after": (float(np.mean([e < tol for e in later])) if later
                              else (math.nan if first is None else 1.0)),
        "last10_mean_m": float(np.mean(last)),
        "failed": bool(status != "completed" or diverged or len(pos) < trials),
        "wall_s": time.perf_counter() - start,
    }


def rules_study_jobs(maneuver: Any, design: Any, *, methods: list[str], seeds: int, trials: int, seed: int = 0,
                     arena: dict[str, Any] | None = None, tolerance_m: float = 0.12,
                     plant: str = "arena") -> list[Job]:
    """Every method on the same ``seeds`` plant seeds (seed, seed + 1, …); ``plant`` is arena or rotorpy."""
    from .plants.arena.params import ArenaParams

    arena = arena if arena is not None else dataclass_to_table(ArenaParams())
    design_table = {k: v for k, v in design.to_json_dict().items() if k != "maneuver"}
    return [
        Job(key=f"{method}-seed-{seed + k:04d}", kind="rule_run", spec={
            "maneuver": maneuver.spec(), "design": design_table, "arena": arena, "method": method,
            "seed": seed + k, "trials": trials, "tolerance_m": tolerance_m, "plant": plant})
        for method in methods for k in range(seeds)
    ]


def summarize_rules(results: list[dict[str, Any]], trials: int) -> list[dict[str, Any]]:
    """Per method: median trials to tolerance, share staying below, last-10 mean, failures, wall time."""
    rows = []
    for method in dict.fromkeys(r["method"] for r in results):
        runs = [r for r in results if r["method"] == method]
        ttt = [r["trials_to_tolerance"] if r["trials_to_tolerance"] is not None else math.inf for r in runs]
        shares = [r["share_below_after"] for r in runs if not math.isnan(r["share_below_after"])]
        rows.append({
            "method": method,
            "runs": len(runs),
            "median_trials_to_tolerance": float(np.median(ttt)),
            "reached": sum(1 for t in ttt if math.isfinite(t)),
            "share_below_after": float(np.mean(shares)) if shares else math.nan,
            "last10_mean_m": float(np.mean([r["last10_mean_m"] for r in runs])),
            "failures": sum(1 for r in runs if r["failed"]),
            "wall_s": float(np.mean([r["wall_s"] for r in runs])),
        })
    return rows
