"""How fast the store and `aerobat browse` answer on a lab's store (issue 46: 100,000 sessions).

Builds the store in a temporary folder (``tests/browse_fixtures.build_large_store``: a fifth plain
sessions, the rest in studies of 1,000, each study session with its own sampled vehicle and plant,
as a robustness study stores them), serves it on a free port and times, over ``--repeat`` fetches
each (median): the first page of the sessions table, a filter, a text search, a deep page sorted
by the last error, the study page, a session page and its progress JSON. With ``--chromium`` it
also times the first page in headless Chromium (the process's wall time, and Chromium's own
start-up on an empty page beside it). Then each store command as a new process, as a user runs
it: ``aerobat sessions --limit 50``, ``studies``, ``show``, ``compare``. Prints one JSON object;
``make bench`` puts the same figures in docs/performance.md (:func:`section`).

    .venv/bin/python benchmarks/browse_load.py [--sessions 100000] [--repeat 5] [--chromium]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from aerobat.browse import start  # noqa: E402
from browse_fixtures import build_large_store  # noqa: E402


def timed(url: str, repeat: int) -> dict[str, float]:
    times, size = [], 0
    for _ in range(repeat):
        started = time.perf_counter()
        with urllib.request.urlopen(url, timeout=120) as response:
            size = len(response.read())
        times.append(time.perf_counter() - started)
    return {"median_s": round(statistics.median(times), 4), "max_s": round(max(times), 4), "bytes": size}


def _chromium_s(chromium: str, url: str, profile: Path) -> float:
    started = time.perf_counter()
    subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--dump-dom",
                    f"--user-data-dir={profile}", url], capture_output=True, timeout=180, check=True)
    return time.perf_counter() - started


def _command_s(db: Path, *args: str, repeat: int = 3) -> float:
    """Median wall time of ``aerobat ARGS --db DB`` as a new process (interpreter and imports included)."""
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        subprocess.run([sys.executable, "-m", "aerobat.cli", *args, "--db", str(db)], capture_output=True,
                       check=True, timeout=120)
        times.append(time.perf_counter() - started)
    return round(statistics.median(times), 3)


def run(sessions: int = 100_000, repeat: int = 5, chromium: bool = True) -> dict:
    """Every figure of the benchmark, as a dict."""
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "store.sqlite"
        started = time.perf_counter()
        built = build_large_store(db, sessions=sessions)
        result: dict = {"sessions": sessions, "studies": built["studies"], "build_s": round(time.perf_counter()
                                                                                          - started, 1),
                        "store_mb": round(db.stat().st_size / 1e6), "load": os.getloadavg()[0], "repeat": repeat}
        with start(db, port=0) as browser:
            url = browser.url
            result["index"] = timed(url, repeat)
            result["filter"] = timed(url + "index.html?plant=rotorpy&studies=1", repeat)
            result["search"] = timed(url + "index.html?q=battery&studies=1", repeat)
            result["deep_sorted"] = timed(url + "index.html?studies=1&sort=error&dir=desc&page=500", repeat)
            result["study_page"] = timed(url + "study-7.html", repeat)
            result["session_page"] = timed(url + "session-1.html", repeat)
            result["progress_json"] = timed(url + "api/session-1.json", repeat)
            found = shutil.which("chromium")
            if chromium and found:
                result["chromium_blank_s"] = round(_chromium_s(found, "about:blank", Path(tmp) / "p0"), 2)
                result["chromium_index_s"] = round(_chromium_s(found, url, Path(tmp) / "p1"), 2)
        result["cli_sessions_limit_50_s"] = _command_s(db, "sessions", "--limit", "50")
        result["cli_studies_s"] = _command_s(db, "studies")
        result["cli_show_s"] = _command_s(db, "show", str(sessions // 2))
        result["cli_compare_s"] = _command_s(db, "compare", "1", str(sessions))
    return result


def section(r: dict) -> list[str]:
    """The markdown lines of docs/performance.md's store section."""
    chromium = (f"**{r['chromium_index_s']:.2f} s** (Chromium's own start-up on an empty page: "
                f"{r['chromium_blank_s']:.2f} s)" if "chromium_index_s" in r else "not measured (no chromium)")
    rows = [
        ("first page of the sessions table from the server (100 rows, counts per filter value)", "≤ 0.5 s",
         f"**{r['index']['median_s']:.3f} s** median ({r['index']['bytes'] / 1e3:.0f} kB)"),
        ("the same page in headless Chromium, process start to DOM", "≤ 2 s", chromium),
        ("a filter (plant, study sessions shown)", "≤ 0.5 s", f"**{r['filter']['median_s']:.3f} s**"),
        ("a text search (maneuver, plant, vehicle, rule, tags, notes)", "≤ 0.5 s",
         f"{r['search']['median_s']:.3f} s"),
        ("page 500, sorted by the last error", "—", f"{r['deep_sorted']['median_s']:.3f} s"),
        ("a study's page (1,000 sessions and jobs)", "—", f"{r['study_page']['median_s']:.3f} s"),
        ("a session's page; its progress JSON", "—",
         f"{r['session_page']['median_s']:.3f} s; {r['progress_json']['median_s'] * 1e3:.0f} ms"),
        ("`aerobat sessions --limit 50`, a new process", "≤ 1 s", f"**{r['cli_sessions_limit_50_s']:.2f} s**"),
        ("`aerobat studies`; `show`; `compare`, each a new process", "—",
         f"{r['cli_studies_s']:.2f} s; {r['cli_show_s']:.2f} s; {r['cli_compare_s']:.2f} s"),
    ]
    return [f"## The store at {r['sessions']:,} sessions (`benchmarks/browse_load.py`)", "",
            f"{r['sessions']:,} sessions ({r['studies']} studies of 1,000, each study session with its own vehicle "
            f"and plant; {r['store_mb']} MB), built by `tests/browse_fixtures.build_large_store` in {r['build_s']} s; "
            f"load average {r['load']:.1f} at the start; medians of {r['repeat']} fetches.", "",
            "| what | target | measured |", "|---|---|---|", *[f"| {a} | {b} | {c} |" for a, b, c in rows], ""]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=100_000, help="sessions in the store (default: 100000)")
    parser.add_argument("--repeat", type=int, default=5, help="fetches per page (default: 5)")
    parser.add_argument("--chromium", action="store_true", help="also time the page in headless Chromium")
    args = parser.parse_args()
    print(json.dumps(run(args.sessions, args.repeat, args.chromium)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
