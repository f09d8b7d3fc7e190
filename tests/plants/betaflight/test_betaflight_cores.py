"""A core each for the driver and the firmware while they spin (issue 46): claimed, exclusive, given back."""

from __future__ import annotations

import os
import subprocess
import sys
import threading

import pytest

from aerobat.plants.betaflight import cores
from aerobat.plants.betaflight.cores import claim_core_pair

needs_two = pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs two cores")


@pytest.fixture
def private_locks(tmp_path, monkeypatch):
    monkeypatch.setattr(cores, "default_cache_dir", lambda: tmp_path)


@pytest.fixture
def child():
    process = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    yield process
    process.kill()
    process.wait()


def _in_thread(fn):
    """Run ``fn`` in a fresh thread (its cores are its own) and return what it returns."""
    out = {}
    thread = threading.Thread(target=lambda: out.setdefault("r", fn()))
    thread.start()
    thread.join()
    return out["r"]


@needs_two
@pytest.mark.usefixtures("private_locks")
def test_a_pair_pins_the_thread_and_the_firmware_apart_and_gives_the_cores_back(child):
    def fly():
        before = os.sched_getaffinity(0)
        pair = claim_core_pair(child.pid)
        assert pair is not None and pair.driver != pair.firmware
        during = (os.sched_getaffinity(0), os.sched_getaffinity(child.pid))
        pair.release()
        pair.release()  # idempotent
        return before, during, os.sched_getaffinity(0), pair

    before, (driver, firmware), after, pair = _in_thread(fly)
    assert driver == {pair.driver} and firmware == {pair.firmware}
    assert after == before


@needs_two
@pytest.mark.usefixtures("private_locks")
def test_a_taken_pair_is_not_shared(child):
    """A second instance (another process, or here another open of the lock) gets another pair or none."""
    allowed = sorted(os.sched_getaffinity(0))

    def two():
        first = claim_core_pair(child.pid)
        second = claim_core_pair(child.pid)
        pairs = (first, second)
        for pair in pairs:
            if pair is not None:
                pair.release()
        third = claim_core_pair(child.pid)  # released: free again
        third.release()
        return pairs, third

    (first, second), third = _in_thread(two)
    assert first is not None and (first.driver, first.firmware) == (allowed[0], allowed[1])
    if len(allowed) < 4:
        assert second is None  # every pair taken: nothing is pinned
    else:
        assert {second.driver, second.firmware}.isdisjoint({first.driver, first.firmware})
    assert (third.driver, third.firmware) == (first.driver, first.firmware)


@needs_two
def test_a_betaflight_flight_holds_its_pair_while_it_flies(firmware):
    from aerobat.plants.betaflight.plant import BetaflightPlant
    from aerobat.plants.fpv.params import BetaflightParams
    from aerobat.quadrotor.vehicle import fpv5

    def fly():
        before = os.sched_getaffinity(0)
        plant = BetaflightPlant(fpv5(), BetaflightParams(), seed=1)
        with plant.open_flight() as flight:
            held = flight.cores
            seen = (os.sched_getaffinity(0), os.sched_getaffinity(flight.sitl.pid)) if held is not None else None
        unpinned = BetaflightPlant(fpv5(), BetaflightParams().replace(firmware__pin_cores=False), seed=1)
        with unpinned.open_flight() as flight:
            free = flight.cores
        return before, held, seen, os.sched_getaffinity(0), free

    before, held, seen, after, free = _in_thread(fly)
    assert free is None and after == before
    if held is not None:  # another instance on this machine may hold every pair: then none is pinned
        assert seen == ({held.driver}, {held.firmware})
