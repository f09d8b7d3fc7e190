"""The Betaflight plant with the real firmware in the loop (quick: a few seconds per trial)."""

from __future__ import annotations

import math
import threading
from pathlib import Path

import numpy as np
import pytest

from aerobat.core.design import design
from aerobat.core.plant import Trial
from aerobat.firmware.betaflight.rc import RADIO_LOST_US
from aerobat.plants.betaflight.plant import BetaflightPlant
from aerobat.plants.fpv.params import BetaflightParams
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import NominalModel
from aerobat.quadrotor.vehicle import fpv5

FPV = fpv5()
FLIP = MultiFlip(vehicle=FPV.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
P0 = design(FLIP, NominalModel(FPV)).p_nominal


def test_quick_arms_hovers_flips_in_acro_returns_and_disarms(firmware: tuple[Path, Path]) -> None:
    # the plant finds the firmware itself, through ensure_sitl (built on first use, then cached)
    plant = BetaflightPlant(FPV, BetaflightParams().replace(pilot__hover_s=2.0), seed=1)
    assert plant.binary == firmware[0]
    trial = plant.fly(FLIP.program(P0))
    assert trial.ok, trial.message
    info = trial.info
    assert info["armed_at_s"] < plant.params.pilot.calibration_s + 0.1
    hover = info["hover"]
    assert hover["seconds"] == 2.0
    assert hover["max_error_true_m"] < 0.05 and hover["max_error_measured_m"] < 0.05, hover
    # one flip in ACRO: the measured roll turned through a full turn and ended near it
    assert trial.states[:, 17].max() > 1.5 * math.pi
    assert abs(FLIP.error(trial.final_state)[4]) < math.radians(30)
    assert info["returned_error_m"] < 0.1
    assert info["landed"] and info["disarmed"]


def test_sticks_move_the_vehicle_the_way_aerobat_defines_its_rates(firmware: tuple[Path, Path]) -> None:
    """Positive roll stick: +p about body x (FLU); pitch forward: +q (nose down); yaw right: −r."""
    plant = BetaflightPlant(FPV, seed=2)
    with plant.open_flight() as flight:
        plant.pilot.power_on_and_arm(flight)
        plant.pilot.settle(flight)
        hover_us = 1250.0
        for index, (axis, sign) in enumerate(((10, +1), (11, +1), (12, -1))):
            sticks = np.zeros(4)
            sticks[index] = 0.1  # 200 deg/s
            sticks[3] = hover_us
            for _ in range(flight.frames_for(0.08)):
                flight.frame(plant.pilot.channels(sticks, arm=True, angle=False))
            rate = flight.x[axis]
            assert sign * rate > math.radians(150), (axis, math.degrees(rate))
            assert all(abs(flight.x[a]) < 0.3 * abs(rate) for a in (10, 11, 12) if a != axis)
            plant.pilot.fly_to(flight, plant.start_m, 1.5, check=True)


def test_lost_radio_makes_betaflight_fail_safe(firmware: tuple[Path, Path]) -> None:
    """Out-of-range channels (a receiver's lost link): hold 0.3 s, stage 1 (idle), then disarm."""
    plant = BetaflightPlant(FPV, seed=3)
    with plant.open_flight() as flight:
        plant.pilot.power_on_and_arm(flight)
        plant.pilot.settle(flight)
        plant.pilot.hover(flight, 1.5)  # well after boot: failsafe timing is shorter then
        lost_at = flight.time_s
        samples = []
        for _ in range(flight.frames_for(3.0)):
            flight.frame(RADIO_LOST_US, lossless=True)
            samples.append((flight.time_s - lost_at, max(flight.motor_commands()), flight.on_floor))
    times, top, floor = (np.array(column) for column in zip(*samples, strict=True))
    assert top[times < 0.25].min() > 0.15  # the last valid frame is held
    assert top[(times > 0.45) & (times < 1.2)].max() < 0.2  # stage 1: throttle low, motors near idle
    disarmed = times[top == 0.0]
    assert disarmed.size and 1.5 < disarmed[0] < 2.3  # 0.3 s hold + failsafe_delay 1.5 s
    assert floor[-1]


def test_five_percent_radio_loss_is_survived(firmware: tuple[Path, Path]) -> None:
    plant = BetaflightPlant(FPV, BetaflightParams().replace(radio__drop_probability=0.05), seed=4)
    trial = plant.fly(FLIP.program(P0))
    assert trial.ok, trial.message
    lost = trial.info["frames_dropped"] / trial.info["frames_sent"]
    assert 0.03 < lost < 0.07
    assert np.linalg.norm(FLIP.error(trial.final_state)[[0, 2]]) < 0.5


def same(a: Trial, b: Trial) -> bool:
    return (a.status == b.status and np.array_equal(a.final_state, b.final_state, equal_nan=True)
            and np.array_equal(a.states, b.states, equal_nan=True))


def test_same_seed_same_trial_and_two_plants_at_once_without_cross_talk(firmware: tuple[Path, Path]) -> None:
    program = FLIP.program(P0)
    alone = {seed: BetaflightPlant(FPV, seed=seed).fly(program) for seed in (5, 6)}
    assert not same(alone[5], alone[6])
    together: dict[int, Trial] = {}
    plants = {seed: BetaflightPlant(FPV, seed=seed) for seed in (5, 6)}
    threads = [threading.Thread(target=lambda s=seed: together.__setitem__(s, plants[s].fly(program)))
               for seed in (5, 6)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for seed in (5, 6):
        assert together[seed].ok and same(together[seed], alone[seed]), seed  # bit for bit


def test_every_step_is_one_firmware_loop(firmware: tuple[Path, Path]) -> None:
    plant = BetaflightPlant(FPV, seed=7)
    with plant.open_flight() as flight:
        plant.pilot.power_on_and_arm(flight)
        assert flight.sitl.steps == flight.tick  # one motor packet answered every state packet
        assert flight.sitl.steps == round(flight.time_s * plant.params.firmware.gyro_rate_hz)


def test_a_stored_state_repeats_the_next_trial(firmware: tuple[Path, Path]) -> None:
    plant = BetaflightPlant(FPV, seed=8)
    plant.trials_flown, plant.capacity = 4, 0.99
    saved = plant.get_state()
    first = plant.fly(FLIP.program(P0))
    again = BetaflightPlant(FPV, seed=0)
    again.set_state(saved)
    assert same(again.fly(FLIP.program(P0)), first)
    with pytest.raises(ValueError, match="format"):
        again.set_state({**saved, "format": 9})


def test_a_settle_that_times_out_says_where_the_vehicle_was(firmware: tuple[Path, Path]) -> None:
    """A second to settle is too short to take off and settle: the trial is aborted, and its message gives the
    estimate's distance, speed and tilt beside the tolerances it had to meet."""
    plant = BetaflightPlant(FPV, BetaflightParams().replace(pilot__settle_timeout_s=1.0), seed=1,
                            eeprom=firmware[1])
    trial = plant.fly(FLIP.program(P0))
    assert trial.status.value == "aborted", trial.message
    message = trial.message
    assert message.startswith("did not settle at the start within 1 s: at the end "), message
    pilot = plant.params.pilot
    tolerances = (f"(must hold {pilot.settle_position_m * 100:g} cm, {pilot.settle_velocity_m_s * 100:g} cm/s and "
                  f"{math.degrees(pilot.settle_tilt_rad):.2f}° for {pilot.settle_hold_s:g} s)")
    for part in ("cm from it (x ", "cm/s, tilted", "motion-capture samples", tolerances):
        assert part in message, message


class _ArmsOnTheSecondSwitch:
    """A flight whose firmware ignores the first ARM switch (as after a gap in the link) and arms at the second."""

    def __init__(self) -> None:
        self.time_s = 0.0
        self.runs: list[tuple[int, int, bool]] = []  # (frames, AUX1 pulse, until ARMED)

    def frames_for(self, seconds: float) -> int:
        return max(1, math.ceil(seconds * 100.0 - 1e-9))

    def run_frames(self, mode, frames, *, channels_us, until=None, **_):  # noqa: ANN001, ANN003
        from aerobat.plants.fpv.frames import FramesEnd, FramesRun, Until

        self.time_s += frames / 100.0
        self.runs.append((frames, int(channels_us[0][4]), until is Until.ARMED))
        arming = [r for r in self.runs if r[2]]
        met = until is Until.ARMED and len(arming) == 2
        return FramesRun(FramesEnd.MET if met else FramesEnd.DONE, frames)


def test_a_switch_that_did_not_arm_is_cycled_once_as_a_pilot_would(firmware: tuple[Path, Path]) -> None:
    pilot = BetaflightPlant(FPV, BetaflightParams(), seed=1, eeprom=firmware[1]).pilot
    flight = _ArmsOnTheSecondSwitch()
    pilot.power_on_and_arm(flight)
    assert pilot.arm_attempts == 2
    calibrate, arm = flight.runs[0], flight.runs[1]
    assert [r[2] for r in flight.runs] == [False, True, False, True]  # calibrate, arm, switch off, arm again
    off_run, rearm = flight.runs[2], flight.runs[3]
    assert off_run[1] == calibrate[1] != arm[1] == rearm[1]  # the switch went off, then on again
    assert off_run[0] == 30  # 0.3 s at 100 Hz
