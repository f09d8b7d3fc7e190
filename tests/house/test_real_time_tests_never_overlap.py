"""Two wall-clock flights never run at once in ``make test`` (tests/README.md, "Tests on the wall clock").

In a session of its own on two workers (as ``make test`` runs), tests marked ``xdist_group("real_time")``
must run on one worker (``--dist loadgroup``) and, through tests/real_time_lock.py, never overlap in time.
pytest 9.2 with pytest-xdist 3.8 broke the first silently (pytest-dev/pytest-xdist#1386): two rehearsals
then flew at once and one did not settle (CI, stop 52).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]

_FLIGHTS = '''
import json, os, time
from pathlib import Path
import pytest

pytestmark = pytest.mark.xdist_group("real_time")

@pytest.mark.parametrize("i", range({n}))
def test_flight(i):
    start = time.monotonic()
    time.sleep(0.3)
    Path(os.environ["FLIGHTS"], f"{{__name__}}-{{i}}.json").write_text(json.dumps(
        {{"worker": os.environ.get("PYTEST_XDIST_WORKER"), "start": start, "end": time.monotonic()}}))
'''

_OTHERS = '''
import time
import pytest

@pytest.mark.parametrize("i", range(8))
def test_other(i):
    time.sleep(0.1)
'''


def test_wall_clock_tests_run_on_one_worker_one_at_a_time(tmp_path):
    suite = tmp_path / "suite"
    suite.mkdir()
    (suite / "test_flights_a.py").write_text(_FLIGHTS.format(n=3))
    (suite / "test_flights_b.py").write_text(_FLIGHTS.format(n=3))
    (suite / "test_others.py").write_text(_OTHERS)
    (suite / "pytest.ini").write_text("[pytest]\n")
    flights = tmp_path / "flights"
    flights.mkdir()
    env = {**os.environ, "FLIGHTS": str(flights), "PYTHONPATH": str(TESTS),
           "AEROBAT_REAL_TIME_LOCK": str(tmp_path / "real_time.lock")}
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "2", "--dist", "loadgroup", "-p",
                           "real_time_lock", "-p", "no:cacheprovider", str(suite)],
                          cwd=suite, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    runs = sorted((json.loads(p.read_text()) for p in flights.glob("*.json")), key=lambda r: r["start"])
    assert len(runs) == 6
    for before, after in zip(runs, runs[1:], strict=False):
        assert after["start"] >= before["end"], f"two wall-clock tests overlapped: {before} {after}"
    # the scheduler groups them too (else one worker waits on the lock while the other flies: slower, not wrong)
    assert len({r["worker"] for r in runs}) == 1, f"--dist loadgroup split the real_time group: {runs}"
