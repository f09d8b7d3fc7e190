"""Exact records whatever numba's cache held (issue 19, item 6).

A process that compiles the kernels and one that loads them from numba's cache must fly the
same trials bit for bit, and a session started cold, killed and resumed warm must equal an
uninterrupted one. Each run here is a real ``aerobat learn`` process with its own
``NUMBA_CACHE_DIR``: an empty folder (it compiles everything) or one a previous run filled.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from aerobat.store import Store

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="POSIX signals")

ROOT = Path(__file__).resolve().parents[2]
AEROBAT = ROOT / ".venv" / "bin" / "aerobat"
LEARN = ["learn", "flip", "--dims", "2", "--flips", "1", "--max-rate-deg-s", "800", "--plant", "arena",
         "--seed", "3"]
ITERATION = re.compile(r"^\s+(\d+)\s+(ok|rejected|no_trigger|crashed|aborted)\b")
TRIALS = 6


def _command(*args: str) -> list[str]:
    return [str(AEROBAT), *args] if AEROBAT.exists() else [sys.executable, "-m", "aerobat.cli", *args]


def _env(cache: Path) -> dict[str, str]:
    return {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONUNBUFFERED": "1"}


def _run(cache: Path, db: Path, *args: str) -> None:
    out = [] if "--resume" in args else ["--out", str(db.with_suffix(""))]  # a resumed session writes where it wrote
    done = subprocess.run(_command(*args, "--db", str(db), *out), env=_env(cache), capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]


def _records(db: Path) -> list[tuple]:
    with Store(db) as store:
        assert store.session(1).n_measured == TRIALS
        return [(it.index, it.status, it.params, it.error, it.next_params) for it in store.iterations(1)]


def _same(a: list[tuple], b: list[tuple]) -> None:
    assert len(a) == len(b) >= TRIALS
    for x, y in zip(a, b, strict=True):
        assert x[:2] == y[:2]
        for u, v in zip(x[2:], y[2:], strict=True):
            assert np.array_equal(u, v, equal_nan=True), (x[0], u - v)


@pytest.mark.slow  # a cold compile in a fresh cache (~150 s on 2 busy cores): make test-slow
def test_compiled_and_cached_kernels_give_the_same_records_and_a_cold_killed_warm_resumed_session_too(tmp_path):
    cold, other = tmp_path / "cache-a", tmp_path / "cache-b"
    cold.mkdir()
    other.mkdir()
    # 1. compiles everything (empty cache), 2. loads it all from the cache the first one filled
    _run(cold, tmp_path / "cold.sqlite", *LEARN, "--trials", str(TRIALS))
    assert any(cold.rglob("*.nbi")), "numba wrote no cache: the test would compare two compiling runs"
    _run(cold, tmp_path / "warm.sqlite", *LEARN, "--trials", str(TRIALS))
    reference = _records(tmp_path / "cold.sqlite")
    _same(_records(tmp_path / "warm.sqlite"), reference)

    # 3. cold (another empty cache), killed after its third stored trial, resumed warm
    killed = tmp_path / "killed.sqlite"
    proc = subprocess.Popen(_command(*LEARN, "--trials", str(TRIALS), "--db", str(killed), "--out",
                                     str(tmp_path / "killed")), env=_env(other), stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    try:
        deadline = time.monotonic() + 900
        assert proc.stdout is not None
        for line in proc.stdout:  # each line is printed after its trial was committed
            match = ITERATION.match(line)
            if match and int(match.group(1)) >= 3:
                proc.send_signal(signal.SIGKILL)
                break
            assert time.monotonic() < deadline, "no third trial within 15 minutes"
    finally:
        proc.kill()
        proc.wait(timeout=60)
    with Store(killed) as store:
        assert 3 <= store.session(1).n_measured < TRIALS
    _run(cold, killed, "learn", "--resume", "1")
    _same(_records(killed), reference)


@pytest.mark.slow  # ~45 s; every `make` target runs the warm-up itself on a fresh checkout
def test_the_warm_up_fills_the_cache_in_two_processes_and_then_loads_it(tmp_path):
    """``make setup``'s warm-up: two processes compile into an empty cache, then one loads it all."""
    cache = tmp_path / "cache"
    env = _env(cache)
    cold = subprocess.run([sys.executable, "-m", "aerobat.experiments.warmup"], env=env, capture_output=True,
                          text=True, timeout=600)
    assert cold.returncode == 0 and "compiled kernels ready" in cold.stdout, cold.stderr
    for part in ("playback", "arena", "plants", "firmware"):  # issue 44: setup says what is ready, never silent
        assert f"  {part} kernels ready (" in cold.stdout, cold.stdout
    written = {path: path.stat().st_mtime_ns for path in cache.rglob("*.nb[ci]")}
    assert len(written) >= 20  # both processes' kernels are there (index and data of each)
    again = subprocess.run([sys.executable, "-c", "from aerobat.experiments.warmup import warm_up; warm_up(workers=1)"],
                           env=env, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr
    assert {path: path.stat().st_mtime_ns for path in cache.rglob("*.nb[ci]")} == written  # loaded, none compiled
