"""The ground station's real-time priority in flight: taken where allowed, given back afterwards, never required."""

from __future__ import annotations

import os
import threading

import pytest

from aerobat.plants.fc.world import WORLD_FIFO_PRIORITY
from aerobat.plants.fpv.priority import GROUND_FIFO_PRIORITY, real_time_threads


def _may_set_fifo() -> bool:
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
    except PermissionError:
        return False
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    return True


def test_the_world_outranks_the_ground():
    assert 0 < GROUND_FIFO_PRIORITY < WORLD_FIFO_PRIORITY


@pytest.mark.skipif(not _may_set_fifo(), reason="SCHED_FIFO needs root or CAP_SYS_NICE here")
def test_threads_fly_real_time_and_get_their_scheduling_back():
    ready, done = threading.Event(), threading.Event()
    worker = threading.Thread(target=lambda: (ready.set(), done.wait(10)), daemon=True)
    worker.start()
    ready.wait(5)
    me = threading.get_native_id()
    try:
        with real_time_threads([me, worker.native_id, None]) as how:
            assert how == "fifo"
            for tid in (me, worker.native_id):
                assert os.sched_getscheduler(tid) == os.SCHED_FIFO
                assert os.sched_getparam(tid).sched_priority == GROUND_FIFO_PRIORITY
        for tid in (me, worker.native_id):
            assert os.sched_getscheduler(tid) == os.SCHED_OTHER
    finally:
        done.set()
        worker.join(5)


def test_where_priority_is_not_allowed_nothing_changes_and_the_trial_says_so(monkeypatch):
    def refused(*args, **kwargs):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refused)
    with real_time_threads([threading.get_native_id()]) as how:
        assert how == "normal"
    assert os.sched_getscheduler(0) == os.SCHED_OTHER


def test_a_failure_inside_still_gives_the_scheduling_back():
    if not _may_set_fifo():
        pytest.skip("SCHED_FIFO needs root or CAP_SYS_NICE here")
    with pytest.raises(RuntimeError), real_time_threads([threading.get_native_id()]):
        raise RuntimeError("the trial failed")
    assert os.sched_getscheduler(0) == os.SCHED_OTHER
