"""The replay's gyro before the filters (issue 42): the log's unfiltered gyro against the gyro the SITL's firmware read.

The ROMA F5's logs record the gyro before the firmware's filters (debug_mode GYRO_SCALED); the Gecko's do not.
Needs ../shared/data (skipped with the reason when absent) and the SITL (the ``firmware`` fixture).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from aerobat.cli import main
from aerobat.experiments.log_replay import VIBRATION_LOW_HZ, replay_log
from aerobat.plants.fpv.params import BetaflightParams

DATA = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "flight-logs"  # ../shared/data
ROMA = DATA / "betaflight" / "diatone-roma-f5.bbl"
GECKO = DATA / "betaflight" / "aikonf7-gecko.bbl"
needs_data = pytest.mark.skipif(not ROMA.is_file(), reason=f"the real flight logs are not here ({DATA} is absent)")
WINDOW = (20.0, 28.0)


def _vibrating() -> BetaflightParams:
    """The default airframe with the lines identification finds in the ROMA F5's first flight (rounded)."""
    base = BetaflightParams()
    airframe = dataclasses.replace(base.airframe, thrust_coefficient_n_s2=9.8e-7,
                                   vibration_rms_rad_s=(0.233, 0.177, 0.123), vibration_thrust_n=1.46)
    return dataclasses.replace(base, airframe=airframe)


@needs_data
def test_the_gyro_the_firmware_read_carries_the_airframes_lines_and_is_held_against_the_logs(firmware) -> None:
    quiet = replay_log(ROMA, index=2, window_s=WINDOW)
    shaking = replay_log(ROMA, index=2, window_s=WINDOW, params=_vibrating())
    for result in (quiet, shaking):
        assert result.gyro_unfiltered_log is not None and result.gyro_sensor_sim is not None
        assert result.gyro_sensor_sim.shape == result.gyro_sim.shape == result.gyro_unfiltered_log.shape
        assert len(result.vibration) == 3
    # the sensor is the true rates, FRD turned back into FLU, plus its errors: they follow each other
    for k in range(3):
        assert np.corrcoef(quiet.gyro_sensor_sim[:, k], quiet.gyro_sim[:, k])[0, 1] > 0.9
    assert quiet.vibration[0].rms_log_deg_s == shaking.vibration[0].rms_log_deg_s  # the log is the log
    for k in range(3):
        q, s = quiet.vibration[k], shaking.vibration[k]
        assert s.rms_sim_deg_s > 5.0 * q.rms_sim_deg_s  # the lines are there
        # closer to the log's than without them (the numbers themselves: scripts/results_vibration.py --replay)
        assert abs(s.rms_sim_deg_s - s.rms_log_deg_s) < abs(q.rms_sim_deg_s - q.rms_log_deg_s)
        assert VIBRATION_LOW_HZ <= s.peak_sim_hz <= 125.0 and VIBRATION_LOW_HZ <= s.peak_log_hz <= 125.0
    assert set(shaking.summary()["vibration"]) == {"roll", "pitch", "yaw"}


@needs_data
def test_a_log_without_the_unfiltered_gyro_says_vibration_was_not_compared(firmware, tmp_path, capsys) -> None:
    assert main(["log", "replay", f"{GECKO}:1", "--window-s", "50", "51.5", "--out", str(tmp_path / "g")]) == 0
    out = capsys.readouterr().out
    assert "vibration: not compared (the log records no gyro before the firmware's filters" in out
    assert main(["log", "replay", f"{ROMA}:2", "--window-s", "20", "21.5", "--out", str(tmp_path / "r"),
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert set(summary["vibration"]) == {"roll", "pitch", "yaw"}
    assert {"rms_log_deg_s", "rms_sim_deg_s", "peak_log_hz", "peak_sim_hz"} == set(summary["vibration"]["roll"])
