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
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from bf_processes import running, sitl_processes, wait_gone

pytest.importorskip("serial", reason="pyserial is not installed (pip install 'aerobat[fc]')")
pytestmark = pytest.mark.xdist_group("real_time")  # flights on the wall clock: one at a time (tests/README.md)

from aerobat.core.design import design  # noqa: E402
from aerobat.core.plant import Trial, TrialStatus  # noqa: E402
from aerobat.plants.fc.plant import FlightControllerPlant, RehearsalConnection  # noqa: E402
from aerobat.plants.fc.settings import fc_params  # noqa: E402
from aerobat.plants.fc.wall_clock import WallClockFlight  # noqa: E402
from aerobat.plants.fpv.params import BetaflightParams, Firmware, Radio  # noqa: E402
from aerobat.quadrotor.maneuvers import MultiFlip  # noqa: E402
from aerobat.quadrotor.simulate import NominalModel  # noqa: E402
from aerobat.quadrotor.vehicle import fpv5  # noqa: E402
from aerobat.store import Store  # noqa: E402

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


def _why(trial: Trial) -> str:
    """A failed trial's message with what the world and the ground measured of their timing."""
    return (f"{trial.message}; world {trial.info.get('world')}; ground {trial.info.get('ground_scheduling')}, "
            f"frames {trial.info.get('frames')}")


def _no_process_left(connection: RehearsalConnection) -> None:
    assert connection.current is None and connection.reports, "the trial's world was not stopped"
    for report in connection.reports:
        assert report.firmware_pid is not None and not running(report.firmware_pid), "a firmware outlived its world"



def test_the_world_sleeps_while_it_waits_instead_of_spinning() -> None:
    """Spinning firmware and driver under SCHED_FIFO held both cores from the ground: its link went silent."""
    from aerobat.plants.fc.world import world_params

    assert world_params(None).firmware.spin_us == 0.0 and BetaflightParams().firmware.spin_us > 0.0
    given = fc_params(radio=Radio(rate_hz=100.0))
    assert world_params(given) == given.replace(firmware__spin_us=0.0)


def test_a_trial_flies_in_real_time_over_the_serial_path_and_reports_its_timing(firmware: tuple[Path, Path]) -> None:
    plant, connection = _plant(firmware, fc_params(radio=Radio(rate_hz=100.0)))  # 8 kHz, as in lockstep
    trial = plant.fly(FLIP.program(P0))
    assert trial.status is TrialStatus.OK, _why(trial)
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


def _may_set_fifo() -> bool:
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
    except PermissionError:
        return False
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    return True


_NEEDS_FIFO = pytest.mark.skipif(not _may_set_fifo(), reason="the rehearsal holds its deadlines under load with "
                                 "real-time priority, which needs root or CAP_SYS_NICE here")


def _fly_beside_two_busy_loops(firmware: tuple[Path, Path]) -> Trial:
    """One rehearsal trial beside two busy loops; it ended disarmed and left no process behind."""
    loops = [subprocess.Popen(["sh", "-c", "while :; do :; done"], start_new_session=True) for _ in range(2)]
    try:
        plant, connection = _plant(firmware, fc_params(radio=Radio(rate_hz=100.0)))  # 8 kHz, as in lockstep
        trial = plant.fly(FLIP.program(P0))
    finally:
        for loop in loops:
            loop.kill()
            loop.wait(timeout=10)
    if trial.ok:
        _ended_disarmed(trial)
    _no_process_left(connection)
    return trial


@_NEEDS_FIFO
def test_a_trial_flies_real_time_beside_two_busy_loops(firmware: tuple[Path, Path]) -> None:
    """Issue 45 E12: on a busy machine the ground's frames and poses kept the wall clock only by luck (the
    pre-flight once measured motion capture at 20 Hz). The ground now flies real-time too, where allowed: the
    trial flies, both sides run under SCHED_FIFO, the world keeps the wall clock and the typical frame is on time.
    (How many frames may be late is a measurement of the machine: the slow suite's bar, below.)"""
    trial = _fly_beside_two_busy_loops(firmware)
    assert trial.status is TrialStatus.OK, _why(trial)
    info = trial.info
    assert info["ground_scheduling"] == "fifo" and info["world"]["scheduling"] == "fifo"
    assert info["world"]["simulated_s"] == pytest.approx(info["world"]["wall_s"], abs=0.5)
    assert info["maneuver_frames"]["lateness_median_ms"] < 1.0, info["maneuver_frames"]


@pytest.mark.slow
@_NEEDS_FIFO
def test_a_trial_keeps_its_deadlines_with_two_busy_loops_beside_it(firmware: tuple[Path, Path]) -> None:
    """The bar measured on a quiet machine (``scripts/results_fc.py lag --busy 2``): with the ground real-time,
    0-2 of a triple flip's frames at 250 Hz late per trial; without, 19-79. Here 100 Hz: late = more than 5 ms
    after the deadline. On a shared virtual machine under a test suite's load it is a measurement of the
    machine (it missed by 1-2 frames, or 0.2 % of the world's chunks, in runs of ``make test``), so it runs
    in ``make test-slow``."""
    trial = _fly_beside_two_busy_loops(firmware)
    assert trial.status is TrialStatus.OK, _why(trial)
    info = trial.info
    frames = info["maneuver_frames"]
    assert frames["late_frames"] <= 0.02 * frames["frames"], frames
    assert frames["lateness_median_ms"] < 1.0, frames
    assert info["world"]["late_chunks"] <= 0.02 * info["world"]["chunks"], info["world"]


def test_the_operators_kill_disarms_in_flight(firmware: tuple[Path, Path]) -> None:
    plant, connection = _plant(firmware)
    _when_airborne(plant, plant.kill)
    trial = plant.fly(FLIP.program(P0))
    assert trial.status is TrialStatus.ABORTED and trial.info.get("safety_stop") == "kill", \
        (trial.status, trial.info.get("safety_stop"), trial.message)
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
    assert trial.status is TrialStatus.CRASHED and trial.info.get("safety_stop") == "geofence", \
        (trial.status, trial.info.get("safety_stop"), trial.message, trial.info.get("world"))
    _ended_disarmed(trial)


def test_a_motion_capture_dropout_disarms(firmware: tuple[Path, Path]) -> None:
    plant, connection = _plant(firmware)
    _when_airborne(plant, lambda: connection.current.poses.blind(2.0))  # type: ignore[union-attr]
    trial = plant.fly(FLIP.program(P0))
    assert trial.status is TrialStatus.ABORTED and trial.info.get("safety_stop") == "mocap_lost", \
        (trial.status, trial.info.get("safety_stop"), trial.message)
    _ended_disarmed(trial)


def test_a_link_loss_leaves_the_vehicle_to_the_firmwares_failsafe_which_disarms_it(
        firmware: tuple[Path, Path]) -> None:
    plant, connection = _plant(firmware)
    _when_airborne(plant, lambda: connection.current.bridge.close())  # type: ignore[union-attr]
    trial = plant.fly(FLIP.program(P0))
    assert trial.status is TrialStatus.ABORTED and trial.info.get("safety_stop") == "link_lost", \
        (trial.status, trial.info.get("safety_stop"), trial.message)
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


def _world_processes(parent: int) -> list[int]:
    """Pids of the rehearsal's world processes started by ``parent``."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
                command = (entry / "cmdline").read_bytes().split(b"\0")
            except OSError:
                continue
            if int(fields[1]) == parent and b"aerobat.plants.betaflight.paced_world" in command:
                found.append(int(entry.name))
    return found


def _session_in_flight(tmp_path: Path) -> tuple[subprocess.Popen[str], int, int]:
    """`aerobat learn --plant fc` in a process group of its own, as a terminal starts it: (process, world, firmware)
    once the first trial's world and firmware run and the vehicle has had time to take off."""
    room = tmp_path / "drill.toml"
    room.write_text("[betaflight.firmware]\ngyro_rate_hz = 2000\n\n[betaflight.radio]\nrate_hz = 100.0\n")
    exe = Path(sys.executable).with_name("aerobat")
    command = [str(exe), "learn", "flip", "--flips", "1", "--max-rate-deg-s", "800", "--dims", "2", "--vehicle",
               "fpv5", "--plant", "fc", "--fc", str(room), "--trials", "3", "--db", str(tmp_path / "s.sqlite"),
               "--out", str(tmp_path / "out")]
    session = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                               start_new_session=True)
    deadline = time.monotonic() + 120.0
    worlds: list[int] = []
    firmwares: list[int] = []
    while not firmwares and time.monotonic() < deadline and session.poll() is None:
        worlds = _world_processes(session.pid)
        firmwares = [pid for world in worlds for pid in sitl_processes(world)]
        time.sleep(0.05)
    assert firmwares, f"the session never started a world with its firmware: {session.poll()}"
    time.sleep(8.0)  # calibration, arming and the take-off (the pilot settles for seconds after)
    return session, worlds[0], firmwares[0]


def test_no_world_or_firmware_outlives_a_killed_fc_session(firmware: tuple[Path, Path], tmp_path: Path) -> None:
    session, world, sitl = _session_in_flight(tmp_path)
    try:
        session.kill()  # SIGKILL: no cleanup code runs in the ground station
        session.wait(timeout=10)
        assert wait_gone(world, 10.0), "the world outlived its ground station"
        assert wait_gone(sitl, 10.0), "the firmware outlived its world"
    finally:
        if session.poll() is None:
            session.kill()
            session.wait()


def test_ctrl_c_at_the_terminal_is_the_kill_and_the_world_flies_on_until_the_vehicle_is_disarmed(
        firmware: tuple[Path, Path], tmp_path: Path) -> None:
    session, world, sitl = _session_in_flight(tmp_path)
    try:
        os.killpg(session.pid, signal.SIGINT)  # what Ctrl-C in the terminal sends: the whole foreground group
        _, err = session.communicate(timeout=120)
        # the kill ends the session (a real vehicle is not flown again until a person has looked), stored
        assert session.returncode == 1 and "trial 1 aborted: kill" in err and "resume with" in err, err[-2000:]
        assert wait_gone(world, 10.0) and wait_gone(sitl, 10.0)
    finally:
        if session.poll() is None:
            session.kill()
            session.wait()
    with Store(tmp_path / "s.sqlite") as store:
        info = store.iterations(1)[0].info
    # the ground disarmed the vehicle through the firmware and the firmware said so: the world had not been
    # killed by the signal (a dead world is a lost link, and a lost trial)
    assert info.get("safety_stop") == "kill" and info.get("disarm_confirmed") is True, info
    assert max(info["world"]["motors"]) == 0.0


@pytest.mark.slow
def test_the_rehearsal_learns_the_3d_triple_flip_open_loop_with_no_trial_lost(firmware: tuple[Path, Path]) -> None:
    """docs/real-vehicle.md's command, as a library call: 30 trials in real time at 8 kHz (about 9 minutes)."""
    from aerobat.core.learning import learn
    from aerobat.core.maneuver import ErrorKind

    triple = MultiFlip(vehicle=FPV.vehicle, flips=3, max_rate_rad_s=math.radians(1800.0), dims=3)
    plant = FlightControllerPlant(FPV, RehearsalConnection({}), seed=1, binary=firmware[0])
    session = learn(triple, design(triple, NominalModel(FPV)), plant, iterations=30)
    assert session.status.value == "completed" and len(session.iterations) == 30, session.message
    assert all(it.measured for it in session.iterations), [it.message for it in session.iterations]
    pos = [i for i, e in enumerate(triple.errors) if e.kind is ErrorKind.POSITION]
    position = [float(math.dist(it.error[pos], (0.0,) * len(pos))) for it in session.measured]
    assert sum(position[-10:]) / 10 <= 0.15, position
