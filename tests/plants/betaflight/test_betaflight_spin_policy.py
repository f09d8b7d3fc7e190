"""The driver's measured choice between spinning and sleeping over shared memory (issue 46).

``aerobat_shm_choose_spin`` (shm_exchange.c) is driven here with a clock of the test's own, so
the policy's decisions are checked exactly: it keeps the mode that steps faster, probes the other
ever more rarely while it loses, takes it when it steps at least 5 % faster, and ignores pauses
between compiled calls. Needs only the C compiler, not the firmware.
"""

from __future__ import annotations

import ctypes

import pytest

from aerobat.firmware.betaflight import shm
from aerobat.firmware.betaflight.errors import FirmwareUnavailable

SPIN_NS = 20_000
EPOCH_NS = 25_000_000


class Clocked:
    """A policy and a synthetic clock: each step costs what its mode costs (ns per step)."""

    def __init__(self, spin_step_ns: float, sleep_step_ns: float) -> None:
        try:
            self.lib = shm.library()
        except FirmwareUnavailable as error:
            pytest.skip(str(error))
        self.policy = ctypes.create_string_buffer(shm._POLICY_STRUCT.size)
        self.cost = {SPIN_NS: spin_step_ns, 0: sleep_step_ns}
        self.now, self.seq = 1_000_000_000, 0
        self.modes: list[int] = []

    def fly(self, steps: int) -> None:
        for _ in range(steps):
            self.seq += 1
            budget = self.lib.aerobat_shm_choose_spin(self.policy, self.seq, SPIN_NS, int(self.now))
            self.modes.append(budget)
            self.now += self.cost[budget]

    def pause(self, ns: int) -> None:
        self.now += ns

    @property
    def fields(self) -> tuple:
        return shm._POLICY_STRUCT.unpack(self.policy.raw)

    def sleeping_share(self, last: int) -> float:
        return sum(1 for m in self.modes[-last:] if m == 0) / last


def test_spinning_that_pays_is_kept_and_the_probes_of_sleeping_grow_rare():
    run = Clocked(spin_step_ns=1_500, sleep_step_ns=30_000)  # a quiet machine: spinning 20× faster
    run.fly(800_000)  # 1.2 s spinning
    fields = run.fields
    assert fields[5] == 0 and fields[13] == 0  # home: spinning; never switched
    assert fields[14] >= 3 and fields[8] >= 16  # it probed, and backs off
    assert abs(fields[9] - 1_500) < 1 and abs(fields[10] - 30_000) < 1  # both costs measured exactly
    # a probe lasts one epoch of 25 ms: ~830 sleeping steps among 16,700 per epoch, ever rarer
    assert run.sleeping_share(200_000) < 0.01


def test_sleeping_is_taken_when_it_steps_faster_and_spinning_comes_back_when_the_load_goes():
    run = Clocked(spin_step_ns=40_000, sleep_step_ns=20_000)  # loaded: spinning takes the peer's core
    run.fly(30_000)  # 1.2 s
    assert run.fields[5] == 1 and run.fields[13] == 1  # home: sleeping, after one switch
    assert run.sleeping_share(10_000) > 0.9
    run.cost = {SPIN_NS: 1_500, 0: 20_000}  # the load is gone: the next probe finds spinning faster
    run.fly(60_000)
    assert run.fields[5] == 0 and run.fields[13] == 2
    assert run.sleeping_share(20_000) < 0.05


def test_a_small_difference_does_not_switch():
    run = Clocked(spin_step_ns=10_000, sleep_step_ns=9_700)  # 3 %: within the 5 % margin
    run.fly(60_000)
    assert run.fields[5] == 0 and run.fields[13] == 0 and run.fields[14] >= 2


def test_a_pause_between_compiled_calls_is_not_charged_to_the_mode_in_force():
    run = Clocked(spin_step_ns=1_500, sleep_step_ns=1_450)  # alike; a long pause must not decide
    run.fly(EPOCH_NS // 1_500 * 4 + 10)  # up to the first probe (sleeping)
    assert run.modes[-1] == 0
    run.pause(50_000_000)  # Python's turn: 50 ms between two waits, within the probe
    run.fly(EPOCH_NS // 1_450 + 10)
    assert run.fields[5] == 0 and run.fields[13] == 0  # the probe measured its steps, not the pause
    assert abs(run.fields[10] - 1_450) < 1


def test_a_trial_with_the_measured_spin_is_the_trial_with_the_fixed_one(firmware):
    """Only the wall time depends on the driver's waits: the same seed flies the same trial bit for bit."""
    import math

    import numpy as np

    from aerobat.core.design import design
    from aerobat.plants.betaflight.plant import BetaflightPlant
    from aerobat.plants.fpv.params import BetaflightParams
    from aerobat.quadrotor.maneuvers import MultiFlip
    from aerobat.quadrotor.simulate import NominalModel
    from aerobat.quadrotor.vehicle import fpv5

    config = fpv5()
    flip = MultiFlip(vehicle=config.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
    program = flip.program(design(flip, NominalModel(config)).p_nominal)
    trials = {spin: BetaflightPlant(config, BetaflightParams().replace(firmware__spin=spin), seed=5).fly(program)
              for spin in ("always", "measured")}
    always, measured = trials["always"], trials["measured"]
    assert always.ok and measured.ok
    assert np.array_equal(always.states, measured.states, equal_nan=True)
    assert np.array_equal(always.final_state, measured.final_state, equal_nan=True)
    assert np.array_equal(always.signals.values, measured.signals.values)
    assert "driver_sleeping_share" not in always.info  # a fixed spin measures nothing
    assert 0.0 <= measured.info["driver_sleeping_share"] <= 1.0
    assert measured.info["driver_spin_switches"] >= 0 and measured.info["driver_spin_probes"] >= 0
