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

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "fuzz_campaign.py"


def _module():
    spec = importlib.util.spec_from_file_location("fuzz_campaign", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules["fuzz_campaign"] = module
    spec.loader.exec_module(module)
    return module


def _campaign(tmp_path: Path, *, cli: int, api: int, seed: int, budget_s: float, timeout: float) -> dict:
    report = tmp_path / "fuzz.json"
    result = subprocess.run([sys.executable, str(SCRIPT), "--cli", str(cli), "--api", str(api), "--seed", str(seed),
                             "--budget-s", str(budget_s), "--report", str(report)],
                            capture_output=True, text=True, timeout=timeout, cwd=tmp_path)
    data = json.loads(report.read_text())
    internal = data["cli"]["internal"] + data["api"]["internal"]
    assert result.returncode == 0 and data["internal"] == 0, json.dumps(internal, indent=1)[:8000]
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


def test_a_small_campaign_finds_no_internal_error(tmp_path):
    data = _campaign(tmp_path, cli=60, api=40, seed=1, budget_s=4.0, timeout=240)
    assert data["cli"]["counts"].get("ok", 0) > 0 and data["cli"]["counts"].get("bad-input", 0) > 0


@pytest.mark.slow
def test_the_full_campaign_finds_no_internal_error(tmp_path):
    """Issue 19: 2,000 command lines and 500 library calls, 0 internal errors, 0 tracebacks."""
    data = _campaign(tmp_path, cli=2000, api=500, seed=0, budget_s=6.0, timeout=3 * 3600)
    assert len(data["cli"]["by_command"]) >= 16
