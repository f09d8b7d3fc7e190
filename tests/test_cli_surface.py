"""What a reader of the command line meets: parsing, messages and exit statuses (issues 25 and 31)."""

from __future__ import annotations

import argparse
import contextlib
import io
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
