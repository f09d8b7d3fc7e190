"""The flight-controller plant rehearsed against the real firmware in real time.

Each trial runs a :class:`~aerobat.plants.fc.world.RealTimeWorld` (the SITL and the physics, paced to
the wall clock, in a process of their own), MSP and sticks over a serial device
(:class:`~aerobat.plants.fc.PtyBridge`) and motion capture over UDP at 200 Hz with latency. Every
safety trigger is pulled during a real flight, and the vehicle must end disarmed (the firmware's
motors stopped when its world stopped), by the plant's disarm or by the firmware's own failsafe.
The drills fly the firmware at 2 kHz to spare the machine; the full trial at 8 kHz.
"""

from __future__ import annotations

import _thread
import dataclasses
import math
import os
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

pytest.importorskip("serial", reason="pyserial is not installed (pip install 'aerobat[fc]')")

from aerobat.core.design import design  # noqa: E402
from aerobat.core.plant import TrialStatus  # noqa: E402
from aerobat.plants.betaflight.params import BetaflightParams, Firmware, Radio  # noqa: E402
from aerobat.plants.fc.plant import FlightControllerPlant, RehearsalConnection  # noqa: E402
from aerobat.plants.fc.settings import fc_params  # noqa: E402
from aerobat.plants.fc.wall_clock import WallClockFlight  # noqa: E402
from aerobat.quadrotor.maneuvers import MultiFlip  # noqa: E402
from aerobat.quadrotor.simulate import NominalModel  # noqa: E402
from aerobat.quadrotor.vehicle import fpv5  # noqa: E402

FPV = fpv5()
FLIP = MultiFlip(vehicle=FPV.vehicle, flips=1, max_rate_rad_s=math.radians(800.0), dims=2)
P0 = design(FLIP, NominalModel(FPV)).p_nominal
DRILL = fc_params(firmware=Firmware(gyro_rate_hz=2000), radio=Radio(rate_hz=100.0))


def _plant(firmware: tuple[Path, Path], params: BetaflightParams = DRILL) -> tuple[FlightControllerPlant,
                                                                                  RehearsalConnection]:
    connection = RehearsalConnection({})
    return FlightControllerPlant(FPV, connection, params, seed=1, binary=firmware[0]), connection


def _when_airborne(plant: FlightControllerPlant, action: Callable[[], None], after_s: float = 0.3) -> threading.Thread:
    """Run ``action`` once the vehicle has left the floor (and ``after_s`` more), from another thread."""

    def watch() -> None:
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline:
            flight = plant.flight
            if isinstance(flight, WallClockFlight) and flight.log_count and not flight.on_floor:
                time.sleep(after_s)
                action()
                return
            time.sleep(0.01)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    return thread


def _ended_disarmed(trial) -> None:  # noqa: ANN001
    world = trial.info["world"]
    assert max(world["motors"]) == 0.0, f"the firmware's motors still ran when its world stopped: {world['motors']}"


def _no_process_left(connection: RehearsalConnection) -> None:
    assert connection.current is None and connection.reports, "the trial's world was not stopped"
    for report in connection.reports:
        assert report.firmware_pid is not None and not _running(report.firmware_pid), "a firmware outlived its world"


def _running(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_a_trial_flies_in_real_time_over_the_serial_path_and_reports_its_timing(firmware: tuple[Path, Path]) -> None:
    plant, connection = _plant(firmware, fc_params(radio=Radio(rate_hz=100.0)))  # 8 kHz, as in lockstep
    trial = plant.fly(FLIP.program(P0))
    assert trial.status is TrialStatus.OK, trial.message
    info = trial.info
    assert info["landed"] and info["disarmed"]
    _ended_disarmed(trial)
    assert info["world"]["gyro_rate_hz"] == 8000 and info["world"]["error"] == ""
    # the world kept to the wall clock: its simulated time is its wall time (it never skips, it lags)
    assert info["world"]["simulated_s"] == pytest.approx(info["world"]["wall_s"], abs=0.5)
    frames = info["maneuver_frames"]
    assert frames["frames"] >= 0.9 * FLIP.program(P0).compile().duration_s * 100.0  # 100 Hz, from its start
    assert frames["lateness_median_ms"] < 5.0
    assert math.isfinite(trial.final_state[0]) and trial.times_s.size > 0
    _no_process_left(connection)


def test_the_operators_kill_disarms_in_flight(firmware: tuple[Path, Path]) -> None:
    plant, connection = _plant(firmware)
    _when_airborne(plant, plant.kill)
    trial = plant.fly(FLIP.program(P0))
    assert trial.status is TrialStatus.ABORTED and trial.info["safety_stop"] == "kill", trial.message
    _ended_disarmed(trial)


def test_ctrl_c_in_flight_disarms_before_it_stops_the_program(firmware: tuple[Path, Path]) -> None:
    plant, connection = _plant(firmware)
    _when_airborne(plant, _thread.interrupt_main)  # what Ctrl-C does to the main thread
    with pytest.raises(KeyboardInterrupt):
        plant.fly(FLIP.program(P0))
    assert connection.reports and connection.reports[-1].disarmed, connection.reports
    _no_process_left(connection)


def test_leaving_the_geofence_disarms(firmware: tuple[Path, Path]) -> None:
    plant, _ = _plant(firmware)
    floor = plant.params.volume.z_m[0]
    plant.safety = dataclasses.replace(plant.safety, fence_z_m=(floor - 0.1, floor + 1.0))  # the take-off crosses it
    trial = plant.fly(FLIP.program(P0))
    assert trial.status is TrialStatus.CRASHED and trial.info["safety_stop"] == "geofence", trial.message
    _ended_disarmed(trial)


def test_a_motion_capture_dropout_disarms(firmware: tuple[Path, Path]) -> None:
    plant, connection = _plant(firmware)
    _when_airborne(plant, lambda: connection.current.poses.blind(2.0))  # type: ignore[union-attr]
    trial = plant.fly(FLIP.program(P0))
    assert trial.status is TrialStatus.ABORTED and trial.info["safety_stop"] == "mocap_lost", trial.message
    _ended_disarmed(trial)


def test_a_link_loss_leaves_the_vehicle_to_the_firmwares_failsafe_which_disarms_it(
        firmware: tuple[Path, Path]) -> None:
    plant, connection = _plant(firmware)
    _when_airborne(plant, lambda: connection.current.bridge.close())  # type: ignore[union-attr]
    trial = plant.fly(FLIP.program(P0))
    assert trial.status is TrialStatus.ABORTED and trial.info["safety_stop"] == "link_lost", trial.message
    _ended_disarmed(trial)  # nobody disarmed it over the link: Betaflight's RX-loss failsafe (DROP) did
    _no_process_left(connection)


def test_a_firmware_killed_in_flight_is_a_lost_trial_and_the_next_trial_flies_a_new_one(
        firmware: tuple[Path, Path]) -> None:
    plant, connection = _plant(firmware)
    _when_airborne(plant, lambda: os.kill(connection.current.world.firmware_pid, signal.SIGKILL))  # type: ignore[union-attr]
    lost = plant.fly(FLIP.program(P0))
    assert lost.status is TrialStatus.LOST and "firmware lost" in lost.message, lost.message
    _when_airborne(plant, plant.kill)  # the next trial: a fresh world takes off (then the drill ends it)
    after = plant.fly(FLIP.program(P0))
    assert after.info.get("airborne_at_s") is not None or after.info["safety_stop"] == "kill", after.message
    assert after.status is TrialStatus.ABORTED and after.info["world"]["error"] == ""
    _ended_disarmed(after)
    _no_process_left(connection)


def test_a_dry_run_with_the_firmware_never_spins_a_motor(firmware: tuple[Path, Path]) -> None:
    connection = RehearsalConnection({})
    plant = FlightControllerPlant(FPV, connection, DRILL, seed=1, binary=firmware[0], dry_run=True)
    trial = plant.fly(FLIP.program(P0))
    assert trial.status is TrialStatus.ABORTED and trial.message.startswith("dry run: pre-flight passed"), trial.message
    assert trial.info["world"]["peak_motor"] == 0.0  # not one motor command above zero, the whole run
    assert trial.info["dry_run"]["frames"] >= 0.9 * FLIP.program(P0).compile().duration_s * 100.0
    _no_process_left(connection)
