"""What a reader of the command line meets: parsing, messages and exit statuses (issues 25 and 31)."""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import subprocess
import sys

import pytest

from aerobat.cli import main
from aerobat.cli.app import build_parser


def call(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 2
    return code, out.getvalue(), err.getvalue()


def _leaves() -> list[tuple[list[str], argparse.ArgumentParser]]:
    out = []

    def walk(path: list[str], parser: argparse.ArgumentParser) -> None:
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]  # noqa: SLF001
        if not subs:
            out.append((path, parser))
        for action in subs:
            for name, sub in action.choices.items():
                walk([*path, name], sub)

    walk([], build_parser())
    return out


VALUED = sorted({(tuple(path), option) for path, parser in _leaves() for action in parser._actions  # noqa: SLF001
                 if action.nargs != 0 for option in action.option_strings})


def test_there_are_many_valued_options():
    assert len(VALUED) > 100


@pytest.mark.parametrize("value", ["--", ""])
def test_no_option_takes_dashdash_or_an_empty_value(value, tmp_path, monkeypatch):
    """issue 31 S4, I5: `--output=--`, `--output ''`, `--max-rate-deg-s=--`… exit 2 with one line naming the option."""
    monkeypatch.chdir(tmp_path)
    failures = []
    for path, option in VALUED:
        for argv in ([*path, f"{option}={value}"], [*path, option, value]):
            if value == "--" and argv[-1] == "--":
                continue  # `--opt --` is argparse's own "expected one argument"
            code, out, err = call(argv)
            lines = err.strip().splitlines()
            if code != 2 or len(lines) != 1 or option not in lines[0] or "Traceback" in err:
                failures.append((argv, code, err[-200:]))
    assert not failures, failures[:5]
    assert not list(tmp_path.iterdir())  # nothing was written, no store created


def test_options_are_not_matched_by_a_prefix_and_a_typo_gets_a_suggestion():
    code, _, err = call(["design", "flip", "--flip", "3", "--json"])
    assert code == 2
    assert err.strip() == "aerobat: error: unrecognized arguments: --flip 3 (did you mean --flips?)"
    code, _, err = call(["learn", "flip", "--trails", "3"])
    assert code == 2 and "did you mean --trials?" in err
    for _, parser in _leaves():
        assert parser.allow_abbrev is False


def test_debug_keeps_bad_input_at_exit_2(tmp_path):
    """issue 31 E1: `aerobat --debug simulate /nonexist.toml` exits 2 (it exited 1), with the traceback."""
    missing = tmp_path / "nonexist.toml"
    run = subprocess.run([sys.executable, "-m", "aerobat.cli", "--debug", "simulate", str(missing)],
                         capture_output=True, text=True, timeout=300, check=False)
    assert run.returncode == 2, run.stderr
    assert "Traceback" in run.stderr
    assert run.stderr.strip().splitlines()[-1] == f"aerobat: error: {missing}: file not found"


# ------------------------------------------------------------------ wording (issue 25, item 7)


def _nested_parentheses(text: str) -> list[str]:
    out, depth = [], 0
    for line in text.splitlines():
        depth = 0
        for c in line:
            depth += (c == "(") - (c == ")")
            if depth > 1:
                out.append(line)
                break
    return out


def test_design_and_benchmark_say_their_status_once_in_plain_words():
    code, out, err = call(["design", "flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "800"])
    assert code == 0, err
    first = out.splitlines()[0]
    assert "converged — converged" not in first and "converged — residual norm" in first, first
    assert "1 iterations" not in out and not _nested_parentheses(first), first
    code, out, err = call(["benchmark", "translation", "--to-m", "1,1"])
    assert code == 0, err
    assert "optimal — optimal" not in out and "status: optimal — T*=" in out, out
    assert not _nested_parentheses(out), _nested_parentheses(out)
    assert "[rad/s]" not in out and "value [deg/s]" in out  # the option is --body-rate-deg-s
    assert "+572.9578" in out  # a rate arc at the 10 rad/s limit, in degrees


def test_vehicles_speak_degrees_like_their_grid():
    from aerobat.cli.vehicles import _in_degrees

    code, out, _ = call(["vehicles"])
    assert code == 0 and "[rad/s²]" not in out and "[°/s²]" in out
    assert "8750 / 8750" in out  # the Hummingbird's 152.7 rad/s² in °/s²
    assert _in_degrees("largest error flip_angle = -18.8 rad") == "largest error flip_angle = -1077°"
    assert _in_degrees("a rate of 2 rad/s, 3 rad/s² left") == "a rate of 115°/s, 3 rad/s² left"


def test_learn_prints_each_trial_once_with_its_progress(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = call(["learn", "flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "800",
                           "--plant", "nominal", "--trials", "1", "--db", "a.sqlite"])
    assert code == 0, err
    rows = [line for line in out.splitlines() if re.match(r"\s*(│\s*)?1\s+(│\s*)?ok", line)]
    assert len(rows) == 1, out  # the trial, not the trial and then a table of the same rows
    assert "[1/1, " in rows[0] and rows[0].rstrip().endswith("done]"), rows[0]
    assert "1 measured iteration\n" in out and "1 measured iterations" not in out and "of 1 measured iterations" \
        not in out, out
    assert "aerobat show 1 --db a.sqlite" in out
    code, out, err = call(["learn", "--resume", "1", "--trials", "3", "--db", "a.sqlite"])
    assert code == 0, err
    progress = [line[line.index("["):] for line in out.splitlines() if "position error" in line and "[" in line]
    assert progress[0].startswith("[2/3, ") and "left]" in progress[0], progress
    assert progress[1].startswith("[3/3, ") and progress[1].endswith("done]"), progress


def test_a_closed_pipe_ends_quietly(tmp_path):
    """`aerobat vehicles | head -0`: no broken-pipe error and no 'Exception ignored'; the status is 141 (SIGPIPE)."""
    for argv in (["vehicles"], ["design", "flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "800", "--json"]):
        proc = subprocess.Popen([sys.executable, "-m", "aerobat.cli", *argv], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, cwd=tmp_path)
        assert proc.stdout is not None and proc.stderr is not None
        proc.stdout.close()  # the reader left before the first line
        err = proc.stderr.read().decode()
        assert proc.wait(timeout=300) == 141, err
        assert err == "", err


# ------------------------------------------------------------------ estimates (issue 25, item 8)


def test_a_study_estimate_comes_from_its_measured_jobs_not_from_the_pool_start():
    """The first job of 100 ends 60 s in, 55 s of which were the pool starting; each job takes 5 s on 2 workers.

    The time since the start says 60 × 99 = 5940 s left; the jobs' own times say 5 s × 50 rounds = 250 s,
    which is what the rest takes."""
    from aerobat.cli.study import study_eta

    assert study_eta(60.0, 1, 99, [5.0], workers=2) == pytest.approx(250.0)
    assert study_eta(70.0, 5, 95, [5.0, 4.0, 6.0, 5.0, 5.0], workers=2) == pytest.approx(5.0 * 48)
    assert study_eta(70.0, 5, 0, [5.0], workers=2) == 0.0
    # no job times (design jobs) or an unknown pool (Dask): the rate since the start
    assert study_eta(60.0, 3, 6, [], workers=2) == pytest.approx(120.0)
    assert study_eta(60.0, 3, 6, [5.0], workers=None) == pytest.approx(120.0)


def test_design_refuses_a_plant_settings_file_without_its_plant():
    """The fuzz campaign (issue 41's plant options on design): --arena /dev/zero without --plant ran and exited 0."""
    code, out, err = call(["design", "flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "800",
                           "--arena", "/dev/zero"])
    assert code == 2 and err.strip() == "aerobat: error: --arena applies only with --plant arena (no --plant given)"
