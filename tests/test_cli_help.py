"""Every subcommand's --help lists, for each option, its default or that it is required (issue 16)."""

from __future__ import annotations

import argparse
import contextlib
import io

import pytest

from aerobat.cli import main
from aerobat.cli.app import build_parser


def _parsers() -> list[tuple[str, argparse.ArgumentParser]]:
    out = []

    def walk(prefix: str, parser: argparse.ArgumentParser) -> None:
        out.append((prefix, parser))
        for action in parser._actions:  # noqa: SLF001 - the only way to list subparsers
            if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001
                for name, sub in action.choices.items():
                    walk(f"{prefix} {name}".strip(), sub)

    walk("", build_parser())
    return out


PARSERS = _parsers()


@pytest.mark.parametrize("name, parser", PARSERS, ids=[name or "aerobat" for name, _ in PARSERS])
def test_every_option_has_help_with_its_default_or_required(name, parser):
    text = parser.format_help()
    for action in parser._actions:  # noqa: SLF001
        if action.help == argparse.SUPPRESS or isinstance(action, argparse._HelpAction | argparse._VersionAction |
                                                          argparse._SubParsersAction):  # noqa: SLF001
            continue
        label = action.option_strings[0] if action.option_strings else action.dest
        assert action.help, f"aerobat {name}: {label} has no help text"
        shown = parser._get_formatter()._get_help_string(action)  # noqa: SLF001
        assert "default" in shown or "required" in shown, f"aerobat {name}: {label}: {shown!r} names no default"
    assert text


def test_bare_aerobat_lists_the_commands_and_version_works():
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main([]) == 0
    for command in ("simulate", "design", "learn", "sessions", "show", "studies", "study", "benchmark", "fly"):
        assert command in out.getvalue()
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["--version"]) == 0
    assert out.getvalue().startswith("aerobat ")


def test_debug_is_accepted_anywhere_and_negative_values_are_values():
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        assert main(["design", "translation", "--to", "-2,4", "--debug", "--json"]) == 0


LEAVES = [(name, parser) for name, parser in PARSERS
          if name and not any(isinstance(a, argparse._SubParsersAction) for a in parser._actions)]  # noqa: SLF001
UNIT_SUFFIXES = ("-m", "-s", "-deg", "-deg-s", "-m-s2", "-mm")


def _visible(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    return [a for a in parser._actions if a.option_strings and a.help != argparse.SUPPRESS]  # noqa: SLF001


@pytest.mark.parametrize("name, parser", LEAVES, ids=[name for name, _ in LEAVES])
def test_the_vocabulary_of_docs_cli_md_holds(name, parser):
    """--json everywhere; --out only ever a folder; a unit in the help means a unit in the name;
    a count of flights is --trials (docs/cli.md)."""
    options = {s: a for a in _visible(parser) for s in a.option_strings}
    assert "--json" in options, f"aerobat {name}: no --json"
    if "--out" in options:
        out = options["--out"]
        assert out.metavar == "DIR" or "folder" in (out.help or ""), f"aerobat {name}: --out is not a folder"
    for option, action in options.items():
        units = [u for u in ("[m]", "[s]", "[deg]", "[deg/s]", "[m/s²]", "[mm]") if u in (action.help or "")]
        if units and action.nargs != 0:
            assert option.endswith(UNIT_SUFFIXES), f"aerobat {name}: {option} takes {units[0]}, its name no unit"
        assert option not in ("--iterations", "--plot") or name == "replay", f"aerobat {name}: {option} is an old word"


def test_earlier_spellings_still_work(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        assert main(["learn", "flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "800", "--plant", "nominal",
                     "--iterations", "2", "--db", "a.sqlite"]) == 0
        assert main(["learn", "--resume", "1", "--trials", "3", "--db", "a.sqlite"]) == 0
    from aerobat.store import Store

    with Store(tmp_path / "a.sqlite") as store:
        assert store.session(1).n_measured == 3
    assert next((tmp_path / "out").glob("a-*/session-1")).joinpath("session.json").exists()
