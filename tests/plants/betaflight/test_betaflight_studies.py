"""Studies with the Betaflight plant: the jobs build it in worker processes from its stored settings."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from aerobat.core.design import design
from aerobat.experiments.job import run_job
from aerobat.experiments.studies import RobustnessRanges, robustness_jobs
from aerobat.plants.betaflight.sampling import sample_betaflight
from aerobat.plants.fpv.params import BetaflightParams
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import NominalModel
from aerobat.quadrotor.vehicle import fpv5

FPV = fpv5()


def test_sampled_betaflight_vehicles_vary_the_airframe_and_the_pilots_model_of_it() -> None:
    table, props = sample_betaflight(RobustnessRanges(), seed=3)
    again, _ = sample_betaflight(RobustnessRanges(), seed=3)
    assert table == again
    base = BetaflightParams()
    assert table["airframe"]["mass_kg"] == pytest.approx(base.airframe.mass_kg * props["mass_scale"])
    assert table["airframe"]["motor_tau_up_s"] == pytest.approx(base.airframe.motor_tau_up_s * props["motor_tau_scale"])
    assert table["pilot"] == json.loads(json.dumps(table["pilot"]))
    # issue 31 B1: the pilot's mass model is off too, by up to ±15 % (drawn after every other property)
    lo, hi = RobustnessRanges().pilot_mass_scale
    assert (lo, hi) == (0.85, 1.15) and lo <= props["pilot_mass_scale"] <= hi
    assert table["pilot"]["vehicle_mass_kg"] == pytest.approx(0.752 * props["pilot_mass_scale"])
    assert "tune" not in table
    assert table["firmware"]["gyro_rate_hz"] == 8000


def test_a_robustness_job_learns_on_a_sampled_betaflight_vehicle(firmware: tuple[Path, Path]) -> None:
    flip = MultiFlip(vehicle=FPV.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
    jobs = robustness_jobs(flip, design(flip, NominalModel(FPV)), FPV, vehicles=1, iterations=2, seed=1,
                           plant="betaflight")
    assert jobs[0].spec["plant"]["kind"] == "betaflight"
    outcome = run_job(jobs[0])
    assert outcome.done, outcome.error
    assert outcome.result["status"] == "completed" and len(outcome.result["position_errors_m"]) == 2


def test_rules_study_runs_betaflight_in_worker_processes(firmware: tuple[Path, Path], tmp_path: Path) -> None:
    exe = Path(sys.executable).with_name("aerobat")
    result = subprocess.run(
        [str(exe), "study", "rules", "flip", "--flips", "1", "--max-rate-deg-s", "800", "--dims", "2",
         "--vehicle", "fpv5", "--plant", "betaflight", "--methods", "paper", "--seeds", "1", "--trials", "2",
         "--workers", "1", "--db", str(tmp_path / "s.sqlite"), "--out", str(tmp_path / "out")],
        capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    assert "1 jobs to run" in result.stdout and "paper-seed-0000 done" in result.stderr  # study seeds start at 0;
    # progress lines go to standard error (docs/cli.md)
