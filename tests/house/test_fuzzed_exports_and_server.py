"""The exports and server phases of the fuzz campaign (issue 45; ``scripts/fuzz_exports.py``, ``fuzz_server.py``).

A seeded sample of each phase runs here against a small store and must end with no internal error,
no hang and no data loss; the phases' own judges are checked too, so that a phase that stopped
noticing a link written through, or a traceback, does not pass for a clean one. The full phases
(over 300 cases each) run with ``python scripts/fuzz_exports.py``.
"""

from __future__ import annotations

import importlib.util
import json
import os
import random
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from browse_fixtures import build_store

ROOT = Path(__file__).resolve().parents[2]


def _script(name: str):
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    """The campaign's fixtures and a small store (two flown sessions and a study), as the phases get them."""
    fz = _script("fuzz_campaign")
    root = tmp_path_factory.mktemp("fuzz-exports")
    fx = fz.Fixtures(root, random.Random(0))
    build_store(fx.store, sessions=2, study_vehicles=1, failed_jobs=0)
    fx.backup_store()
    (root / "work").mkdir()
    return fz, fx, root


@pytest.fixture
def campaign(scratch, monkeypatch):
    fz, fx, root = scratch
    monkeypatch.chdir(root / "work")
    monkeypatch.setenv("AEROBAT_DB", str(fx.store))
    said: list[str] = []
    run = fz.Campaign(seed=3, budget_s=6.0, root=root, progress=said.append)
    yield fz, run, fx
    run.alarm.close()


def _zeros(report: dict) -> None:
    findings = {key: report[key] for key in ("internal", "hangs", "data_loss")}
    assert not any(findings.values()), json.dumps(findings, indent=1, default=str)[:8000]


def test_a_sample_of_the_exports_phase_finds_nothing(campaign):
    fz, run, fx = campaign
    _script("fuzz_exports").run_exports_phase(fz, run, fx, 16)
    report = run.report["exports"]
    _zeros(report)
    assert report["cases"] == 16 == sum(report["counts"].values()) + len(report["not_covered"])
    assert set(report["by_kind"]) == {"browse-link", "browse-folder", "output-link", "full-disk"} or \
        report["full_disk"].get("skipped")
    assert report["counts"]["bad-input"] >= 6 and report["counts"].get("ok", 0) + report["counts"].get(
        "failed", 0) >= 1
    assert len(report["reference"]["pages"]) >= 10  # index, 3 session pages, 6 figures and replays, study, compare


def test_a_sample_of_the_server_phase_finds_nothing(campaign):
    fz, run, fx = campaign
    _script("fuzz_server").run_server_phase(fz, run, fx, 40)
    report = run.report["server"]
    _zeros(report)
    assert report["cases"] == 40 == sum(report["counts"].values()) == report["counts"]["ok"]
    assert len(report["by_kind"]) == 8


def test_the_phases_judges_see_a_link_written_through_a_late_refusal_and_a_half_file(tmp_path):
    exports, server = _script("fuzz_exports"), _script("fuzz_server")
    cases, store = tmp_path / "cases", tmp_path / "store.sqlite"
    store.write_bytes(b"SQLite format 3\x00" + bytes(100))
    site = cases / "c1" / "site"
    site.mkdir(parents=True)
    other = cases / "c1" / "other.txt"
    other.write_text("somebody else")
    os.symlink(other, site / "index.html")
    targets = exports.link_targets(store, cases, site / "index.html")
    assert set(targets) == {store, other}
    (site / "index.html").write_text("<html>written through the link</html>")  # what the export did before
    assert [p for p, d in targets.items() if exports.digest(p) != d] == [other]
    refused = exports.Case("browse-link", "symlink-other", "index.html", [], [], refused=True)
    replaced = exports.Case("browse-link", "symlink-other", "index.html", [], [], refused=False)
    listing = exports.listing(site)
    assert "exit 0" in exports.judge_case(refused, 0, "", listing, listing, site / "index.html", None)
    assert "not replaced" in exports.judge_case(replaced, 0, "", listing, listing, site / "index.html", None)
    (site / "index.html").unlink()
    (site / "index.html").write_text("<html>whole</html>\n")
    assert exports.judge_case(replaced, 0, "", listing, exports.listing(site), site / "index.html", None) is None
    late = exports.judge_case(refused, 2, "", listing, exports.listing(site), site / "index.html", None)
    assert "only after writing" in late
    half = tmp_path / "half.png"
    half.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(100))
    assert not exports.whole(half) and exports.whole(site / "index.html")
    shm = tmp_path / "x-shm"
    shm.write_bytes(bytes(200))
    marked = exports.digest(shm, shm=True)
    shm.write_bytes(bytes(100) + b"\x01" + bytes(99))  # a reader's mark
    assert exports.digest(shm, shm=True) == marked
    shm.write_bytes(b"<html>" + bytes(194))
    assert exports.digest(shm, shm=True) != marked
    assert "b'9' * 5000" in server.as_python(b"GET /session-" + b"9" * 5000 + b".html")
    fake = SimpleNamespace(port=1, argv=["browse", "--db", "s", "--host", "h", "--port", "0", "--json"])
    case = server.Case("huge-id", "x", b"GET / HTTP/1.1\r\n\r\n", (404,))
    assert "socket.create_connection" in server.reproduce(fake, case, case.request)
