"""No process aerobat starts outlives its owner (issue 31, P1 and P2).

Each test runs a real ``aerobat study`` (or a pool) and waits on conditions (an output line,
a process appearing or vanishing) with a deadline; it never sleeps on a guess. Every process a
test sees is killed at its end, whatever happened.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from aerobat.store import Store

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="POSIX signals and /proc")

SRC = Path(__file__).resolve().parents[2] / "src"
PROGRESS = re.compile(r"^\s+\[(\d+)/(\d+)\] ")
# 2 × 20 envelope designs (a few tenths of a second each): the study runs for seconds after its first result
ENVELOPE = ["study", "envelope", "--flips", "1,2", "--rates-deg-s", "600:2000:20", "--workers", "2"]
ROBUSTNESS = ["study", "robustness", "flip", "--dims", "2", "--flips", "1", "--max-rate-deg-s", "800",
              "--vehicles", "16", "--trials", "3", "--workers", "2"]


def identity(pid: int) -> tuple[int, str] | None:
    """(pid, start time) of a live process, robust to pid reuse; None if it is gone or a zombie."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return None if fields[0] in ("Z", "X") else (pid, fields[19])


def descendants(pid: int) -> set[tuple[int, str]]:
    """Every live process below ``pid``, by identity."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(entry.name))
    found: set[tuple[int, str]] = set()
    todo = list(children.get(pid, []))
    while todo:
        child = todo.pop()
        ident = identity(child)
        if ident is not None:
            found.add(ident)
        todo += children.get(child, [])
    return found


def alive(processes: set[tuple[int, str]]) -> set[tuple[int, str]]:
    return {p for p in processes if identity(p[0]) == p}


def wait_until(predicate: Callable[[], object], timeout: float, step: float = 0.05) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return bool(predicate())
        time.sleep(step)
    return True


class Command:
    """An ``aerobat`` process whose output lines are collected as they arrive."""

    def __init__(self, argv: list[str], cwd: Path) -> None:
        env = {**os.environ, "PYTHONUNBUFFERED": "1",
               "PYTHONPATH": os.pathsep.join([str(SRC), *filter(None, [os.environ.get("PYTHONPATH")])])}
        self.proc = subprocess.Popen([sys.executable, "-m", "aerobat.cli", *argv], cwd=cwd, env=env, text=True,
                                     stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        self.out: list[str] = []
        self.err: list[str] = []
        self.changed = threading.Condition()
        self.readers = [threading.Thread(target=self._read, args=(stream, sink), daemon=True)
                        for stream, sink in ((self.proc.stdout, self.out), (self.proc.stderr, self.err))]
        for reader in self.readers:
            reader.start()
        self.seen: set[tuple[int, str]] = set()  # every descendant noticed: the test kills them at its end

    def _read(self, stream, sink: list[str]) -> None:
        for line in stream:
            with self.changed:
                sink.append(line)
                self.changed.notify_all()

    def progress(self) -> int:
        """The last job a progress line reported done (progress is on standard error, docs/cli.md)."""
        with self.changed:
            return max((int(m.group(1)) for m in map(PROGRESS.match, self.err) if m), default=0)

    def wait_for(self, predicate: Callable[[], object], timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        with self.changed:
            while not predicate():
                left = deadline - time.monotonic()
                if left <= 0 or self.proc.poll() is not None:
                    return bool(predicate())
                self.changed.wait(min(left, 0.05))
        return True

    def workers(self) -> set[tuple[int, str]]:
        """Its descendants, once its 2 pool workers and the resource tracker run (within 60 s)."""

        def started() -> bool:
            self.seen |= descendants(self.proc.pid)
            names = [_cmdline(pid) for pid, _ in alive(self.seen)]
            return sum("spawn_main" in n for n in names) >= 2 and any("resource_tracker" in n for n in names)

        assert wait_until(started, 60), f"workers never started: {[_cmdline(p) for p, _ in self.seen]}"
        return alive(self.seen)

    def streams_closed(self, timeout: float) -> bool:
        """True once both pipes reached end of file: no process holds them any more."""
        for reader in self.readers:
            reader.join(timeout)
        return not any(reader.is_alive() for reader in self.readers)

    def cleanup(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.seen |= descendants(self.proc.pid)
        for pid, _ in alive(self.seen):
            os.kill(pid, signal.SIGKILL)
        for stream in (self.proc.stdout, self.proc.stderr):
            stream.close()


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


@pytest.fixture
def commands() -> Iterator[list[Command]]:
    started: list[Command] = []
    yield started
    for command in started:
        command.cleanup()


def start(commands: list[Command], argv: list[str], cwd: Path) -> Command:
    command = Command(argv, cwd)
    commands.append(command)
    return command


def test_sigkill_of_a_study_leaves_no_worker_and_no_resource_tracker(tmp_path, commands):
    """P1: the workers and the resource tracker used to wait forever, holding the caller's pipe."""
    run = start(commands, [*ENVELOPE, "--db", str(tmp_path / "s.sqlite"), "--out", str(tmp_path / "o")], tmp_path)
    assert run.wait_for(lambda: run.progress() >= 1, 120), "".join(run.err)
    children = run.workers()
    assert len(children) >= 3
    run.proc.send_signal(signal.SIGKILL)
    assert run.proc.wait(10) == -signal.SIGKILL
    assert wait_until(lambda: not alive(children), 20), \
        f"still alive 20 s after the owner's SIGKILL: {[_cmdline(p) for p, _ in alive(children)]}"
    assert run.streams_closed(10), "a process still holds the study's standard output"


@pytest.mark.parametrize("argv", [ENVELOPE, ROBUSTNESS], ids=["envelope", "robustness"])
def test_sigterm_of_a_study_ends_it_cleanly_and_it_resumes(tmp_path, commands, argv):
    """P2: SIGTERM ends the study like Ctrl-C: one line, status 143, no worker left, the pipe released."""
    db, out = tmp_path / "s.sqlite", tmp_path / "o"
    run = start(commands, [*argv, "--db", str(db), "--out", str(out)], tmp_path)
    assert run.wait_for(lambda: run.progress() >= 1, 300), "".join(run.err)
    children = run.workers()
    run.proc.send_signal(signal.SIGTERM)
    assert run.proc.wait(30) == 128 + signal.SIGTERM, "".join(run.err)
    assert wait_until(lambda: not alive(children), 20), [_cmdline(p) for p, _ in alive(children)]
    assert run.streams_closed(10), "a worker still holds the study's standard output"
    err = "".join(run.err)
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.startswith("aerobat:")]
    with Store(db) as store:
        done = len(store.finished_study_jobs(1))
    total = int(PROGRESS.match(next(line for line in run.err if PROGRESS.match(line))).group(2))
    assert 1 <= run.progress() <= done < total, "the study was not interrupted, or lost a reported job"
    assert lines == [f"aerobat: interrupted by SIGTERM: study 1 stopped with {done} of {total} jobs stored; "
                     f"resume with: aerobat {' '.join(argv)} --db {db} --out {out} --resume 1"], err
    again = start(commands, [*argv, "--db", str(db), "--out", str(out), "--resume", "1"], tmp_path)
    assert again.proc.wait(600) == 0, "".join(again.err)
    assert again.streams_closed(10)
    assert again.out[0].startswith(f"study 1 ({argv[1]}): {total - done} jobs to run, {done} already done")
    with Store(db) as store:
        assert len(store.finished_study_jobs(1)) == total


def test_an_abandoned_local_run_ends_its_workers_at_once():
    """A run left before its last result (an interrupt, a failed commit) does not wait for the jobs in flight."""
    from aerobat.experiments.execution import LocalExecutor
    from aerobat.experiments.studies import envelope_jobs
    from aerobat.quadrotor.maneuvers import MultiFlip
    from aerobat.quadrotor.vehicle import hummingbird

    config = hummingbird()
    jobs = envelope_jobs(MultiFlip(vehicle=config.vehicle, dims=2).spec(), config, [1, 2], range(600, 2000, 70))
    pool = LocalExecutor(2)
    try:
        results = pool.run(jobs)
        next(results)
        children = descendants(os.getpid())
        workers = {p for p in children if "spawn_main" in _cmdline(p[0])}
        assert len(workers) == 2
        started = time.monotonic()
        results.close()  # what a KeyboardInterrupt in the consumer does
        assert not alive(workers), "the workers outlived the abandoned run"
        assert time.monotonic() - started < 10
        again = dict(pool.run(jobs[:2]))  # a new pool the next time
        assert len(again) == 2
    finally:
        pool.close()
        for pid, _ in alive(descendants(os.getpid())):
            if "spawn_main" in _cmdline(pid):
                os.kill(pid, signal.SIGKILL)


def test_sigkill_of_a_betaflight_study_leaves_no_firmware(tmp_path, commands):
    """Each worker's SITL firmware dies with its worker, which dies with the study (PR_SET_PDEATHSIG chain)."""
    from aerobat.firmware.betaflight.build import BINARY_NAME, ensure_sitl
    from aerobat.firmware.betaflight.errors import FirmwareUnavailable

    try:
        ensure_sitl()
    except FirmwareUnavailable as error:
        pytest.skip(f"Betaflight SITL unavailable: {error}")

    def firmware(processes: set[tuple[int, str]]) -> set[tuple[int, str]]:
        found = set()
        for pid, start in processes:
            try:
                if Path(os.readlink(f"/proc/{pid}/exe")).name == BINARY_NAME:
                    found.add((pid, start))
            except OSError:
                continue
        return found

    run = start(commands, ["study", "rules", "flip", "--flips", "1", "--max-rate-deg-s", "800", "--dims", "2",
                           "--vehicle", "fpv5", "--plant", "betaflight", "--methods", "paper", "--seeds", "4",
                           "--trials", "30", "--workers", "2", "--db", str(tmp_path / "s.sqlite"),
                           "--out", str(tmp_path / "o")], tmp_path)
    assert run.wait_for(lambda: any("jobs to run" in line for line in run.out), 120), "".join(run.err)

    def flying() -> bool:
        run.seen |= descendants(run.proc.pid)
        return len(firmware(alive(run.seen))) >= 2

    assert wait_until(flying, 120), f"no two firmware processes: {[_cmdline(p) for p, _ in run.seen]}"
    assert run.proc.poll() is None
    children = alive(run.seen)
    run.proc.send_signal(signal.SIGKILL)
    assert run.proc.wait(10) == -signal.SIGKILL
    assert wait_until(lambda: not alive(children), 20), [_cmdline(p) for p, _ in alive(children)]
    assert run.streams_closed(10)


def test_a_firmware_build_tool_stops_when_its_owner_is_killed(tmp_path):
    """``make`` (pip, patch) of a Betaflight build whose owner got SIGKILL used to run on, unowned."""
    marker = tmp_path / "tool-started"
    owner = (f"from pathlib import Path\n"
             f"from aerobat.firmware.betaflight.build import _run_logged\n"
             f"_run_logged(['sh', '-c', 'touch {marker}; exec sleep 300'], Path({str(tmp_path)!r}), "
             f"Path({str(tmp_path / 'build.log')!r}), 'a build step')\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(SRC), *filter(None, [os.environ.get("PYTHONPATH")])])}
    proc = subprocess.Popen([sys.executable, "-c", owner], env=env)
    seen: set[tuple[int, str]] = set()
    try:
        assert wait_until(marker.exists, 60)
        seen = descendants(proc.pid)
        assert any("sleep" in _cmdline(pid) for pid, _ in seen)
        proc.kill()
        assert proc.wait(10) == -signal.SIGKILL
        assert wait_until(lambda: not alive(seen), 10), [_cmdline(p) for p, _ in alive(seen)]
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for pid, _ in alive(seen):
            os.kill(pid, signal.SIGKILL)


def test_sigterm_inside_an_ipopt_solve_stops_after_it():
    """CasADi swallows the KeyboardInterrupt a signal handler raises inside IPOPT; SIGTERM's Stopped comes back out."""
    from aerobat.cli.stopping import Stopped, sigterm_stops
    from aerobat.quadrotor.timeoptimal.transcription import run_solver

    def solver(**inputs):
        try:  # what CasADi does with the exception of a signal handler
            signal.raise_signal(signal.SIGTERM)
        except KeyboardInterrupt:
            pass
        return "solved"

    before = signal.getsignal(signal.SIGTERM)
    with sigterm_stops():
        with pytest.raises(Stopped) as info:
            run_solver(solver)
    assert info.value.signum == signal.SIGTERM
    assert signal.getsignal(signal.SIGTERM) is before


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_while_a_dask_run_waits_is_raised_between_waits(signum):
    """As for the local pool: SIGINT and SIGTERM inside distributed's waiting could land inside its locks."""
    distributed = pytest.importorskip("distributed")
    from aerobat.cli.stopping import sigterm_stops
    from aerobat.experiments.execution import DaskExecutor
    from aerobat.experiments.job import Job

    seen = []
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) \
            as cluster, distributed.Client(cluster) as client, sigterm_stops():
        before = signal.getsignal(signum)
        with pytest.raises(KeyboardInterrupt):
            for _job, _result in DaskExecutor(client=client).run([Job(f"k{i}", "no-such-kind", {}) for i in range(4)]):
                seen.append(signal.getsignal(signum))
                signal.raise_signal(signum)
        assert signal.getsignal(signum) is before
    assert len(seen) == 1 and seen[0] is not before
