"""The tunes phase of the fuzz campaign (issue 45, ``scripts/fuzz_tunes.py``).

A few dozen crafted tunes, one or more of every class, read by ``aerobat tune`` without flying: no
internal error, hang or data loss. The phase's judge and oracle are checked too, so that a phase
that stopped noticing an unsafe command or a wrong refusal does not pass for a clean one.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import time
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[2]


def _load(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def test_a_small_tunes_phase_finds_no_internal_error(tmp_path: Path) -> None:
    report = tmp_path / "tunes.json"
    started = time.monotonic()
    result = subprocess.run([sys.executable, str(ROOT / "scripts" / "fuzz_tunes.py"), "--cases", "44", "--seed", "1",
                             "--report", str(report)], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    seconds = time.monotonic() - started
    data = json.loads(report.read_text())
    tunes = data["tunes"]
    found = tunes["internal"] + tunes["hangs"] + tunes["data_loss"]
    assert result.returncode == 0 and data["internal"] == data["hangs"] == data["data_loss"] == 0, \
        json.dumps(found, indent=1)[:6000]
    assert sum(tunes["counts"].values()) == 44 and set(tunes["by_class"]) == set(_load("fuzz_tunes").CLASSES)
    assert tunes["counts"]["ok"] >= 5 and tunes["counts"]["bad-input"] >= 5
    assert "tunes 44 cases in 11 classes" in result.stderr
    assert seconds < 30, f"{seconds:.1f} s"


def test_the_oracle_sees_what_the_firmware_would_not_take_as_written() -> None:
    fuzz = _load("fuzz_tunes")
    settings = fuzz.table()
    assert fuzz.unsafe_commands(["set p_roll = 45", "set rates_type = ACTUAL", "feature -ANTI_GRAVITY",
                                 "set profile_name = fast", "set i_roll = 0"], settings) == []
    for bad in (["set profile_name = " + "\x7f" * 19 + "set p_roll = 123"], ["set p_roll = 045"],
                ["set p_roll = 1e2"], ["set p_roll = 251"], ["set p_roll = -0"], ["set rates_type = actual"],
                ["set profile_name = 123456789"], ["set p_roll = 45", "set p_roll = 46"], ["set zz = 1"],
                ["serial 0 1"], ["set profile_name = a#b"], ["set craft_name = " + "A" * 300], "set p_roll = 45"):
        assert fuzz.unsafe_commands(bad, settings), bad


def test_the_judge_holds_each_case_to_what_it_expects(tmp_path: Path) -> None:
    fz, fuzz = _load("fuzz_campaign"), _load("fuzz_tunes")
    settings = fuzz.table()
    path = tmp_path / "t.txt"
    refused = ("returned", 2, "", f"aerobat: error: {path}: line 2: unknown setting 'p_rol'\n", "", 0, 0.1)
    bad = fuzz.TuneCase("unknown-name", b"", ".txt", fuzz.Expect.BAD, ("p_rol",))
    assert fuzz.judge_case(fz, bad, path, refused, settings) == ("bad-input", "")
    assert fuzz.judge_case(fz, fuzz.TuneCase("x", b"", ".txt", fuzz.Expect.BAD, ("p_roll2",)), path, refused,
                           settings)[0] == "INTERNAL"  # the refusal must name the setting
    assert fuzz.judge_case(fz, fuzz.TuneCase("x", b"", ".txt", fuzz.Expect.GOOD), path, refused,
                           settings)[0] == "INTERNAL"  # a good tune refused

    def accepted(*commands: str) -> tuple[object, ...]:
        return "returned", 0, json.dumps({"commands": list(commands)}), "tune ...\n", "", 0, 0.1

    good = fuzz.TuneCase("duplicate", b"", ".txt", fuzz.Expect.GOOD, applied=("p_roll", "41"))
    assert fuzz.judge_case(fz, good, path, accepted("set p_roll = 41"), settings) == ("ok", "")
    assert fuzz.judge_case(fz, good, path, accepted("set p_roll = 40"), settings)[0] == "INTERNAL"  # not the last
    assert fuzz.judge_case(fz, bad, path, accepted("set p_roll = 41"), settings)[0] == "INTERNAL"  # bad accepted
    unsafe = fuzz.judge_case(fz, fuzz.TuneCase("x", b"", ".txt", fuzz.Expect.ANY), path,
                             accepted("set profile_name = \x7f\x7fset p_roll = 123"), settings)
    assert unsafe[0] == "INTERNAL" and "would not take as written" in unsafe[1]
