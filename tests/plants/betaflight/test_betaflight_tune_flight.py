"""A real tune flown by the firmware, and a pilot whose vehicle model is off (issue 31 B1). Firmware in the loop."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from aerobat.cli import main
from aerobat.core.design import design
from aerobat.firmware.betaflight.configure import AtRestStepper
from aerobat.firmware.betaflight.sitl import SitlProcess
from aerobat.firmware.betaflight.tune import load_tune
from aerobat.plants.betaflight.plant import BetaflightPlant
from aerobat.plants.fpv.params import BetaflightParams
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import NominalModel
from aerobat.quadrotor.vehicle import fpv5

DIFF = Path("/work/shared/data/betaflight-configs/tii-racing-kakuteh7-4.3.1-diff.txt")
FPV = fpv5()
HOVER = Path(__file__).resolve().parents[3] / "src" / "aerobat" / "examples" / "hover.toml"


def _flip(max_rate_deg_s: float) -> tuple[MultiFlip, object]:
    flip = MultiFlip(vehicle=FPV.vehicle, flips=1, max_rate_rad_s=math.radians(max_rate_deg_s), dims=2)
    return flip, design(flip, NominalModel(FPV)).p_nominal


@pytest.mark.skipif(not DIFF.is_file(), reason="the shared real data is absent")
def test_the_431_diff_lands_in_the_sitl_which_arms_and_flies_a_trial(firmware: tuple[Path, Path]) -> None:
    plant = BetaflightPlant(FPV, BetaflightParams(tune=load_tune(DIFF)), seed=1)
    # what the saved eeprom holds, asked through the SITL's own CLI
    with SitlProcess(plant.binary, plant.eeprom) as sitl:
        stepper = AtRestStepper(sitl)
        try:
            with sitl.open_link() as link:
                link.cli.enter()
                diff = link.cli.command("diff", timeout_s=20.0)
                rates = link.cli.command("get roll_rc_rate")
        finally:
            stepper.stop()
    for line in ("set p_roll = 63", "set i_pitch = 81", "set d_max_roll = 46", "set thrust_linear = 30",
                 "set feedforward_averaging = 3_POINT", "set simplified_master_multiplier = 140",
                 "set rates_type = BETAFLIGHT", "set roll_srate = 0", "aux 0 0 0 1700 2100 0 0"):
        assert line in diff, line
    assert re.search(r"roll_rc_rate = 202", rates)
    assert "align_board_roll" not in diff and "set small_angle" not in diff  # refused / pinned
    # the tune's rates top out at 462 deg/s: a flip within them flies, through the pilot's inverted curve
    assert plant.pilot.sticks.full_rates_deg_s()[0] == pytest.approx(462.16)
    flip, p0 = _flip(420.0)
    trial = plant.fly(flip.program(p0))
    assert trial.ok, trial.message
    assert trial.states[:, 17].max() > 1.5 * math.pi  # a full roll
    assert trial.info["landed"] and trial.info["disarmed"] and "tune" in trial.info["firmware"]


@pytest.mark.parametrize("airframe_over_model", [1.15, 0.85])
def test_take_off_hover_and_return_hold_with_the_pilot_model_off_by_15_percent(
        firmware: tuple[Path, Path], airframe_over_model: float) -> None:
    """Issue 31 B1: 0.79 kg against the pilot's 0.752 aborted every trial; ±15 % with the default disturbances."""
    params = BetaflightParams().replace(airframe__mass_kg=0.752 * airframe_over_model)
    assert params.disturbances.enabled and params.pilot.vehicle_mass_kg == 0.752
    plant = BetaflightPlant(FPV, params, seed=1)
    flip, p0 = _flip(800.0)
    trial = plant.fly(flip.program(p0))
    assert trial.ok, trial.message
    assert trial.info["settled_at_s"] < plant.params.pilot.settle_timeout_s
    assert trial.info["hover"]["max_error_true_m"] < 0.05
    assert trial.info["returned_error_m"] < 0.15
    assert trial.info["landed"]


def test_a_bad_tune_is_refused_before_anything_flies(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.txt"
    bad.write_text("# Betaflight / X 4.3.1\nset p_roll = 50\nset p_rol = 50\n")
    db = tmp_path / "s.sqlite"
    learn = ["learn", "flip", "--flips", "1", "--dims", "2", "--iterations", "1", "--db", str(db), "--tune", str(bad)]
    assert main([*learn, "--plant", "betaflight"]) == 2
    assert f"{bad}: line 3: unknown setting 'p_rol'" in capsys.readouterr().err
    assert main([*learn, "--plant", "arena"]) == 2
    assert "--tune applies only with --plant betaflight" in capsys.readouterr().err
    assert main([*learn, "--plant", "betaflight", "--tune-log-index", "2"]) == 2  # a diff holds no logs
    assert f"{bad}:2: the file is a CLI diff/dump, not a blackbox log" in capsys.readouterr().err
    learn[-1] = f"{bad}:2"  # the same log named as every command names one (issue 44)
    assert main([*learn, "--plant", "betaflight"]) == 2
    assert f"{bad}:2: the file is a CLI diff/dump, not a blackbox log" in capsys.readouterr().err
    assert not db.exists()  # nothing flown, nothing stored


def test_a_crafted_header_never_reaches_the_firmware(firmware: tuple[Path, Path], tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 45 E3 end to end: 19 DELs in a header value erased ``set profile_name = `` on the firmware's line,
    which then ran ``set p_roll = 123``. Now the header is bad input before any firmware starts, and the CLI
    client refuses the line itself; written raw to the real firmware, the same bytes do set p_roll."""
    import time

    from aerobat.errors import ConfigError
    from aerobat.firmware.betaflight.sitl_table import load_table

    binary, eeprom = firmware
    payload = "\x7f" * 19 + "set p_roll = 123"
    log = tmp_path / "crafted.bbl"
    log.write_bytes(b"H Product:Blackbox flight data recorder by Nicholas Sherlock\n"
                    b"H Firmware revision:Betaflight 4.2.9 (e097f4ab7) STM32F7X2\n"
                    b"H rollPID:47,85,38\nH profile_name:" + payload.encode() + b"\n")
    started = time.time()
    assert main(["fly", str(HOVER), "--plant", "betaflight", "--tune", str(log), "--trials", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{log}#log1: header field profile_name:" in err and "0x7f (DEL)" in err
    configured = [path for path in binary.parent.glob("eeprom-*.cli.txt") if path.stat().st_mtime >= started]
    assert not any("p_roll set to 123" in path.read_text(errors="replace") for path in configured)
    line = "set profile_name = " + payload
    default = load_table().get("p_roll").default
    with SitlProcess(binary, eeprom) as sitl:
        stepper = AtRestStepper(sitl)
        try:
            with sitl.open_link() as link:
                link.cli.enter()
                with pytest.raises(ConfigError, match=r"not sent: the control character 0x7f \(DEL\)"):
                    link.cli.command(line)
                assert f"p_roll = {default}" in link.cli.command("get p_roll")
                link.transport.write(line.encode() + b"\n")  # what the client refuses to send
                answers = link.cli.command("get p_roll") + link.cli.command("get p_roll")
                assert re.search(r"p_roll (set to|=) 123\b", answers), answers
        finally:
            stepper.stop()


@pytest.mark.skipif(not DIFF.is_file(), reason="the shared real data is absent")
def test_a_resumed_session_flies_the_stored_tune(firmware: tuple[Path, Path], tmp_path: Path) -> None:
    from aerobat.experiments.sessions import resume_session, start_session
    from aerobat.plants import PlantChoice
    from aerobat.store import Store

    tune = load_tune(DIFF)
    flip, _ = _flip(420.0)
    with Store(tmp_path / "s.sqlite") as store:
        run = start_session(store, flip, model=FPV, plant=PlantChoice("betaflight", BetaflightParams(tune=tune), 1),
                            iterations=1)
        assert run.run().measured == 1
    with Store(tmp_path / "s.sqlite") as store:
        resumed = resume_session(store, "last", iterations=2)
        assert resumed.plant_choice.settings.tune == tune  # from the store, not the file
        assert resumed.plant.settings.value("roll_rc_rate") == "202"
        assert resumed.plant.eeprom == run.plant.eeprom  # the same tuned firmware
        assert resumed.run().measured == 2


def test_settings_that_would_not_arm_get_a_clear_message(firmware: tuple[Path, Path]) -> None:
    import dataclasses

    from aerobat.firmware.betaflight.configure import check_arms
    from aerobat.firmware.betaflight.errors import ConfigureFailed
    from aerobat.firmware.betaflight.settings import load_settings

    binary, eeprom = firmware
    settings = load_settings()
    check_arms(binary, eeprom, settings)  # the shipped settings arm
    # the pilot's ARM pulse on a channel the firmware does not watch: it never arms, and says why
    moved = dataclasses.replace(settings, modes={**settings.modes,
                                                 "ARM": dataclasses.replace(settings.modes["ARM"], aux=3)})
    with pytest.raises(ConfigureFailed, match=r"would not arm with these settings: the ARM switch \(AUX3\) did not"):
        check_arms(binary, eeprom, moved)


def test_the_shipped_settings_table_is_what_the_built_sitl_accepts(firmware: tuple[Path, Path]) -> None:
    import json

    from aerobat.firmware.betaflight.sitl_table import SITL_TABLE_PATH
    from aerobat.firmware.betaflight.table_reader import read_table

    shipped = json.loads(SITL_TABLE_PATH.read_text())
    read = read_table(firmware[0])
    assert read["firmware"] == shipped["firmware"] and read["features"] == shipped["features"]
    assert read["settings"] == shipped["settings"]
    assert len(read["settings"]) == 347 and set(read["settings"]) <= set(shipped["all_4_6_names"])
