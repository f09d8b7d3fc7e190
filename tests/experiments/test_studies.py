"""Studies on the execution layer (issue 9): local pool vs Dask, store streaming, resume."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from aerobat import hummingbird
from aerobat.cli import main
from aerobat.core.design import design
from aerobat.errors import ConfigError
from aerobat.experiments.execution import DaskExecutor, LocalExecutor
from aerobat.experiments.job import Job, run_job
from aerobat.experiments.studies import RobustnessRanges, robustness_jobs, summarize_robustness
from aerobat.plants.arena.sampling import sample_arena
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import NominalModel
from aerobat.store import Store

CONFIG = hummingbird()
FLIP = MultiFlip(vehicle=CONFIG.vehicle, flips=1, max_rate_rad_s=np.radians(800), dims=2)


@pytest.fixture(scope="module")
def jobs():
    d = design(FLIP, NominalModel(CONFIG))
    return robustness_jobs(FLIP, d, CONFIG, vehicles=4, iterations=5, seed=3)


def test_sampling_is_reproducible_and_varied():
    a, pa = sample_arena(RobustnessRanges(), 11)
    b, pb = sample_arena(RobustnessRanges(), 11)
    c, pc = sample_arena(RobustnessRanges(), 12)
    assert a == b and pa == pb
    assert pa != pc
    lo, hi = RobustnessRanges().mass_scale
    assert lo <= pa["mass_scale"] <= hi


def test_jobs_are_pure(jobs):
    first, again = run_job(jobs[0]), run_job(jobs[0])
    assert first.done and again.done
    assert first.result["position_errors_m"] == again.result["position_errors_m"]
    assert first.result["final_params"] == again.result["final_params"]
    unknown = run_job(Job("x", "no-such-kind", {}))
    assert not unknown.done and "unknown job kind" in unknown.error
    broken = run_job(Job("y", "learn", {"maneuver": {"kind": "flip"}}))  # a job that raises is a failed result
    assert not broken.done and broken.error and broken.result == {}


def test_local_pool_equals_dask_scheduler(jobs):
    distributed = pytest.importorskip("distributed")
    pool = LocalExecutor(2)
    try:
        local = {job.key: outcome.result for job, outcome in pool.run(jobs)}
    finally:
        pool.close()
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        remote = {job.key: outcome.result for job, outcome in DaskExecutor(client=client).run(jobs)}
        address = cluster.scheduler_address
        assert address.startswith("tcp://127.0.0.1")
    assert set(local) == set(remote) == {job.key for job in jobs}
    for key in local:
        assert local[key]["position_errors_m"] == remote[key]["position_errors_m"]
        assert local[key]["final_params"] == remote[key]["final_params"]
    summary = summarize_robustness(list(local.values()))
    assert summary.vehicles == 4 and summary.completed == 4


def test_cli_study_through_a_scheduler_address(tmp_path, capsys):
    distributed = pytest.importorskip("distributed")
    db = tmp_path / "s.sqlite"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        code = main(["study", "robustness", "flip", "--flips", "1", "--max-rate-deg-s", "800", "--dims", "2",
                     "--vehicles", "3", "--iterations", "4", "--seed", "5", "--db", str(db),
                     "--scheduler", cluster.scheduler_address, "--out", str(tmp_path / "out"), "--json"])
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    assert report["vehicles"] == 3 and report["ran"] == 3 and report["failed_jobs"] == []
    with Store(db) as store:
        results = store.study_results(report["study"])
        sessions = store.study_sessions(report["study"])  # every vehicle's learning run is a session
        assert len(sessions) == 3 and all(s.n_measured == 4 for s in sessions)
    assert len(results) == 3
    assert (tmp_path / "out" / "trials_to_tolerance.png").exists()
    assert (tmp_path / "out" / "success_vs_property.png").exists()


def test_killed_study_resumes_only_unfinished_jobs(tmp_path):
    db = tmp_path / "k.sqlite"
    exe = Path(sys.executable).with_name("aerobat")
    argv = [str(exe), "study", "robustness", "flip", "--flips", "1", "--max-rate-deg-s", "800", "--dims", "2",
            "--vehicles", "40", "--iterations", "6", "--seed", "2", "--workers", "1", "--db", str(db),
            "--out", str(tmp_path / "out")]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=dict(os.environ))
    finished = 0
    deadline = time.time() + 120
    while time.time() < deadline and finished < 3:
        time.sleep(0.02)
        if db.exists():
            try:
                with Store(db) as store:
                    finished = len(store.finished_study_jobs(1)) if store.list_studies() else 0
            except Exception:  # noqa: BLE001 - the file may be mid-creation
                finished = 0
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    with Store(db) as store:
        done_before = store.finished_study_jobs(1)
    assert 3 <= len(done_before) < 40
    out = subprocess.run([*argv, "--resume", "1", "--json"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert report["ran"] == 40 - len(done_before) and report["skipped"] == len(done_before)
    with Store(db) as store:
        assert len(store.study_results(1)) == 40
        assert len(store.study_sessions(1)) == 40  # a killed job left no half-stored session behind


def test_envelope_study(tmp_path, capsys):
    code = main(["study", "envelope", "--flips", "1,3", "--rates-deg-s", "800,1800", "--workers", "1",
                 "--db", str(tmp_path / "e.sqlite"), "--out", str(tmp_path / "env")])
    assert code == 0
    rows = json.loads((tmp_path / "env" / "envelope.json").read_text())
    assert len(rows) == 4
    triple = next(r for r in rows if r["flips"] == 3 and r["max_rate_deg_s"] == 1800)
    assert triple["converged"] and 1.3 < triple["duration_s"] < 1.7 and triple["apex_m"] > 0.5
    # 3 flips at 800°/s: Newton stalls from the eq 37–39 guess; from its neighbours' mean p⁰ it converges
    slow = next(r for r in rows if r["flips"] == 3 and r["max_rate_deg_s"] == 800)
    assert slow["converged"] and slow["continued_from_deg_s"] == [600, 1000] and 2.4 < slow["duration_s"] < 2.7
    assert triple["continued_from_deg_s"] == []  # converged from its own guess
    for name in ("feasible", "duration_s", "apex_m", "condition_number"):
        assert (tmp_path / "env" / f"envelope_{name}.png").exists()


def test_a_design_job_without_continuation_reports_the_guess_failure():
    """The continuation is the envelope's: a plain design job says what its guess gave."""
    import math

    from aerobat import hummingbird
    from aerobat.experiments.jobs import design_job
    from aerobat.quadrotor.maneuvers import MultiFlip
    from aerobat.quadrotor.vehicle import vehicle_table

    config = hummingbird()
    spec = {"maneuver": MultiFlip(vehicle=config.vehicle, flips=3, dims=2, max_rate_rad_s=math.radians(800)).spec(),
            "model": vehicle_table(config)}
    plain = design_job(spec)
    assert not plain["converged"] and plain["continued_from_deg_s"] == [] and "recover collective" in plain["message"]
    assert design_job({**spec, "continuation": True})["converged"]


def test_a_median_never_reached_reads_never_in_the_study_tables():
    from aerobat.cli.study import trials_text

    assert trials_text(float("inf")) == "never" and trials_text(3.0) == "3" and trials_text(2.5) == "2.5"


@pytest.mark.parametrize("address", ["1:2:3", "inproc://x", "tls://127.0.0.1:1", "tcp://127.0.0.1:1"])
def test_a_refused_scheduler_leaves_no_client_for_the_garbage_collector(address):
    """A Client that failed to connect was left in a reference cycle; collected later inside the next
    Client's loop thread, its __del__ took distributed's loop-runner lock and deadlocked that Client
    (tests/cli/test_cli_fuzz.py hung 20 min on a fresh clone). The executor collects it at once."""
    import gc

    distributed = pytest.importorskip("distributed")
    from aerobat.errors import ConfigError
    from aerobat.experiments.execution import DaskExecutor

    gc.collect()
    gc.disable()  # only what DaskExecutor itself collects may go
    try:
        with pytest.raises(ConfigError):
            DaskExecutor(address)
        alive = [o for o in gc.get_objects() if isinstance(o, distributed.Client)]
    finally:
        gc.enable()
    assert not alive


def test_a_study_runs_as_many_jobs_at_once_as_its_plant_leaves_cores(jobs, tmp_path, monkeypatch):
    """Without ``workers``: the cores ÷ the cores one job's plant keeps busy (a spinning Betaflight keeps two)."""
    from aerobat.experiments.execution import default_workers
    from aerobat.experiments.studies import runner
    from aerobat.plants import PlantChoice
    from aerobat.plants.fpv.params import BetaflightParams

    monkeypatch.setattr(os, "cpu_count", lambda: 8)
    assert default_workers() == 8 and default_workers(2) == 4 and default_workers(16) == 1
    for bad in (0, -1, True, 1.5):
        with pytest.raises(ConfigError, match=r"^cores_per_job = .*: allowed integers ≥ 1$"):
            default_workers(bad)
    spun = PlantChoice("betaflight")  # shared memory, spin ≤ 20 µs: the defaults
    assert spun.cores() == 2 and PlantChoice("arena").cores() == 1
    assert PlantChoice("betaflight", BetaflightParams().replace(firmware__spin_us=0.0)).cores() == 1
    assert PlantChoice("betaflight", BetaflightParams().replace(firmware__exchange="udp")).cores() == 1
    flown = [Job(f"b{k}", "learn", {**jobs[k].spec, "plant": PlantChoice("betaflight", seed=k).to_table()})
             for k in range(2)]
    assert runner.job_cores(jobs) == 1 and runner.job_cores([*jobs, *flown]) == 2 and runner.job_cores([]) == 1

    asked: list[int | None] = []

    class Stop(Exception):
        pass

    def make_executor(*, scheduler=None, workers=None):
        asked.append(workers)
        raise Stop

    monkeypatch.setattr(runner, "make_executor", make_executor)
    with Store(tmp_path / "s.sqlite") as store:
        for given, expected in ((None, 4), (3, 3)):
            with pytest.raises(Stop):
                runner.run_study(store, "robustness", {}, [*jobs, *flown], workers=given)
            assert asked.pop() == expected
        with pytest.raises(Stop):
            runner.run_study(store, "robustness", {}, jobs)
        assert asked.pop() == 8


def test_a_study_says_when_its_jobs_want_more_cores_than_there_are():
    from aerobat.cli.study import crowding_note

    assert crowding_note(1, 2, 2) == "" and crowding_note(2, 1, 2) == "" and crowding_note(None, 2, 2) == ""
    note = crowding_note(2, 2, 2)
    assert note.startswith("note: 2 jobs at a time, each keeping 2 cores busy") and "--workers 1 " in note
    assert "--workers 4 " in crowding_note(5, 2, 8)
