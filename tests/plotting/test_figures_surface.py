"""Figures a reader can read (issue 25, item 3): the side view's plane follows the motion, titles say the loop,
counts have integer ticks."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from aerobat.plotting.vehicle import plot_side_views, side_view_planes  # noqa: E402
from aerobat.quadrotor.dynamics import N_STATE, POS, QUAT, RATE_INT  # noqa: E402


def _flight(*, x_m: float = 0.0, y_m: float = 0.0, roll_rad: float = 0.0, pitch_rad: float = 0.0,
            n: int = 60) -> tuple[np.ndarray, np.ndarray]:
    t = np.linspace(0.0, 1.0, n)
    s = np.zeros((n, N_STATE))
    s[:, QUAT] = (1.0, 0.0, 0.0, 0.0)
    s[:, POS] = np.stack([x_m * t, y_m * t, 0.3 * np.sin(np.pi * t)], axis=1)
    s[:, RATE_INT] = np.stack([roll_rad * t, pitch_rad * t, 0 * t], axis=1)
    return t, s


def _drawn_extent(ax) -> float:
    """Horizontal extent of the path line drawn in a panel [m]."""
    xs = np.concatenate([line.get_xdata() for line in ax.get_lines() if len(line.get_xdata()) > 2])
    return float(np.ptp(xs))


def test_a_step_along_x_is_drawn_in_the_x_z_plane_not_piled_at_the_origin():
    t, s = _flight(x_m=2.0)
    assert side_view_planes([s]) == ("xz",)
    fig = plot_side_views([("step", t, s)], target=(2.0, 0.0, 0.0))
    (ax,) = fig.axes
    assert ax.get_xlabel() == "X [m]"
    assert _drawn_extent(ax) == pytest.approx(2.0)  # the y-z view drew 0.0 m: a pile of markers
    target = [line for line in ax.get_lines() if line.get_label() == "desired final position"]
    assert target and target[0].get_xdata()[0] == pytest.approx(2.0)


def test_flips_are_seen_along_their_axis_and_a_diagonal_motion_in_both_planes():
    assert side_view_planes([_flight(roll_rad=2 * np.pi)[1]]) == ("yz",)
    assert side_view_planes([_flight(pitch_rad=2 * np.pi, x_m=0.3)[1]]) == ("xz",)
    assert side_view_planes([_flight(y_m=3.0)[1]]) == ("yz",)
    t, s = _flight(x_m=2.0, y_m=1.5)
    assert side_view_planes([s]) == ("yz", "xz")
    fig = plot_side_views([("a", t, s), ("b", t, s)])
    assert len(fig.axes) == 4
    assert {ax.get_xlabel() for ax in fig.axes} == {"X [m]", "Y [m]"}


def test_no_target_is_drawn_when_the_maneuver_names_none():
    t, s = _flight(x_m=1.0)
    fig = plot_side_views([("trial 1", t, s)], target=None)
    assert not [line for line in fig.axes[0].get_lines() if line.get_label() == "desired final position"]
    assert "names no final position" in fig._suptitle.get_text()  # noqa: SLF001


def test_the_robustness_histogram_has_integer_ticks_on_counts():
    from aerobat.plotting.studies import plot_trials_to_tolerance

    fig = plot_trials_to_tolerance([1, 2, 2, 3, None], 0.12)
    ax = fig.axes[0]
    fig.canvas.draw()
    for ticks in (ax.get_xticks(), ax.get_yticks()):
        assert np.allclose(ticks, np.round(ticks)), ticks


def test_rules_and_feedback_figures_label_every_line():
    from aerobat.plotting.studies import plot_feedback, plot_rules

    curves = {"paper": [[0.3, 0.1, 0.05]], "bayesopt": [[float("nan"), 0.2, float("nan")]], "cma": [[float("nan")] * 3]}
    fig = plot_rules(curves, 3, 0.12)
    labels = fig.axes[0].get_legend_handles_labels()[1]
    assert "bayesopt" in labels and "cma: no trial measured" in labels and "tolerance 0.12 m" in labels
    bayes = next(line for line in fig.axes[0].get_lines() if line.get_label() == "bayesopt")
    assert bayes.get_marker() == "."  # its one finite median is a visible point, not a line of length zero
    fig = plot_feedback({"default": curves, "lossy-link": curves}, 3, 0.12)
    assert fig._suptitle is not None and "feedback" in fig._suptitle.get_text()  # noqa: SLF001
    ylabels = [ax.get_ylabel() for ax in fig.axes if ax.get_visible()]
    assert sum(bool(label) for label in ylabels) == 1, ylabels
    fig.canvas.draw()
    minor = [t.get_text() for t in fig.axes[0].get_yticklabels(minor=True) if t.get_text()]
    assert not minor, minor


def test_learning_figure_has_iteration_ticks_on_both_columns():
    from aerobat.plotting.learning import plot_learning

    iterations = [{"i": i, "status": "ok", "params": [1.0, 2.0, 3.0, 4.0], "error": [0.1 / i, 0.2 / i]}
                  for i in range(1, 6)]
    fig = plot_learning(iterations, ["y", "z"], ["m", "m"], ["p0", "p1", "p2", "p3"], ["s", "s", "s", "s"])
    fig.canvas.draw()
    error_axes = [ax for ax in fig.axes if ax.axison and ax.get_subplotspec().colspan.start == 0]
    assert error_axes[-1].get_xlabel() == "iteration"
    assert any(t.get_text() for t in error_axes[-1].get_xticklabels())


def test_benchmark_figure_labels_z_outside_and_rates_in_degrees():
    from aerobat.plotting.benchmarks import plot_solution
    from aerobat.quadrotor.timeoptimal import solve_translation

    solution = solve_translation(1.0, 1.0)
    fig = plot_solution(solution)
    path = fig.axes[2]
    assert path.yaxis.get_label_position() == "right"
    assert fig.axes[1].get_ylabel() == "rate ω [°/s]"
    fig.canvas.draw()
    inputs = fig.axes[0].get_window_extent()
    assert path.get_window_extent().x0 > inputs.x1  # the path panel no longer grows over the input panels
    lo, hi = path.get_ylim()
    assert lo < float(solution.states[:, 1].min()) and hi > float(solution.states[:, 1].max())


def test_a_stored_sessions_side_views_say_the_loop_and_follow_the_motion(tmp_path, monkeypatch):
    import contextlib
    import io

    from aerobat.cli import main
    from aerobat.experiments import reports
    from aerobat.store import Store

    monkeypatch.chdir(tmp_path)
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(["learn", "flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "800", "--axis", "pitch",
                     "--plant", "nominal", "--trials", "1", "--db", "a.sqlite"]) == 0
    seen = {}

    def capture(panels, **kwargs):
        seen.update(kwargs, planes=side_view_planes([s for _, _, s in panels]))
        return plot_side_views(panels, **kwargs)

    monkeypatch.setattr(reports, "plot_side_views", capture)
    with Store(tmp_path / "a.sqlite") as store:
        reports.session_figures(store, 1, tmp_path)
    assert seen["title"].endswith("on nominal, open loop"), seen["title"]
    assert seen["planes"] == ("xz",) and "plane" not in seen  # a pitch flip, seen along its axis
    assert seen["target"] == (0.0, 0.0, 0.0)


def test_the_learning_figure_has_no_tick_between_two_iterations():
    """Iterations are whole numbers: three of them get ticks at 1, 2, 3, not at 1.5 and 2.5 (issue 44)."""
    from aerobat.plotting.learning import plot_learning

    its = [{"i": i, "status": "ok", "error": [0.1 / i, 0.2 / i], "params": [1.0 + i, 2.0]} for i in (1, 2, 3)]
    fig = plot_learning(its, ["x", "z"], ["m", "m"], ["p0", "p1"], ["s", "s"])
    for ax in fig.axes:
        if ax.get_visible() and ax.get_xlabel() == "iteration":
            ticks = [t for t in ax.get_xticks() if ax.get_xlim()[0] <= t <= ax.get_xlim()[1]]
            assert ticks and all(float(t).is_integer() for t in ticks), ticks


def test_the_robustness_panels_show_what_varies_when_every_vehicle_succeeds():
    """Issue 44: 11 flat 100 % panels said nothing; the median trials to the tolerance per quintile does."""
    import numpy as np

    from aerobat.plotting.studies import plot_success_by_property

    rng = np.random.default_rng(0)
    mass = rng.uniform(0.4, 0.6, 50)
    props = [{"mass_kg": float(m), "arm_m": 0.17} for m in mass]
    trials = [int(2 + 10 * (m - 0.4)) for m in mass]  # heavier vehicles take longer
    fig = plot_success_by_property(props, [True] * 50, ["mass_kg", "arm_m"], trials)
    assert "every vehicle met the tolerance" in fig._suptitle.get_text()
    twins = [ax for ax in fig.axes if ax.get_ylabel() == "median trials to tolerance"]
    assert len(twins) == 1  # the constant property has no panel data
    medians = twins[0].lines[0].get_ydata()
    assert np.all(np.diff(medians) >= 0) and medians[-1] > medians[0]


def test_a_tall_side_view_has_no_tick_labels_running_together():
    """Issue 44: a flip that goes up 3 m and sideways 0.2 m drew "-0.50.0 0.5" under a narrow panel."""
    import numpy as np

    from aerobat.plotting.vehicle import plot_side_views

    t = np.linspace(0.0, 1.5, 300)
    states = np.zeros((t.size, 13))
    states[:, 6] = 1.0  # level attitude (w of the quaternion)
    states[:, 1] = 0.1 * np.sin(4 * t)  # y: a little sideways
    states[:, 2] = 3.0 * np.sin(np.pi * t / 1.5)  # z: up 3 m and back
    fig = plot_side_views([("trial 1", t, states), ("trial 30", t, states)], plane="yz", target=(0.0, 0.0))
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    for ax in fig.axes:
        low, high = ax.get_xlim()
        labels = [lab for lab, at in zip(ax.get_xticklabels(), ax.get_xticks(), strict=True)
                  if lab.get_visible() and lab.get_text() and low <= at <= high]  # the ones drawn
        boxes = sorted((lab.get_window_extent(renderer) for lab in labels), key=lambda b: b.x0)
        assert len(boxes) >= 2
        assert all(a.x1 + 2 <= b.x0 for a, b in zip(boxes, boxes[1:], strict=False)), [lab.get_text() for lab in labels]
