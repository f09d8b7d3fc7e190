"""Malformed TOML files and command-line arguments against every command (issue 6).

The property: whatever comes in, ``aerobat`` never prints a traceback; it exits 0, or with
one ``aerobat: error: …`` line and status 2 for bad input, or one ``aerobat: failed: …`` line
and status 1 for a run that failed. Inputs that are bad by construction must give status 2.

Most examples run ``aerobat.cli.main`` in-process (fast); a few run the installed command.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import sqlite3
import string
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

import pytest
import tomli_w
from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st

from aerobat import hummingbird, save_vehicle
from aerobat.cli import main
from aerobat.plants.arena.params import ArenaParams, save_arena

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
SMALL = ["flip", "--dims", "2", "--flips", "1", "--max-rate-deg-s", "800"]
FUZZ = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow],
                derandomize=True)


def call(argv: list[str]) -> tuple[int, str, str]:
    """``main(argv)`` in-process: (exit status, stdout, stderr); argparse's exits count too."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 2
    return code, out.getvalue(), err.getvalue()


def check(code: int, err: str, *, bad: bool, argv: list[str]) -> None:
    where = f"aerobat {' '.join(map(repr, argv))}\n{err}"
    event(f"{argv[0] if argv and argv[0] in COMMANDS else 'no command'}: exit {code}")
    assert "Traceback" not in err, where
    if bad:
        assert code == 2, where
    assert code in (0, 1, 2), where
    if code == 0:
        return
    lines = err.splitlines()
    assert len(lines) == 1, where
    assert lines[0].startswith("aerobat: error: " if code == 2 else "aerobat: failed: "), where


@pytest.fixture(scope="module")
def env(tmp_path_factory) -> dict[str, Any]:
    """Valid and invalid files to point commands at, and a store with one session."""
    root = tmp_path_factory.mktemp("fuzz")
    db = root / "good.sqlite"
    code, _, err = call(["learn", *SMALL, "--plant", "nominal", "--iterations", "1", "--db", str(db),
                         "--out", str(root / "out")])
    assert code == 0, err
    vehicle = root / "vehicle.toml"
    save_vehicle(hummingbird(), vehicle)
    arena = root / "arena.toml"
    save_arena(ArenaParams(), arena)
    random_bytes = root / "random.sqlite"
    random_bytes.write_bytes(bytes((k * 131 + 7) % 256 for k in range(5000)))
    foreign = root / "foreign.sqlite"
    conn = sqlite3.connect(foreign)
    conn.execute("CREATE TABLE t (x)")
    conn.commit()
    conn.close()
    newer = root / "newer.sqlite"
    newer.write_bytes(db.read_bytes())
    conn = sqlite3.connect(newer)
    conn.execute("PRAGMA user_version = 99")
    conn.commit()
    conn.close()
    plain_file = root / "plain.txt"
    plain_file.write_text("x")
    return {"root": root, "db": db, "vehicle": vehicle, "arena": arena, "program": EXAMPLES / "single_flip.toml",
            "bad_dbs": [random_bytes, foreign, newer, root, root / "missing.sqlite", Path("/proc/nope.sqlite"),
                        Path("/dev/null")],
            "plain_file": plain_file, "counter": [0]}


def scratch(env: dict[str, Any], suffix: str) -> Path:
    env["counter"][0] += 1
    return env["root"] / f"case{env['counter'][0]}{suffix}"


# --------------------------------------------------------------------- TOML files


def leaves(table: Any, path: tuple = ()) -> list[tuple]:
    """Paths of every scalar in a parsed TOML document."""
    if isinstance(table, dict):
        return [p for k, v in table.items() for p in leaves(v, (*path, k))]
    if isinstance(table, list) and table and all(isinstance(v, dict) for v in table):
        return [p for i, v in enumerate(table) for p in leaves(v, (*path, i))]
    return [path]


def tables(table: Any, path: tuple = ()) -> list[tuple]:
    if isinstance(table, dict):
        return [path] + [p for k, v in table.items() for p in tables(v, (*path, k))]
    if isinstance(table, list):
        return [p for i, v in enumerate(table) for p in tables(v, (*path, i))]
    return []


def get(doc: Any, path: tuple) -> Any:
    for key in path:
        doc = doc[key]
    return doc


NOT_A_NUMBER = st.one_of(st.text(max_size=8), st.booleans(), st.just([1, 2]), st.just({"a": 1}))


@st.composite
def mutated_toml(draw, base_text: str) -> tuple[str, bool]:
    """(file text, bad by construction) from a valid file."""
    doc = tomllib.loads(base_text)
    kind = draw(st.sampled_from(["type", "nonfinite", "unknown", "syntax", "delete", "absurd", "bytes", "text"]))
    if kind == "bytes":
        return draw(st.binary(max_size=300)).decode("latin-1"), False
    if kind == "text":
        return draw(st.text(max_size=200)), False
    if kind == "syntax":
        cut = draw(st.integers(0, len(base_text)))
        return base_text[:cut] + "\n= = [\n" + base_text[cut:], True
    if kind == "unknown":
        where = draw(st.sampled_from([p for p in tables(doc) if isinstance(get(doc, p), dict)]))
        get(doc, where)["zz_" + draw(st.text(string.ascii_lowercase, min_size=1, max_size=6))] = 1.0
        return tomli_w.dumps(doc), True
    path = draw(st.sampled_from(leaves(doc)))
    parent, key = get(doc, path[:-1]), path[-1]
    old = parent[key]
    number = isinstance(old, int | float) and not isinstance(old, bool)
    bad = False
    if kind == "delete":
        del parent[key]
    elif kind == "type":
        new = draw(NOT_A_NUMBER if number else st.one_of(st.integers(-5, 5), st.just([[]]), st.just({"b": 2})))
        parent[key] = new
        bad = (number and not (isinstance(new, int | float) and not isinstance(new, bool))) or (
            isinstance(old, bool) and not isinstance(new, bool))
    elif kind == "nonfinite":
        parent[key] = draw(st.sampled_from([math.nan, math.inf, -math.inf]))
        bad = number
    else:  # absurd magnitudes: either refused (2), or flown and reported (0/1)
        parent[key] = draw(st.sampled_from([1e300, -1e300, 10**30, -(10**30)]))
    return tomli_w.dumps(doc), bad


def _toml_case(env, kind: str, text: str, bad: bool, command: int) -> None:
    path = scratch(env, ".toml")
    path.write_text(text, encoding="utf-8", errors="surrogateescape")
    slow_ok = bad  # design and learn only get files that must be refused before any solve
    if kind == "program":
        argv = [["simulate", str(path)], ["fly", str(path), "--plant", "nominal"]][command % 2]
    elif kind == "vehicle":
        options = [["simulate", str(EXAMPLES / "hover.toml"), "--vehicle", str(path)]]
        if slow_ok:
            options += [["design", *SMALL, "--vehicle", str(path)],
                        ["learn", *SMALL, "--plant", "nominal", "--iterations", "1", "--vehicle", str(path),
                         "--db", str(env["root"] / "fuzz.sqlite"), "--out", str(env["root"] / "o")]]
        argv = options[command % len(options)]
    else:
        options = [["fly", str(EXAMPLES / "hover.toml"), "--plant", "arena", "--arena", str(path)]]
        if slow_ok:
            options += [["learn", *SMALL, "--plant", "arena", "--arena", str(path), "--iterations", "1",
                         "--db", str(env["root"] / "fuzz.sqlite"), "--out", str(env["root"] / "o")]]
        argv = options[command % len(options)]
    code, _, err = call(argv)
    check(code, err, bad=bad, argv=argv)


@FUZZ
@given(data=st.data(), command=st.integers(0, 5))
def test_malformed_program_files(env, data, command):
    text, bad = data.draw(mutated_toml(Path(env["program"]).read_text()))
    _toml_case(env, "program", text, bad, command)


@FUZZ
@given(data=st.data(), command=st.integers(0, 5))
def test_malformed_vehicle_files(env, data, command):
    text, bad = data.draw(mutated_toml(Path(env["vehicle"]).read_text()))
    _toml_case(env, "vehicle", text, bad, command)


@settings(FUZZ, max_examples=60)
@given(data=st.data(), command=st.integers(0, 5))
def test_malformed_arena_files(env, data, command):
    text, bad = data.draw(mutated_toml(Path(env["arena"]).read_text()))
    _toml_case(env, "arena", text, bad, command)


# ----------------------------------------------------------------- arguments


def not_an_int(text: str) -> bool:
    try:
        int(text)
    except ValueError:
        return True
    return False


def not_a_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return True
    return False


ARG_TEXT = st.text(alphabet=st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"),
                   max_size=12).filter(lambda t: not t.startswith("-"))
BAD_INT = st.one_of(ARG_TEXT.filter(not_an_int), st.sampled_from(["1.5", "1e3", "", "three"]))
BAD_FLOAT = st.one_of(ARG_TEXT.filter(not_a_float), st.sampled_from(["", "1,5", "one"]))


def defects(env: dict[str, Any], command: str) -> st.SearchStrategy:
    """Strategies of (options to add, options to drop) that make ``command`` bad input."""
    db_file = st.sampled_from([str(p) for p in env["bad_dbs"]] + [""])
    common = [
        st.tuples(st.tuples(st.text(string.ascii_lowercase, min_size=1, max_size=8).map(lambda s: "--zz" + s)),
                  st.just(())),
    ]
    session_bad = st.one_of(st.sampled_from(["0", "-1", "abc", "1.5", "", "lastt"]), ARG_TEXT.filter(
        lambda t: t.strip().lower() != "last" and not t.strip().isdigit()))
    missing_session = st.sampled_from(["99", "123456789012345678901234567890"])
    if command in ("design", "learn"):
        common += [
            st.tuples(st.tuples(st.just("--flips"), st.one_of(BAD_INT, st.sampled_from(["0", "11", "-3", "10" * 9]))),
                      st.just(("--flips",))),
            st.tuples(st.tuples(st.just("--max-rate-deg-s"), st.one_of(
                BAD_FLOAT, st.sampled_from(["nan", "inf", "-inf", "0", "-800", "1e9", "10"]))),
                st.just(("--max-rate-deg-s",))),
            st.tuples(st.tuples(st.just("--dims"), st.one_of(BAD_INT, st.sampled_from(["1", "4", "-2"]))),
                      st.just(("--dims",))),
            st.tuples(st.tuples(st.just("--ramp-s"), st.one_of(BAD_FLOAT, st.sampled_from(["-0.1", "1.5", "nan"]))),
                      st.just(())),
            st.tuples(st.tuples(st.just("--axis"), ARG_TEXT.filter(lambda t: t not in ("roll", "pitch"))),
                      st.just(())),
            st.tuples(st.tuples(st.just("--correction"), ARG_TEXT.filter(
                lambda t: t not in ("tsvd", "inverse", "damped"))), st.just(())),
            st.tuples(st.tuples(st.just("--vehicle"), st.sampled_from(
                ["blimp", str(env["root"]), str(env["root"] / "none.toml"), str(env["plain_file"])])), st.just(())),
        ]
    if command == "learn":
        common += [
            st.tuples(st.tuples(st.just("--iterations"), st.one_of(BAD_INT, st.sampled_from(["0", "-1", "10001"]))),
                      st.just(("--iterations",))),
            st.tuples(st.tuples(st.just("--gamma"), st.one_of(
                ARG_TEXT.filter(lambda t: t != "paper" and (not_a_float(t) or not 0 < float(t) <= 1)),
                st.sampled_from(["0", "1.01", "nan", "-0.5", "inf"]))), st.just(())),
            st.tuples(st.tuples(st.just("--plant"), ARG_TEXT.filter(
                lambda t: t not in ("nominal", "arena", "rotorpy"))), st.just(("--plant",))),
            st.tuples(st.tuples(st.just("--seed"), BAD_INT), st.just(())),
            st.tuples(st.tuples(st.just("--resume"), st.one_of(session_bad, missing_session)), st.just(())),
            st.tuples(st.tuples(st.just("--from-session"), st.one_of(session_bad, missing_session)), st.just(())),
            st.tuples(st.tuples(st.just("--db"), db_file.filter(lambda p: "missing" not in p)), st.just(("--db",))),
            st.tuples(st.tuples(st.just("--out"), st.just(str(env["plain_file"] / "sub"))), st.just(("--out",))),
            st.tuples(st.tuples(st.just("--arena"), st.sampled_from(
                [str(env["root"]), str(env["plain_file"]), str(env["root"] / "none.toml")])), st.just(())),
        ]
    if command in ("show", "plot", "export"):
        common += [
            st.tuples(st.tuples(st.just("SESSION"), st.one_of(session_bad, missing_session)), st.just(("SESSION",))),
            st.tuples(st.tuples(st.just("--db"), db_file), st.just(("--db",))),
        ]
    if command == "sessions":
        common += [
            st.tuples(st.tuples(st.just("--db"), db_file), st.just(("--db",))),
            st.tuples(st.tuples(st.just("--limit"), st.one_of(BAD_INT, st.sampled_from(["0", "-4"]))), st.just(())),
        ]
    if command == "export":
        common += [
            st.tuples(st.tuples(st.just("--format"), ARG_TEXT.filter(lambda t: t not in ("csv", "json"))),
                      st.just(())),
            st.tuples(st.tuples(st.just("--trajectories")), st.just(("--format",))),  # csv has no trajectories
            st.tuples(st.tuples(st.just("--output"), st.just(str(env["plain_file"] / "x.csv"))), st.just(())),
        ]
    if command == "plot":
        common += [st.tuples(st.tuples(st.just("--out"), st.just(str(env["plain_file"] / "d"))), st.just(()))]
    if command in ("simulate", "fly"):
        common += [
            st.tuples(st.tuples(st.just("PROGRAM"), st.sampled_from(
                [str(env["root"]), str(env["root"] / "none.toml"), str(env["plain_file"]), ""])),
                st.just(("PROGRAM",))),
            st.tuples(st.tuples(st.just("--vehicle"), st.sampled_from(["blimp", str(env["plain_file"])])),
                      st.just(())),
        ]
    if command == "simulate":
        common += [st.tuples(st.tuples(st.just("--mode"), ARG_TEXT.filter(
            lambda t: t not in ("continuous", "sampled"))), st.just(()))]
    if command == "fly":
        common += [st.tuples(st.tuples(st.just("--trials"), st.one_of(BAD_INT, st.sampled_from(["0", "100001"]))),
                             st.just(("--trials",)))]
    return st.one_of(common)


def base_args(env: dict[str, Any], command: str) -> dict[str, list[str]]:
    """Valid, fast arguments per command, as {option: values} (positional keys in capitals)."""
    db = str(env["db"])
    scratch_db = str(env["root"] / "fuzz.sqlite")
    return {
        "simulate": {"PROGRAM": [str(env["program"])]},
        "fly": {"PROGRAM": [str(EXAMPLES / "hover.toml")], "--plant": ["nominal"], "--trials": ["1"]},
        "design": {"MANEUVER": ["flip"], "--dims": ["2"], "--flips": ["1"], "--max-rate-deg-s": ["800"]},
        "learn": {"MANEUVER": ["flip"], "--dims": ["2"], "--flips": ["1"], "--max-rate-deg-s": ["800"],
                  "--plant": ["nominal"], "--iterations": ["1"], "--db": [scratch_db],
                  "--out": [str(env["root"] / "learn-out")]},
        "sessions": {"--db": [db]},
        "show": {"SESSION": ["1"], "--db": [db]},
        "plot": {"SESSION": ["1"], "--db": [db], "--out": [str(env["root"] / "plots")]},
        "export": {"SESSION": ["1"], "--db": [db], "--format": ["csv"]},
    }[command]


COMMANDS = ["simulate", "fly", "design", "learn", "sessions", "show", "plot", "export"]


@st.composite
def bad_command_line(draw, env: dict[str, Any]) -> list[str]:
    command = draw(st.sampled_from(COMMANDS))
    args = base_args(env, command)
    for added, dropped in draw(st.lists(defects(env, command), min_size=1, max_size=3)):
        for key in dropped:
            args.pop(key, None)
        if added:
            args[added[0]] = list(added[1:])
    positional = [v for k, vs in args.items() if k.isupper() for v in vs]
    options = [x for k, vs in args.items() if not k.isupper() for x in (k, *vs)]
    order = draw(st.permutations(range(2)))
    return [command, *(positional + options if order[0] == 0 else options + positional)]


@settings(FUZZ, max_examples=250)
@given(data=st.data())
def test_bad_arguments_to_every_command(env, data):
    argv = data.draw(bad_command_line(env))
    assume("--" not in argv)
    code, _, err = call(argv)
    check(code, err, bad=True, argv=argv)


@settings(FUZZ, max_examples=80)
@given(argv=st.lists(st.one_of(st.sampled_from(COMMANDS + ["--db", "--json", "--iterations", "--resume", "last",
                                                            "flip", "-x", "--format", "json", "1", "nan"]),
                               ARG_TEXT), max_size=6))
def test_random_words_never_crash(env, argv):
    assume(not any(a in ("-h", "--help") or a.startswith("--h") for a in argv))
    # keep random words away from long runs and from files in the working directory
    assume(not (argv and argv[0] in ("learn", "design", "fly", "plot")))
    assume(not (argv and argv[0] == "export" and "--output" in argv))
    code, _, err = call([*argv, "--db", str(env["db"])] if argv and argv[0] in ("sessions", "show", "export")
                        else argv)
    check(code, err, bad=False, argv=argv)


@pytest.mark.parametrize("argv, fragment", [(["--help"], "sessions"), (["learn", "--help"], "--resume"),
                                             (["sessions", "--help"], "--db"), (["export", "--help"], "--format")])
def test_help_exits_0(capsys, argv, fragment):
    assert main(argv) == 0  # main() returns the status; it never raises SystemExit
    assert fragment in capsys.readouterr().out


def test_deeply_nested_toml_is_bad_input(tmp_path):
    path = tmp_path / "deep.toml"
    path.write_text("a = " + "[" * 5000 + "]" * 5000)
    code, _, err = call(["simulate", str(path)])
    assert code == 2 and "Traceback" not in err
    assert err.count("\n") == 1 and err.startswith("aerobat: error: ") and str(path) in err


# --------------------------------------------------------------- installed command


@pytest.mark.parametrize("case", ["random-bytes-vehicle", "foreign-db", "bad-option", "missing-session",
                                  "nan-rate", "newer-db"])
def test_the_installed_command_answers_bad_input_in_one_line(env, case):
    exe = ROOT / ".venv" / "bin" / "aerobat"
    prefix = [str(exe)] if exe.exists() else [sys.executable, "-m", "aerobat.cli"]
    bad_vehicle = env["root"] / "bytes.toml"
    bad_vehicle.write_bytes(b"\xff\xfe\x00garbage[[[")
    argv = {
        "random-bytes-vehicle": ["design", *SMALL, "--vehicle", str(bad_vehicle)],
        "foreign-db": ["sessions", "--db", str(env["bad_dbs"][1])],
        "bad-option": ["learn", *SMALL, "--iterations", "many"],
        "missing-session": ["show", "7", "--db", str(env["db"])],
        "nan-rate": ["learn", "flip", "--max-rate-deg-s", "nan", "--db", str(env["root"] / "n.sqlite")],
        "newer-db": ["export", "1", "--db", str(env["bad_dbs"][2])],
    }[case]
    result = subprocess.run([*prefix, *argv], capture_output=True, text=True, timeout=120, cwd=env["root"])
    assert result.returncode == 2, result.stderr
    assert result.stdout == ""
    assert result.stderr.count("\n") == 1 and result.stderr.startswith("aerobat: error: ")
    assert "Traceback" not in result.stderr


# ------------------------------------------------- found by scripts/fuzz_campaign.py (issue 19)


def one_line(code: int, err: str, status: int, *fragments: str) -> None:
    lines = err.splitlines()
    prefix = "aerobat: error: " if status == 2 else "aerobat: failed: "
    assert code == status and len(lines) == 1 and lines[0].startswith(prefix) and "Traceback" not in err, (code, err)
    for fragment in fragments:
        assert fragment in lines[0], err


@pytest.mark.parametrize("argv, names", [(["benchmark"], ("benchmark", "translation", "map")),
                                         (["study"], ("study", "robustness", "rules", "envelope"))])
def test_a_command_group_without_its_command_says_so_in_one_line(argv, names):
    code, out, err = call(argv)
    one_line(code, err, 2, *names)
    assert "usage:" in out  # and the group's commands, on standard output


@pytest.mark.parametrize("command", ["simulate", "fly", "benchmark"])
def test_a_figure_file_of_an_unknown_format_is_refused_in_one_line(tmp_path, command):
    figure = tmp_path / "figure.sqlite"
    argv = {"simulate": ["simulate", str(EXAMPLES / "hover.toml")],
            "fly": ["fly", str(EXAMPLES / "hover.toml"), "--plant", "nominal"],
            "benchmark": ["benchmark", "translation", "--to", "1,1"]}[command]
    code, _, err = call([*argv, "--plot", str(figure)])
    one_line(code, err, 2, str(figure), ".png")
    assert not figure.exists()


def test_an_undecodable_file_name_is_printed_as_given(tmp_path):
    """``aerobat examples $'\\xff'``: argv carries the byte as \\udcff; strict UTF-8 stdout must not crash."""
    folder = tmp_path / "ex\udcff"
    raw = io.BytesIO()
    strict = io.TextIOWrapper(raw, encoding="utf-8", errors="strict", write_through=True)
    err = io.StringIO()
    with contextlib.redirect_stdout(strict), contextlib.redirect_stderr(err):
        code = main(["examples", str(folder)])
    assert code == 0, err.getvalue()
    assert os.fsencode(str(folder)) in raw.getvalue()
    assert strict.errors == "strict"  # the caller's stream is left as it was


@pytest.mark.parametrize("address", ["nan", "1:2:3", ":", "inproc://x", "abc://h:1", "tls://127.0.0.1:1"])
def test_an_unusable_scheduler_address_is_bad_input(tmp_path, address):
    code, _, err = call(["benchmark", "map", "--y", "1:1:1", "--z", "1:1:1", "--scheduler", address,
                         "--db", str(tmp_path / "s.sqlite"), "--out", str(tmp_path / "out")])
    one_line(code, err, 2, "scheduler", repr(address))


def test_a_negative_number_after_a_flag_is_not_its_value(env):
    """``studies --json -1``: the -1 is the study, refused as such (not ``--json: ignored explicit argument``)."""
    code, _, err = call(["studies", "--json", "-1", "--db", str(env["db"])])
    one_line(code, err, 2, "study", "'-1'")
    code, out, err = call(["sessions", "--json", "--limit", "-1", "--db", str(env["db"])])
    one_line(code, err, 2, "--limit")


def test_ctrl_c_during_an_ipopt_solve_stops_the_benchmark(monkeypatch):
    """CasADi turns a Ctrl-C inside IPOPT into a failed solve; the command must stop (130), not report a failure."""
    import signal

    from aerobat.quadrotor.timeoptimal import transcription

    real = transcription.transcription_solver

    def interrupted_solver(*args, **kwargs):
        solver = real(*args, **kwargs)

        class Interrupted:
            def __call__(self, **inputs):
                try:  # what CasADi does: its signal check raises KeyboardInterrupt, which it catches
                    signal.raise_signal(signal.SIGINT)
                except KeyboardInterrupt:
                    pass
                return solver(**inputs)

            def stats(self):
                return solver.stats()

        return Interrupted()

    monkeypatch.setattr(transcription, "transcription_solver", interrupted_solver)
    code, _, err = call(["benchmark", "translation", "--to", "1,1"])
    assert code == 130 and err.startswith("aerobat: interrupted"), (code, err)


LONG = "飞" * 100 + ".toml"  # 300 bytes: longer than any file name the file system allows


@pytest.mark.parametrize("case", ["db", "ranges", "vehicle", "maneuver", "program", "output", "design-program"])
def test_a_file_name_too_long_for_the_file_system_is_bad_input(env, case):
    long = str(env["root"] / LONG)
    argv = {
        "db": ["sessions", "--db", long],
        "ranges": ["study", "robustness", *SMALL, "--vehicles", "1", "--iterations", "1", "--workers", "1",
                   "--ranges", long, "--db", str(env["root"] / "r.sqlite")],
        "vehicle": ["design", *SMALL, "--vehicle", long.removesuffix(".toml") + "x"],
        "maneuver": ["design", "--maneuver", long.removesuffix(".toml")],
        "program": ["simulate", long],
        "output": ["export", "1", "--db", str(env["db"]), "--output", long],
        "design-program": ["design", *SMALL, "--program", long],
    }[case]
    code, _, err = call(argv)
    assert code == 2 and err.count("\n") == 1 and err.startswith("aerobat: error: ") and "Traceback" not in err, err


def test_an_unusable_scheduler_is_refused_before_a_study_is_created(tmp_path):
    """With --json the study's announcement goes to stderr; a bad --scheduler must not leave it (or the study)."""
    db = tmp_path / "s.sqlite"
    code, _, err = call(["study", "envelope", "--flips", "1", "--rates-deg-s", "800", "--dims", "2", "--json",
                         "--scheduler", "nan", "--db", str(db), "--out", str(tmp_path / "out")])
    one_line(code, err, 2, "scheduler")
    code, out, _ = call(["studies", "--json", "--db", str(db)])
    assert code == 0 and json.loads(out) == []


def test_a_store_whose_name_has_undecodable_bytes_works(tmp_path):
    """``--db $'\\xff.sqlite'``: the SQLite URI is built from the file name's bytes (it failed to encode)."""
    db = tmp_path / "s\udcff.sqlite"
    code, _, err = call(["learn", *SMALL, "--plant", "nominal", "--iterations", "1", "--db", str(db),
                         "--out", str(tmp_path / "out")])
    assert code == 0, err
    assert os.path.exists(os.fsencode(str(db)))
    code, out, err = call(["sessions", "--json", "--db", str(db)])
    assert code == 0 and len(json.loads(out)) == 1, err


def test_a_scheduler_address_where_something_else_answers_is_bad_input(tmp_path):
    """A server that is not a Dask scheduler can answer anything: an HTTP reply read as a frame length is 3 EiB."""
    import socket
    import threading

    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]

    def answer() -> None:
        with contextlib.suppress(OSError):
            while True:
                conn, _ = server.accept()
                conn.recv(1024)
                conn.sendall(b"HTTP/1.1 400 Bad Request\r\nconnection: close\r\ncontent-length: 0\r\n\r\n")
                conn.close()

    threading.Thread(target=answer, daemon=True).start()
    try:
        code, _, err = call(["benchmark", "map", "--y", "1:1:1", "--z", "1:1:1", "--scheduler",
                             f"tcp://127.0.0.1:{port}", "--db", str(tmp_path / "s.sqlite"),
                             "--out", str(tmp_path / "out")])
    finally:
        server.close()
    one_line(code, err, 2, "scheduler")
