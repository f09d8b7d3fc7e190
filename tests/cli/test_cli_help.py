"""Every subcommand's --help lists, for each option, its default or that it is required (issue 16)."""

from __future__ import annotations

import argparse
import contextlib
import io
import re

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


# ------------------------------------------------------------------ what a reader sees (issue 25, item 4)

_ONE_DEFAULT = re.compile(r"\((?:default: |required)[^()]*(?:\([^()]*\)[^()]*)*\)$")


def _shown(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    return parser._get_formatter()._get_help_string(action) % {"default": action.default}  # noqa: SLF001


@pytest.mark.parametrize("name, parser", PARSERS, ids=[name or "aerobat" for name, _ in PARSERS])
def test_help_as_printed_names_each_default_once_and_one_way(name, parser, monkeypatch):
    for columns in ("60", "80", "132"):
        monkeypatch.setenv("COLUMNS", columns)
        text = parser.format_help()
        for bad in ("(default: None)", "(default: False)", "(default: True)", "(default: [])", "(default: ==SUPPRESS"):
            assert bad not in text, f"aerobat {name} --help shows {bad}"
        flat = " ".join(text.split())
        for action in _visible(parser) + [a for a in parser._actions if not a.option_strings  # noqa: SLF001
                                          and not isinstance(a, argparse._SubParsersAction)]:  # noqa: SLF001
            shown = " ".join(_shown(parser, action).split())
            label = action.option_strings[0] if action.option_strings else action.dest
            # wrapped only between words: never inside a path such as out/session-ID or a word with a hyphen
            assert shown in flat, f"aerobat {name}: {label}'s help is broken inside a word at {columns} columns"
    for action in _visible(parser):
        if isinstance(action, argparse._HelpAction | argparse._VersionAction):  # noqa: SLF001
            continue
        shown = _shown(parser, action)
        label = action.option_strings[0]
        assert len(re.findall(r"\bdefault\b(?![,-])", shown)) + len(re.findall(r"\brequired\b", shown)) == 1, \
            f"aerobat {name}: {label} names its default more than once or not at all: {shown!r}"
        assert _ONE_DEFAULT.search(shown), f"aerobat {name}: {label}: the default is not '(default: X)' last: {shown!r}"


@pytest.mark.parametrize("name, parser", LEAVES, ids=[name for name, _ in LEAVES])
def test_metavars_say_what_the_value_is(name, parser):
    """`--trials N`, `--out DIR`, a count is N, a quantity its unit — never argparse's upper-cased dest."""
    for action in _visible(parser):
        if action.nargs == 0 or action.choices is not None:
            continue
        option = action.option_strings[0]
        shown = action.metavar or action.dest.upper()
        assert "_" not in shown, f"aerobat {name}: {option} {shown}: argparse's upper-cased name, not what it takes"
        if option in ("--trials", "--seeds", "--seed", "--workers", "--vehicles", "--limit"):
            assert shown == "N", f"aerobat {name}: {option} {shown}, expected N"
        if option == "--out":
            assert shown == "DIR", f"aerobat {name}: --out {shown}, expected DIR"


def test_one_meaning_per_option_across_commands():
    """--max-rate-deg-s is the flip's coast rate everywhere; --to-m has the same default in design and benchmark."""
    helps: dict[str, set[str]] = {}
    defaults: dict[str, set[str]] = {}
    for _, parser in LEAVES:
        for action in _visible(parser):
            for option in action.option_strings:
                helps.setdefault(option, set()).add((action.help or "").split("[")[0].split("(")[0].strip())
                defaults.setdefault(option, set()).add(re.sub(r".*\((default: |required)", r"\1",
                                                               _shown(parser, action)))
    assert len(helps["--max-rate-deg-s"]) == 1, helps["--max-rate-deg-s"]
    assert len(defaults["--to-m"]) == 1, defaults["--to-m"]


def test_study_help_lists_every_study_and_identify_flies_open_loop():
    text = build_parser().format_help()
    line = next(x for x in text.splitlines() if x.strip().startswith("study "))
    for study in ("robustness", "rules", "feedback", "envelope"):
        assert study in line or study[:4] in line, line
    identify = dict(PARSERS)["identify"]
    assert "--feedback" not in identify.format_help()


def test_study_seeds_start_at_zero_in_every_study():
    for name in ("study robustness", "study rules", "study feedback"):
        args = build_parser().parse_args([*name.split(), "flip"])
        assert args.seed == 0, name
