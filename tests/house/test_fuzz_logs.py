"""The logs phase of the fuzz campaign (issue 45, ``scripts/fuzz_logs.py``).

A seeded sample of its crafted logs, two of every kind, runs with the fast tests (each case a real ``aerobat``
process): no internal error, hang, data loss or output that is not JSON, and every process within 300 MB + 20
times its file. The phase's own judge is checked too, so that a phase that stopped noticing does not pass for
a clean one. The whole phase (``python scripts/fuzz_logs.py``, 1,356 cases) is the campaign's.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import sys
from collections import Counter
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def phase(tmp_path):
    fz, logs = _load("fuzz_campaign"), _load("fuzz_logs")
    if not logs.DATA.is_dir():
        pytest.skip(f"the real flight logs are not here ({logs.DATA} is absent)")
    campaign = fz.Campaign(seed=0, budget_s=6.0, root=tmp_path, progress=lambda text: None)
    yield fz, logs, campaign
    campaign.alarm.close()


def test_a_sample_of_crafted_logs_gives_no_finding(phase):
    fz, logs, campaign = phase
    n = 2 * len(logs.KINDS)
    logs.run_logs_phase(fz, campaign, None, n)
    report = campaign.report["logs"]
    assert report["cases"] == n and sum(report["counts"].values()) == n
    assert set(report["by_kind"]) == set(logs.KINDS)
    found = {key: report[key] for key in ("internal", "hangs", "data_loss", "non_json")}
    assert logs.findings(report) == 0, json.dumps({**found, "over": report["peak_memory"]["over_bound"]})[:8000]
    assert 100 < report["peak_memory"]["worst_mb"] <= report["peak_memory"]["bound_mb"]


def test_there_are_a_thousand_cases_of_every_kind_with_unique_labels():
    logs = _load("fuzz_logs")
    if not logs.DATA.is_dir():
        pytest.skip(f"the real flight logs are not here ({logs.DATA} is absent)")
    cases = logs.build_cases()
    assert len(cases) >= 1000 and {c.kind for c in cases} == set(logs.KINDS)
    assert len({c.label for c in cases}) == len(cases)
    numbers = {c.label.split("=")[0] for c in cases if c.kind == "bb-number"}
    assert {"bb-number:I interval", "bb-number:P interval", "bb-number:acc_1G", "bb-number:motorOutput"} <= numbers
    assert {c.label for c in cases if c.kind == "cf-time"} >= {f"cf-time:0:{bit}" for bit in range(64)}


def _judged(phase, tmp_path: Path, *, argv: list[str], code: int, out: bytes, err: bytes, peak_mb: float,
            changed: bool = False) -> dict:
    fz, logs, campaign = phase
    work = tmp_path / "case"
    work.mkdir(parents=True)
    (work / "out").write_bytes(out)
    (work / "err").write_bytes(err)
    path = work / "log.bbl"
    path.write_bytes(b"H Product:Blackbox flight data recorder\n")
    case = logs.LogCase("bb-number", "test", lambda: b"")
    run = logs.Running(case, 0, path, work, argv, None, 0.0, "" if changed else hashlib.sha256(
        path.read_bytes()).hexdigest())
    report = {"counts": Counter(), "by_kind": {}, "internal": [], "hangs": [], "data_loss": [], "non_json": [],
              "peak_memory": {"worst_mb": 0.0, "bound_mb": 0.0, "worst_fraction_of_bound": 0.0, "case": None,
                              "over_bound": [], "highest": []}}
    logs.judge_case(fz, run, code, peak_mb, 1.0, report, {}, campaign, keep=True)
    return report


def test_the_phase_calls_what_must_not_happen_a_finding(phase, tmp_path):
    fz, logs, _ = phase
    info = ["log", "info", "x", "--json"]
    clean = _judged(phase, tmp_path / "a", argv=info, code=0, out=b'{"logs": []}', err=b"", peak_mb=200.0)
    assert logs.findings(clean) == 0
    nan = _judged(phase, tmp_path / "b", argv=info, code=0, out=b'{"x": NaN}', err=b"", peak_mb=200.0)
    assert len(nan["non_json"]) == 1
    printed = _judged(phase, tmp_path / "c", argv=info, code=0, out=b"Warning: corrupt\n{}", err=b"", peak_mb=200.0)
    assert len(printed["non_json"]) == 1
    internal = _judged(phase, tmp_path / "d", argv=info, code=70, out=b"", err=b"aerobat: failed: internal error: X\n",
                       peak_mb=200.0)
    assert len(internal["internal"]) == 1
    heavy = _judged(phase, tmp_path / "e", argv=info, code=0, out=b"{}", err=b"", peak_mb=400.0)
    assert len(heavy["peak_memory"]["over_bound"]) == 1
    written = _judged(phase, tmp_path / "f", argv=info, code=0, out=b"{}", err=b"", peak_mb=200.0, changed=True)
    assert len(written["data_loss"]) == 1
