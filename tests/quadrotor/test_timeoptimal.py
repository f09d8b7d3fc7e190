"""Tests of the time-optimal hover-to-hover benchmark (aerobat.timeoptimal)."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

casadi = pytest.importorskip("casadi")

from aerobat.experiments import LocalExecutor, run_study  # noqa: E402
from aerobat.experiments.studies import map_csv, map_grid, map_jobs  # noqa: E402
from aerobat.plotting import save_figure  # noqa: E402
from aerobat.plotting.benchmarks import plot_map, plot_solution  # noqa: E402
from aerobat.quadrotor.timeoptimal import (  # noqa: E402
    BenchmarkLimits,
    InputArc,
    TimeOptimalSolution,
    solve_translation,
    switch_times,
)
from aerobat.store import Store  # noqa: E402

LIM = BenchmarkLimits()
G = LIM.gravity_m_s2


# --------------------------------------------------------------------------
# independent helpers (written here, not taken from the module)
# --------------------------------------------------------------------------
def rk4_replay(sol: TimeOptimalSolution, steps_per_piece: int = 400) -> np.ndarray:
    """Integrate the solution's public input program with fixed-step RK4.

    Steps are aligned with the switch times so each step sees smooth inputs.
    """
    cuts = np.concatenate([[0.0], switch_times(sol), [sol.duration_s]])
    x = np.zeros(5)

    def rhs(t: float, s: np.ndarray) -> np.ndarray:
        f, w = sol.inputs(np.array([t]))
        return np.array([s[2], s[3], f[0] * math.sin(s[4]), f[0] * math.cos(s[4]) - G, w[0]])

    for t0, t1 in zip(cuts[:-1], cuts[1:], strict=True):
        h = (t1 - t0) / steps_per_piece
        # evaluate inputs strictly inside the piece (the arc starting at t0)
        eps = 1e-12 * max(1.0, t1)
        for k in range(steps_per_piece):
            t = t0 + k * h
            ta, tb = max(t, t0 + eps), min(t + h, t1 - eps)
            k1 = rhs(ta, x)
            k2 = rhs(t + h / 2, x + h / 2 * k1)
            k3 = rhs(t + h / 2, x + h / 2 * k2)
            k4 = rhs(tb, x + h * k3)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


def trapezoidal_reference(
    target: tuple[float, float],
    final_angle: float,
    warm: TimeOptimalSolution | None,
    theta_guess: float = 0.0,
    n: int = 400,
) -> float:
    """Independent fine transcription: trapezoidal collocation, inputs at nodes.

    Different discretisation from the module (which uses piecewise-constant
    inputs and RK4 steps).  Returns T (nan if IPOPT fails).
    """
    ca = casadi
    nx_ = 1 + 7 * (n + 1)
    w = ca.SX.sym("w", nx_)
    t_final = w[0]
    xs = ca.reshape(w[1 : 1 + 5 * (n + 1)], 5, n + 1)
    us = ca.reshape(w[1 + 5 * (n + 1) :], 2, n + 1)

    def f(x, u):
        return ca.vertcat(x[2, :], x[3, :], u[0, :] * ca.sin(x[4, :]), u[0, :] * ca.cos(x[4, :]) - G, u[1, :])

    fx = f(xs, us)
    h = t_final / n
    defects = xs[:, 1:] - xs[:, :-1] - h / 2 * (fx[:, 1:] + fx[:, :-1])
    solver = ca.nlpsol(
        "ref",
        "ipopt",
        {"x": w, "f": t_final, "g": ca.vec(defects)},
        {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.max_iter": 3000},
    )
    lbx = np.full(nx_, -np.inf)
    ubx = np.full(nx_, np.inf)
    lbx[0], ubx[0] = 0.05, 20.0
    xl = np.full((5, n + 1), -np.inf)
    xu = np.full((5, n + 1), np.inf)
    xl[:, 0] = xu[:, 0] = 0.0
    xl[:, -1] = xu[:, -1] = [target[0], target[1], 0.0, 0.0, final_angle]
    lbx[1 : 1 + 5 * (n + 1)] = xl.T.ravel()
    ubx[1 : 1 + 5 * (n + 1)] = xu.T.ravel()
    lbx[1 + 5 * (n + 1) :] = np.tile([LIM.f_min_m_s2, -LIM.max_rate_rad_s], n + 1)
    ubx[1 + 5 * (n + 1) :] = np.tile([LIM.f_max_m_s2, LIM.max_rate_rad_s], n + 1)
    s = np.linspace(0.0, 1.0, n + 1)
    if warm is not None:
        t0 = warm.duration_s
        tn = s * t0
        x0 = np.column_stack([np.interp(tn, warm.times_s, warm.states[:, i]) for i in range(5)])
        f0, w0 = warm.inputs(np.minimum(tn, t0 * (1 - 1e-9)))
        u0 = np.column_stack([f0, w0])
    else:
        t0 = 1.5
        x0 = np.zeros((n + 1, 5))
        x0[:, 0] = target[0] * (3 * s**2 - 2 * s**3)
        x0[:, 1] = target[1] * (3 * s**2 - 2 * s**3)
        x0[:, 4] = final_angle * s + theta_guess * np.sin(np.pi * s)
        u0 = np.column_stack([np.full(n + 1, G), np.zeros(n + 1)])
    w_init = np.concatenate([[t0], x0.ravel(), u0.ravel()])
    res = solver(x0=np.clip(w_init, lbx, ubx), lbx=lbx, ubx=ubx, lbg=0.0, ubg=0.0)
    if not solver.stats()["success"]:
        return math.nan
    return float(res["x"][0])


def check_solution_invariants(sol: TimeOptimalSolution) -> None:
    target = np.array([sol.target_m[0], sol.target_m[1], 0.0, 0.0, sol.final_angle_rad])
    assert sol.ok, sol.message
    assert sol.boundary_error <= 1e-6
    assert np.max(np.abs(sol.states[-1] - target)) <= 1e-6
    assert np.allclose(sol.states[0], 0.0, atol=1e-14)
    # refined T must not exceed the transcription's
    assert sol.duration_s <= sol.transcription_duration_s + 1e-9
    # arcs tile [0, T] without gaps, for each input
    for arcs in (sol.thrust_arcs, sol.rate_arcs):
        assert arcs[0].start_s == 0.0
        assert arcs[-1].end_s == pytest.approx(sol.duration_s, abs=1e-12)
        for a, b in zip(arcs[:-1], arcs[1:], strict=True):
            assert a.end_s == b.start_s
            assert a.kind != b.kind or a.kind == "singular"
        assert all(a.end_s > a.start_s for a in arcs)
    # inputs exactly within bounds: thrust bang-bang at the bounds
    for a in sol.thrust_arcs:
        assert a.kind in ("max", "min")
        assert a.value == (LIM.f_max_m_s2 if a.kind == "max" else LIM.f_min_m_s2)
    t = np.linspace(0.0, sol.duration_s, 20001)
    f, w = sol.inputs(t)
    assert np.all((f == LIM.f_min_m_s2) | (f == LIM.f_max_m_s2))
    assert np.max(np.abs(w)) <= LIM.max_rate_rad_s
    for a in sol.rate_arcs:
        if a.kind == "singular":
            assert a.tangent_law is not None
            assert abs(a.value) < LIM.max_rate_rad_s
        else:
            assert a.value == (LIM.max_rate_rad_s if a.kind == "max" else -LIM.max_rate_rad_s)
    # the public input program, replayed by an independent integrator, reaches the target
    x_end = rk4_replay(sol)
    assert np.max(np.abs(x_end - target)) < 1e-6


# --------------------------------------------------------------------------
# the (0,0) -> (5,5) benchmark of Ritz et al. / Hehn et al.
# --------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sol55() -> TimeOptimalSolution:
    return solve_translation(5.0, 5.0)


def test_default_limits_follow_formula():
    span = 21.58 - 3.92
    assert LIM.f_min_m_s2 == 3.92 + 0.05 * span
    assert LIM.f_max_m_s2 == 21.58 - 0.05 * span
    assert LIM.f_min_m_s2 == pytest.approx(4.803)
    assert LIM.f_max_m_s2 == pytest.approx(20.697)
    assert LIM.max_rate_rad_s == 10.0
    assert LIM.gravity_m_s2 == 9.81


def test_55_duration_matches_literature(sol55):
    assert sol55.ok, sol55.message
    assert sol55.status == "optimal"
    # paper: 1.38 s; independent RK4/300-interval transcription: 1.389 s
    assert 1.380 <= sol55.duration_s <= 1.392
    assert sol55.transcription_duration_s == pytest.approx(sol55.duration_s, rel=1e-3)


def test_55_invariants(sol55):
    check_solution_invariants(sol55)


def test_55_arc_structure(sol55):
    # rate: bang-singular with four switches: +max, singular (~0), -max, singular (~0), +max
    assert [a.kind for a in sol55.rate_arcs] == ["max", "singular", "min", "singular", "max"]
    for a in sol55.rate_arcs:
        if a.kind == "singular":
            t = np.linspace(a.start_s, a.end_s, 101)
            assert np.max(np.abs(a.evaluate(t))) < 0.1  # singular rate very close to zero
    # thrust: bang-bang; a short minimum-thrust arc during the -max rotation and
    # a final minimum-thrust arc
    assert [a.kind for a in sol55.thrust_arcs] == ["max", "min", "max", "min"]
    assert sol55.thrust_arcs[1].duration_s < 0.05
    # four rate switches + three thrust switches, all distinct and interior
    ts = switch_times(sol55)
    assert ts.shape == (7,)
    assert np.all(np.diff(ts) > 0)
    assert ts[0] > 0 and ts[-1] < sol55.duration_s


def test_55_attitude_excursion(sol55):
    theta = sol55.states[:, 4]
    assert np.degrees(np.min(theta)) < -120.0
    assert np.all(np.diff(sol55.times_s) > 0)
    assert sol55.times_s[-1] == pytest.approx(sol55.duration_s, abs=1e-12)
    assert sol55.states.shape == (sol55.times_s.size, 5)


def test_55_json(sol55):
    d = sol55.to_json_dict()
    text = json.dumps(d, allow_nan=False)
    back = json.loads(text)
    for key in (
        "duration_s",
        "thrust_arcs",
        "rate_arcs",
        "status",
        "message",
        "target_m",
        "final_angle_rad",
        "transcription_duration_s",
        "boundary_error",
    ):
        assert key in back
    assert back["duration_s"] == sol55.duration_s
    assert back["rate_arcs"][1]["kind"] == "singular"
    assert set(back["thrust_arcs"][0]) >= {"kind", "start_s", "end_s", "value"}
    # the arcs are enough to rebuild the program
    arcs = tuple(
        InputArc(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in a.items()}) for a in back["rate_arcs"]
    )
    assert arcs == sol55.rate_arcs


# --------------------------------------------------------------------------
# other targets against an independent fine transcription
# --------------------------------------------------------------------------
TARGETS = [
    (5.0, 0.0, 0.0),  # horizontal
    (0.0, 5.0, 0.0),  # vertical up (the optimum tilts; theta == 0 is only stationary)
    (3.0, -4.0, 0.0),  # downward
    (5.0, 5.0, 2 * math.pi),  # translation with a flip
    (2.0, 0.0, 2 * math.pi),
]


@pytest.fixture(scope="module")
def solved_targets() -> dict[tuple[float, float, float], TimeOptimalSolution]:
    return {t: solve_translation(t[0], t[1], final_angle_rad=t[2]) for t in TARGETS}


@pytest.mark.parametrize("target", TARGETS)
def test_targets_against_independent_transcription(target, solved_targets):
    sol = solved_targets[target]
    check_solution_invariants(sol)
    refs = [trapezoidal_reference(target[:2], target[2], sol)]
    # plus a cold start independent of the module's solution
    refs.append(trapezoidal_reference(target[:2], target[2], None, theta_guess=0.5 * math.pi))
    refs = [r for r in refs if math.isfinite(r)]
    assert refs, "reference transcription failed"
    ref = min(refs)
    assert abs(sol.duration_s - ref) / ref < 0.005, (sol.duration_s, refs)


def test_vertical_moves_are_time_symmetric(solved_targets):
    up = solved_targets[(0.0, 5.0, 0.0)]
    down = solve_translation(0.0, -5.0)
    check_solution_invariants(down)
    # time reversal maps a hover-to-hover move onto its mirror image
    assert down.duration_s == pytest.approx(up.duration_s, abs=1e-7)
    # a pure vertical bang-bang climb (theta == 0) takes 1.7076 s; tilting is faster
    assert up.duration_s < 1.5


def test_mirror_symmetry():
    a = solve_translation(-3.0, 4.0)
    b = solve_translation(3.0, 4.0)
    assert a.ok and b.ok
    assert a.duration_s == pytest.approx(b.duration_s, abs=1e-7)


def test_structure_repair_gives_symmetric_optimum():
    # (4, 5) needs a short singular rate arc between the -max and +max arcs that
    # the transcription does not resolve; (4, -5) is its time-reversed mirror
    a = solve_translation(4.0, 5.0)
    b = solve_translation(4.0, -5.0)
    check_solution_invariants(a)
    check_solution_invariants(b)
    assert a.duration_s == pytest.approx(b.duration_s, abs=1e-9)
    # time reversal maps the rate program onto its mirror image, read backwards
    assert [k.kind for k in a.rate_arcs] == [k.kind for k in reversed(b.rate_arcs)]
    assert sum(k.kind == "singular" for k in a.rate_arcs) == 2
    assert "PMP residual" in a.message


def test_tiny_vertical_hop_is_closed_form_bang_bang():
    z = 0.05
    sol = solve_translation(0.0, z)
    check_solution_invariants(sol)
    a1 = LIM.f_max_m_s2 - G
    a2 = G - LIM.f_min_m_s2
    t1 = math.sqrt(2 * z * a2 / (a1 * (a1 + a2)))
    assert sol.duration_s == pytest.approx(t1 * (1 + a1 / a2), abs=1e-12)
    assert np.max(np.abs(sol.states[:, 4])) == 0.0
    assert [a.kind for a in sol.thrust_arcs] == ["max", "min"]


def test_flip_takes_longer_than_plain(sol55, solved_targets):
    flip = solved_targets[(5.0, 5.0, 2 * math.pi)]
    assert flip.duration_s > sol55.duration_s
    assert np.max(flip.states[:, 4]) == pytest.approx(2 * math.pi, abs=1e-6)


def test_tighter_limits_are_slower():
    slow = solve_translation(5.0, 0.0, limits=BenchmarkLimits(max_rate_rad_s=5.0))
    fast = solve_translation(5.0, 0.0)
    assert slow.ok and fast.ok
    assert slow.duration_s > fast.duration_s
    t = np.linspace(0, slow.duration_s, 5001)
    assert np.max(np.abs(slow.inputs(t)[1])) <= 5.0


def test_zero_move_is_trivial():
    sol = solve_translation(0.0, 0.0)
    assert sol.ok and sol.duration_s == 0.0
    assert switch_times(sol).size == 0


# --------------------------------------------------------------------------
# failures and invalid input
# --------------------------------------------------------------------------
def test_solver_failure_is_reported_not_raised():
    sol = solve_translation(5.0, 5.0, ipopt_max_iter=2)
    assert sol.status == "failed"
    assert not sol.ok
    assert "did not converge" in sol.message
    assert math.isnan(sol.duration_s)
    assert sol.thrust_arcs == () and sol.rate_arcs == ()
    assert switch_times(sol).size == 0
    d = sol.to_json_dict()
    assert d["duration_s"] is None and d["status"] == "failed"
    json.dumps(d, allow_nan=False)
    with pytest.raises(ValueError, match="status"):
        plot_solution(sol)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"f_min_m_s2": -1.0}, "f_min_m_s2"),
        ({"f_min_m_s2": 0.0}, "f_min_m_s2"),
        ({"f_min_m_s2": 25.0}, "f_min_m_s2"),
        ({"f_max_m_s2": 9.0}, "f_max_m_s2"),
        ({"f_max_m_s2": float("inf")}, "f_max_m_s2"),
        ({"max_rate_rad_s": 0.0}, "max_rate_rad_s"),
        ({"max_rate_rad_s": float("nan")}, "max_rate_rad_s"),
        ({"gravity_m_s2": -9.81}, "gravity_m_s2"),
    ],
)
def test_invalid_limits(kwargs, name):
    with pytest.raises(ValueError, match=name) as info:
        BenchmarkLimits(**kwargs)
    assert "allowed" in str(info.value) or "must be finite" in str(info.value)


@pytest.mark.parametrize(
    "args, kwargs, name",
    [
        ((float("nan"), 1.0), {}, "target_y_m"),
        ((1.0, float("inf")), {}, "target_z_m"),
        ((1.0, 1.0), {"final_angle_rad": float("nan")}, "final_angle_rad"),
        ((1.0, 1.0), {"intervals": 3}, "intervals"),
        ((1.0, 1.0), {"ipopt_max_iter": 0}, "ipopt_max_iter"),
        ((1.0, 1.0), {"limits": "fast"}, "limits"),
        (("a", 1.0), {}, "target_y_m"),
    ],
)
def test_invalid_solve_arguments(args, kwargs, name):
    with pytest.raises(ValueError, match=name):
        solve_translation(*args, **kwargs)


def test_invalid_arc_kind():
    with pytest.raises(ValueError, match="kind"):
        InputArc(kind="bang", start_s=0.0, end_s=1.0, value=1.0)


def test_frozen_dataclasses(sol55):
    with pytest.raises(AttributeError):
        sol55.duration_s = 1.0  # type: ignore[misc]
    with pytest.raises(AttributeError):
        LIM.f_max_m_s2 = 30.0  # type: ignore[misc]


# --------------------------------------------------------------------------
# map, CSV and plots
# --------------------------------------------------------------------------
def test_benchmark_map_parallel_csv_and_plots(tmp_path, sol55):
    import dataclasses

    ys = np.array([0.0, 5.0])
    zs = np.array([0.0, 5.0])
    calls = []
    jobs = map_jobs(ys, zs, dataclasses.asdict(BenchmarkLimits()))
    pool = LocalExecutor(2)
    with Store(tmp_path / "m.sqlite") as store:
        outcome = run_study(store, "map", {"ys": ys.tolist(), "zs": zs.tolist()}, jobs, executor=pool,
                            progress=lambda done, total, job, result: calls.append((done, total)))
    pool.close()
    assert outcome.ok and outcome.ran == 4
    grid = map_grid(outcome.results, ys, zs)
    assert grid.shape == (2, 2)
    assert grid[0, 0] == 0.0
    assert grid[1, 1] == pytest.approx(sol55.duration_s, abs=1e-9)
    assert grid[0, 1] == pytest.approx(grid[1, 0], rel=0.5)  # both finite, same order
    assert np.all(np.isfinite(grid))
    assert [c[0] for c in calls] == [1, 2, 3, 4] and all(c[1] == 4 for c in calls)

    rows = list(csv.DictReader(map_csv(ys, zs, grid).splitlines()))
    assert list(rows[0]) == ["y_m", "z_m", "duration_s"]
    assert len(rows) == 4
    row = next(r for r in rows if float(r["y_m"]) == 5.0 and float(r["z_m"]) == 5.0)
    assert float(row["duration_s"]) == grid[1, 1]

    map_png = save_figure(plot_map(ys, zs, grid), tmp_path / "map.png")
    assert map_png.stat().st_size > 1000
    one_row = save_figure(plot_map(ys, zs[:1], grid[:1]), tmp_path / "row.png")  # no contour for one row
    assert one_row.stat().st_size > 1000
    sol_png = save_figure(plot_solution(sol55), tmp_path / "sol.png")
    assert sol_png.stat().st_size > 1000
