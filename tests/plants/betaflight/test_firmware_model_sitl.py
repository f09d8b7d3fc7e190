"""The firmware design model held against the Betaflight SITL it models, and the design model's place in the tools.

The same program, the same vehicle, no noise (:mod:`aerobat.plants.betaflight.model_check`): the exact
model reproduces the firmware's set point and motor packet sample for sample and the flight to millimetres;
the design model (smooth in the program) to a centimetre or two. Then ``--design-model`` through the
command line: the default on a firmware plant, what the store keeps, what a resumed session keeps.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from aerobat.cli import main
from aerobat.experiments.designing import LITTLE_MARGIN_SHARE, nominal_design
from aerobat.firmware.betaflight.tune import load_tune
from aerobat.plants import PlantChoice
from aerobat.plants.betaflight.model_check import noiseless, sitl_flight
from aerobat.plants.betaflight.plant import BetaflightPlant
from aerobat.plants.fpv.design_model import firmware_design_model
from aerobat.plants.fpv.params import BetaflightParams
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.vehicle import fpv5

ROMA = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "flight-logs" / "betaflight" / \
    "diatone-roma-f5.bbl"
FPV = fpv5()


def _compare(params: BetaflightParams, rate_deg_s: float, firmware: tuple[Path, Path]) -> dict[str, dict[str, float]]:
    flip = MultiFlip(vehicle=FPV.vehicle, flips=3, max_rate_rad_s=math.radians(rate_deg_s), dims=3)
    nominal = nominal_design(flip, FPV, plant=PlantChoice("betaflight", params), design_model="firmware")
    program = flip.program(nominal.design.p_nominal)
    model = firmware_design_model(FPV, params)
    binary = firmware[0]
    plant = BetaflightPlant(FPV, noiseless(params, model), seed=0, feedback="none", binary=binary,
                            eeprom=None if params.tune is not None else firmware[1])
    sitl = sitl_flight(plant, program)
    out = {}
    for fidelity in ("exact", "design"):
        flown = firmware_design_model(FPV, params, fidelity=fidelity).trajectory(program)
        n = min(len(sitl.times_s), len(flown.times_s))
        assert n > 0.9 * program.duration_s * 8000
        out[fidelity] = {
            "position_m": float(np.linalg.norm(sitl.states[n - 1, :3] - flown.states[n - 1, :3])),
            "rotation_deg": math.degrees(float(np.linalg.norm(sitl.states[n - 1, 17:20] - flown.states[n - 1, 17:20]))),
            "motors": float(np.max(np.abs(sitl.motors[:n] - flown.motors[:n]))),
            "setpoint_deg_s": float(np.max(np.abs(sitl.setpoint_deg_s[:n] - flown.setpoint_deg_s[:n]))),
            "p_term": float(np.max(np.abs(sitl.pid[:n, 0] - flown.pid[:n, 0]))),
        }
    return out


def test_the_exact_model_flies_aerobats_tune_as_the_firmware_does(firmware: tuple[Path, Path]) -> None:
    """The 3D triple flip at 1800 °/s, the SITL and the model step by step (8 kHz, 7,500 steps)."""
    d = _compare(BetaflightParams(), 1800.0, firmware)
    exact, smooth = d["exact"], d["design"]
    assert exact["setpoint_deg_s"] < 0.01  # the rate curve, RC smoothing and the frames' timing (float32 aside)
    assert exact["motors"] <= 0.0011  # at most one of the packet's microsecond steps, anywhere
    assert exact["p_term"] < 0.5  # of P terms up to hundreds: float32 against float64
    assert exact["position_m"] < 0.005 and exact["rotation_deg"] < 0.05
    assert smooth["position_m"] < 0.02 and smooth["rotation_deg"] < 1.0  # issue 41: 2 cm and 1 degree


def test_the_exact_model_flies_a_sagging_battery_as_the_firmware_does(firmware: tuple[Path, Path]) -> None:
    """A 4S pack that sags 3 V at full load (issue 42): the plant's physics and the model scale thrust alike,
    and the sag moves the flip by far more than the two disagree."""
    params = BetaflightParams().replace(airframe__battery_reference_v=15.6, airframe__battery_rest_v=16.3,
                                        airframe__battery_sag_v=3.0)
    d = _compare(params, 1800.0, firmware)
    exact, smooth = d["exact"], d["design"]
    assert exact["motors"] <= 0.0011
    assert exact["position_m"] < 0.005 and exact["rotation_deg"] < 0.05
    assert smooth["position_m"] < 0.02 and smooth["rotation_deg"] < 1.0
    flip = MultiFlip(vehicle=FPV.vehicle, flips=3, max_rate_rad_s=math.radians(1800.0), dims=3)
    program = flip.program(nominal_design(flip, FPV, plant=PlantChoice("betaflight", params),
                                          design_model="firmware").design.p_nominal)
    sagging = firmware_design_model(FPV, params).final_states([program])[0]
    steady = firmware_design_model(FPV, params.replace(airframe__battery_rest_v=None)).final_states([program])[0]
    assert np.linalg.norm(sagging[:3] - steady[:3]) > 0.05  # the sag matters at this scale
    assert np.linalg.norm(sagging[:3]) < 0.01  # the design knows it: the flip ends where it started


@pytest.mark.skipif(not ROMA.is_file(), reason="../shared/data (the ROMA F5's blackbox log) is not here")
def test_the_exact_model_flies_a_pilots_tune_as_the_firmware_does(firmware: tuple[Path, Path]) -> None:
    """The ROMA F5's own tune (its log's header: BETAFLIGHT rates, a 2 µs deadband, the PID at 4 kHz, its filters)."""
    params = dataclasses.replace(BetaflightParams(), tune=load_tune(ROMA))
    d = _compare(params, 600.0, firmware)
    exact, smooth = d["exact"], d["design"]
    assert exact["setpoint_deg_s"] < 0.01
    assert exact["motors"] <= 0.0011
    assert exact["position_m"] < 0.02 and exact["rotation_deg"] < 0.2  # issue 41: 2 cm and 1 degree
    # the design model leaves out the 1 µs steps and repeated frames: over this 2.6 s flip a few centimetres
    assert smooth["position_m"] < 0.04 and smooth["rotation_deg"] < 1.0


def test_design_runs_on_the_firmware_by_default_on_betaflight_and_says_so(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["design", "flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "800", "--vehicle", "fpv5"]
    assert main([*argv, "--plant", "betaflight", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["design_model"] == "firmware" and out["converged"]
    assert "Betaflight 4.6.0" in out["design_model_description"]
    assert 0.0 <= out["full_output_share"] < LITTLE_MARGIN_SHARE  # a single flip at 800 °/s: thrust to spare
    assert main([*argv, "--plant", "betaflight"]) == 0
    said = capsys.readouterr().out
    assert f"on the model, p⁰ holds a motor at full output in {100 * out['full_output_share']:.1f}% of its steps\n" \
        in said, said
    assert main([*argv, "--plant", "betaflight", "--design-model", "paper", "--json"]) == 0
    paper = json.loads(capsys.readouterr().out)
    assert paper["design_model"] == "paper" and paper["full_output_share"] is None  # the paper's model has no motors
    assert np.max(np.abs(np.array(paper["p_nominal"]) - np.array(out["p_nominal"]))) > 1e-3
    assert main([*argv, "--json"]) == 0  # no plant: the paper's model, as before
    assert json.loads(capsys.readouterr().out)["design_model"] == "paper"
    assert main([*argv, "--plant", "arena", "--design-model", "firmware"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["aerobat: error: --design-model firmware: the arena plant designs on paper (no firmware to model)"]


def test_a_session_keeps_the_model_it_was_designed_on(firmware: tuple[Path, Path], tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    db = str(tmp_path / "s.sqlite")
    argv = ["learn", "flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "800", "--vehicle", "fpv5",
            "--plant", "betaflight", "--feedback", "none", "--trials", "1", "--db", db, "--out", str(tmp_path / "o")]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "designed on the firmware model: Betaflight 4.6.0, aerobat settings revision" in out
    assert "  on the model, p⁰ holds a motor at full output in " in out  # the thrust margin, as design says it
    assert main(["show", "1", "--db", db]) == 0
    assert "designed on the firmware model" in capsys.readouterr().out
    session = json.loads((tmp_path / "o" / "session.json").read_text())
    assert session["design_model"]["kind"] == "firmware"
    assert main(["learn", "--resume", "1", "--trials", "2", "--db", db, "--out", str(tmp_path / "o")]) == 0
    assert "designed on the firmware model" in capsys.readouterr().out
    # a full command line naming the other model describes another session: refused, nothing flown
    assert main([*argv[:-4], "--resume", "1", "--trials", "3", "--design-model", "paper", "--db", db]) == 2
    assert "--design-model paper (stored: firmware)" in capsys.readouterr().err


def test_a_design_that_holds_the_motors_at_full_output_says_its_thrust_margin_is_small() -> None:
    """The summary names the share of p⁰'s steps at full output, and warns above LITTLE_MARGIN_SHARE."""
    import dataclasses

    flip = MultiFlip(vehicle=FPV.vehicle, flips=1, max_rate_rad_s=math.radians(800.0), dims=2)
    nominal = nominal_design(flip, FPV, plant=PlantChoice("betaflight"))
    assert nominal.full_output_share is not None
    assert "thrust margin is small" not in nominal.summary()
    tight = dataclasses.replace(nominal, full_output_share=0.195)
    assert "full output in 19.5% of its steps; above 15% the thrust margin is small" in tight.summary()
