"""The fuzz campaign of issue 19 (``scripts/fuzz_campaign.py``).

A small seeded campaign runs with the fast tests; the full one (2,000 command lines and 500
library calls) is marked slow. Both must end with no internal error. The campaign's own
pieces — the parser walk and the judge — are checked here too, so that a campaign that
silently stopped covering commands, or stopped noticing failures, does not pass for a clean one.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "fuzz_campaign.py"


def _module():
    spec = importlib.util.spec_from_file_location("fuzz_campaign", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules["fuzz_campaign"] = module
    spec.loader.exec_module(module)
    return module


def _campaign(tmp_path: Path, *, cli: int, api: int, seed: int, budget_s: float, timeout: float, files: int = 0,
              files_kinds: str | None = None, tunes: int = 0, logs: int = 0, exports: int = 0,
              server: int = 0) -> dict:
    report = tmp_path / "fuzz.json"
    phases = {"tunes": tunes, "logs": logs, "exports": exports, "server": server}
    result = subprocess.run([sys.executable, str(SCRIPT), "--cli", str(cli), "--api", str(api), "--seed", str(seed),
                             "--budget-s", str(budget_s), "--report", str(report), "--files", str(files),
                             *(["--files-kinds", files_kinds] if files_kinds else []),
                             *(arg for phase, n in phases.items() for arg in (f"--{phase}", str(n)))],
                            capture_output=True, text=True, timeout=timeout, cwd=tmp_path)
    data = json.loads(report.read_text())
    parts = [data[phase] for phase in ("files", *phases) if phase in data]
    keys = ("internal", "hangs", "data_loss", "non_json")
    internal = data["cli"]["internal"] + data["api"]["internal"] + [
        entry for part in parts for key in keys for entry in part.get(key, ())]
    zeros = ("internal", "hangs", "data_loss", "non_json", "over_memory_bound")
    assert result.returncode == 0 and not any(data[key] for key in zeros), \
        (result.stderr[-2000:], json.dumps(internal, indent=1)[:8000])
    assert sum(data["cli"]["counts"].values()) == cli
    assert sum(data["api"]["counts"].values()) == api
    return data


def test_the_campaign_walks_every_command_and_reads_option_bounds():
    from aerobat.cli.app import build_parser

    fuzz = _module()
    cmds = {c.name: c for c in fuzz.commands(build_parser())}
    assert {"learn", "design", "fly", "simulate", "sessions", "show", "plot", "export", "replay", "studies",
            "examples", "benchmark translation", "benchmark map", "study robustness", "study rules",
            "study envelope"} <= set(cmds)
    assert cmds["benchmark"].group and cmds["study"].group
    seed = next(o for o in cmds["learn"].options if "--seed" in o.names)
    assert seed.bounds() == (0, 2**63 - 1) and seed.refuses("-1") and not seed.refuses("0")
    resume = next(o for o in cmds["learn"].options if "--resume" in o.names)
    assert resume.is_ref() and resume.refuses("0")


def test_the_judge_calls_what_must_not_happen_internal():
    fuzz = _module()
    bad = fuzz.Invocation(["learn", "--seed", "-5"], "learn", ["--seed"], "--seed '-5'")
    fine = fuzz.Invocation(["sessions"], "sessions", [])
    judge = fuzz.judge
    assert judge(fine, "returned", 0, "", "", "", 0)[0] == "ok"
    assert judge(bad, "returned", 2, "", "aerobat: error: argument --seed: -5: allowed 0 … 9\n", "", 0)[0] == \
        "bad-input"
    assert judge(bad, "returned", 0, "", "", "", 0)[0] == "INTERNAL"  # bad input accepted
    assert judge(bad, "returned", 2, "", "aerobat: error: something else\n", "", 0)[0] == "INTERNAL"  # not named
    assert judge(fine, "returned", 1, "", "aerobat: failed: a\nand more\n", "", 0)[0] == "INTERNAL"  # two lines
    assert judge(fine, "returned", 70, "", "aerobat: failed: internal error: X\n", "", 0)[0] == "INTERNAL"
    assert judge(fine, "returned", 0, "Traceback (most recent call last):", "", "", 0)[0] == "INTERNAL"
    assert judge(fine, "raised", None, "", "", "ValueError", 0)[0] == "INTERNAL"
    assert judge(fine, "returned", 130, "", "aerobat: interrupted\n", "", 1)[0] == "stopped"
    assert judge(fine, "returned", 130, "", "aerobat: interrupted\n", "", 0)[0] == "INTERNAL"  # nobody asked
    # on a flight controller the budget's Ctrl-C is the operator's kill: its line at once, then the session's (exit 1)
    kill = f"{fuzz.KILL_LINE}\naerobat: failed: stopped: trial 1 aborted: kill: motors stopped at once\n"
    assert judge(fine, "returned", 1, "", kill, "", 1)[0] == "stopped"
    assert judge(fine, "returned", 1, "", kill, "", 0)[0] == "INTERNAL"  # no Ctrl-C was sent
    swapped = "".join(reversed(kill.splitlines(keepends=True)))  # the kill line is written to the descriptor
    assert judge(fine, "returned", 1, "", swapped, "", 1)[0] == "stopped"


def test_a_small_campaign_finds_no_internal_error(tmp_path):
    """Also 30 cases of the files phase (issue 31): special files as inputs and outputs, links to the store; and a
    few of each of issue 45's phases (tunes, logs, exports, server), counted into the campaign's totals."""
    data = _campaign(tmp_path, cli=40, api=25, seed=1, budget_s=4.0, timeout=600, files=30,
                     files_kinds="special-input,special-output,store-link", tunes=6, logs=4, exports=4, server=4)
    assert data["cli"]["counts"].get("ok", 0) > 0 and data["cli"]["counts"].get("bad-input", 0) > 0
    assert sum(data["files"]["counts"].values()) == 30 and data["files"]["counts"].get("bad-input", 0) >= 20
    for phase, n in (("tunes", 6), ("exports", 4), ("server", 4)):
        assert sum(data[phase]["counts"].values()) == n, (phase, data[phase]["counts"])
    logs = data["logs"]
    assert logs.get("skipped") or sum(logs["counts"].values()) == 4, logs.get("counts")
    assert data["cases"] == 40 + 25 + 30 + sum(int(data[p].get("cases", 0)) for p in ("tunes", "logs", "exports",
                                                                                      "server"))


def _files_module():
    fuzz = _module()
    return fuzz, fuzz.files_module()


def test_the_files_phase_covers_every_input_output_and_folder(tmp_path):
    """Issue 31: `=--` and empty values, FIFO and devices as inputs, the store and links to it as outputs."""
    from types import SimpleNamespace

    from aerobat.cli.app import build_parser

    fuzz, files = _files_module()
    fx = SimpleNamespace(store=tmp_path / "store.sqlite", dir=tmp_path)
    uncovered: list[str] = []
    cases = files.build_cases(fuzz.commands(build_parser()), fx, tmp_path, uncovered)
    by = {}
    for case in cases:
        by.setdefault(case.kind, []).append(case)
    assert set(by) == set(files.KINDS)
    assert uncovered == ["log info", "log plot", "log export", "log replay"]  # they need a real flight log

    def tested(kind: str, command: str, option: str) -> list:
        return [c for c in by[kind] if " ".join(c.argv).startswith(command + " ")
                and next(a for a in reversed(c.argv) if a != "--force").startswith(option + "=")]

    for command, option in (("simulate", "--vehicle"), ("fly", "--arena"), ("learn", "--maneuver"),
                            ("study robustness", "--ranges"), ("learn", "--db"), ("identify", "--tune")):
        values = {next(a for a in reversed(c.argv) if a != "--force").split("=", 1)[1]
                  for c in tested("special-input", command, option)}
        assert {"/dev/zero", "/dev/urandom"} <= values, (command, option)
        assert any(v.endswith("fifo.toml") for v in values), (command, option)
    assert any(c.argv[1].endswith("fifo.toml") for c in by["special-input"] if c.argv[0] == "simulate")  # a positional
    for command, option in (("export", "--output"), ("identify", "--figure"), ("design", "--program"),
                            ("simulate", "--plot")):
        setups = [" ".join(c.setup) for c in tested("store-link", command, option)]
        assert len(setups) == 4 and sum("ln -s" in s for s in setups) == 1, (command, setups)
    for command in ("learn", "plot", "replay", "benchmark map", "study envelope", "examples"):
        folders = [c for c in by["store-link"] if " ".join(c.argv).startswith(command) and len(c.setup) > 2]
        assert len(folders) == 2 and any("session.json" in line for line in folders[0].setup), command
    dashdash = tested("dashdash", "study envelope", "--workers")
    assert dashdash and dashdash[0].bad and dashdash[0].dropped == ("workers", "--")
    assert tested("empty", "export", "--output")[0].bad  # an empty file name must be refused


def test_the_files_phase_sees_data_loss_and_dropped_values(tmp_path):
    import sqlite3

    _, files = _files_module()
    db = tmp_path / "s.sqlite"
    conn = sqlite3.connect(db)
    conn.executescript("CREATE TABLE sessions (x); CREATE TABLE iterations (x); INSERT INTO sessions VALUES (1);")
    conn.commit()
    conn.close()
    assert files.store_counts(db) == (1, 0)
    db.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(200))  # a figure written over it
    assert "no longer an SQLite file" in files.store_counts(db)
    assert files.silently_dropped(["export", "1", "--output=x"], "output", "x") is False
    import argparse

    class Drops(argparse.Action):  # what argparse does with `--opt=--`: the value never arrives
        def __call__(self, parser, namespace, values, option_string=None):
            setattr(namespace, self.dest, [])

    parser = argparse.ArgumentParser()
    parser.add_argument("--o", action=Drops)
    parser.add_argument("--k")
    assert files.silently_dropped(["--o=--"], "o", "--", parser) is True
    assert files.silently_dropped(["--k=x"], "k", "x", parser) is False


@pytest.mark.slow
def test_the_full_campaign_finds_no_internal_error(tmp_path):
    """Issues 19 and 45: 2,000 command lines, 500 library calls and every case of the files, tunes, logs, exports and
    server phases; 0 internal errors, hangs, data loss, non-JSON outputs, and log commands within their memory bound."""
    data = _campaign(tmp_path, cli=2000, api=500, seed=0, budget_s=6.0, timeout=4 * 3600, files=-1, tunes=-1, logs=-1,
                     exports=-1, server=-1)
    assert len(data["cli"]["by_command"]) >= 16
    assert data["cases"] >= 2000 + 500 + 1000
