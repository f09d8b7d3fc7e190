"""How fast `aerobat browse` answers on a store of 1,000 sessions (issue 26: the page within 2 s).

Builds the store (1,000 sessions: 800 in a study, 200 plain) in a temporary folder, serves it on a
free port and times, over ``--repeat`` fetches each: the sessions table (index.html), a session page
and its progress JSON. With ``--chromium`` it also times the table loading in headless Chromium
(the process's wall time, start-up included). Prints one JSON object.

    .venv/bin/python benchmarks/browse_load.py [--sessions 1000] [--repeat 5] [--chromium]
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from aerobat.browse import start  # noqa: E402
from browse_fixtures import build_store  # noqa: E402


def timed(url: str, repeat: int) -> dict[str, float]:
    times, size = [], 0
    for _ in range(repeat):
        started = time.perf_counter()
        with urllib.request.urlopen(url, timeout=60) as response:
            size = len(response.read())
        times.append(time.perf_counter() - started)
    return {"median_s": round(statistics.median(times), 4), "max_s": round(max(times), 4), "bytes": size}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=1000, help="sessions in the store (default: 1000)")
    parser.add_argument("--repeat", type=int, default=5, help="fetches per page (default: 5)")
    parser.add_argument("--chromium", action="store_true", help="also time the page in headless Chromium")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "store.sqlite"
        started = time.perf_counter()
        plain = args.sessions // 5
        build_store(db, sessions=plain, study_vehicles=args.sessions - plain, failed_jobs=0, flown=False)
        built = time.perf_counter() - started
        with start(db, port=0) as browser:
            result = {"sessions": args.sessions, "build_s": round(built, 1),
                      "index": timed(browser.url, args.repeat),
                      "session_page": timed(browser.url + "session-1.html", args.repeat),
                      "progress_json": timed(browser.url + "api/session-1.json", args.repeat)}
            chromium = shutil.which("chromium")
            if args.chromium and chromium:
                started = time.perf_counter()
                subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--dump-dom",
                                f"--user-data-dir={tmp}/profile", browser.url], capture_output=True, timeout=120,
                               check=True)
                result["chromium_index_s"] = round(time.perf_counter() - started, 2)
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
