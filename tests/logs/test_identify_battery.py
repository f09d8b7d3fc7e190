"""The battery under load identified from a log's voltage (issue 42): V = rest − drain · t − sag · mean(u²)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from aerobat.experiments.log_identify import airframe_from_log_fit, identify_from_logs
from aerobat.logs import read_log
from aerobat.quadrotor.flightlog import Channel
from aerobat.quadrotor.identification.battery import fit_battery
from aerobat.quadrotor.identification.logfit import Geometry
from aerobat.quadrotor.vehicle import fpv5
from aerobat.quadrotor.xframe import Airframe

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "flight-logs"
ROMA = DATA / "betaflight" / "diatone-roma-f5.bbl"
GECKO = DATA / "betaflight" / "aikonf7-gecko.bbl"
needs_data = pytest.mark.skipif(not ROMA.is_file(), reason=f"the real flight logs are not here ({DATA} is absent)")


def _pack(rest_v: float, drain_v_per_s: float, sag_v: float, seconds: float, seed: int
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 0.004)
    u = np.clip(0.35 + 0.25 * np.sin(2.0 * np.pi * 0.7 * t)[:, None] + 0.1 * rng.standard_normal((t.size, 4)), 0, 1)
    v = rest_v - drain_v_per_s * (t - np.median(t)) - sag_v * (u**2).mean(axis=1) + 0.05 * rng.standard_normal(t.size)
    return t, v, u


def test_two_flights_of_one_pack_give_its_sag_and_each_its_own_rest() -> None:
    fit = fit_battery([_pack(16.2, 0.01, 2.8, 60.0, 1), _pack(15.4, 0.008, 2.8, 40.0, 2)])
    assert fit is not None
    assert fit.sag_v == pytest.approx(2.8, rel=0.01)
    first, second = 60.0 / 100.0, 40.0 / 100.0  # weighted by samples (all of them fly)
    assert fit.rest_v == pytest.approx(first * 16.2 + second * 15.4, abs=0.01)
    assert fit.drain_v_per_s == pytest.approx(first * 0.01 + second * 0.008, abs=5e-4)
    assert fit.rms_v == pytest.approx(0.05, rel=0.05) and fit.r_squared > 0.9


def test_no_flight_or_no_load_change_gives_no_battery() -> None:
    t, v, u = _pack(16.2, 0.01, 2.8, 60.0, 1)
    assert fit_battery([(t, v, np.full_like(u, 0.05))]) is None  # never flying
    assert fit_battery([(t[:40], v[:40], u[:40])]) is None  # too little flight
    assert fit_battery([(t, v, np.full_like(u, 0.5))]) is None  # one load: sag and rest cannot be told apart


@needs_data
@pytest.mark.parametrize(("path", "index"), [(ROMA, 1), (ROMA, 2), (ROMA, 3), (GECKO, 1)])
def test_real_packs_sag_by_a_racing_packs_share_of_their_voltage(path: Path, index: int) -> None:
    """Each real flight alone: the sag at full load is 10–25 % of the resting voltage (a racing LiPo at
    ~100 A), and the model explains most of the logged voltage (the ROMA F5's vbat is noisier than the Gecko's)."""
    log = read_log(path, index)
    motors = log.signals[Channel.MOTOR_COMMAND]
    fit = fit_battery([(motors.time_s, log.signals[Channel.BATTERY_VOLTAGE].at(motors.time_s)[:, 0], motors.values)])
    assert fit is not None and fit.samples > 10_000
    assert 0.10 < fit.sag_v / fit.rest_v < 0.25, fit.describe()
    assert fit.r_squared > 0.6, fit.describe()


@needs_data
def test_identification_writes_the_pack_into_the_airframe_where_its_flight_load_is_the_reference() -> None:
    result = identify_from_logs([f"{ROMA}:1"], Geometry(mass_kg=0.55, motor_x_m=0.08, motor_y_m=0.08,
                                                        inertia_zz_ratio=0.935), prior=fpv5())
    battery = result.battery
    assert battery is not None
    table = airframe_from_log_fit(result.fit, battery_reference_v=result.battery_reference_v, battery=battery)
    assert table["battery_rest_v"] == battery.rest_v and table["battery_sag_v"] == battery.sag_v
    airframe = Airframe(**{k: tuple(v) if isinstance(v, list) else v for k, v in table.items()})
    assert airframe.battery_flown
    # at the flight's median load the pack gives about the median voltage in flight: thrust as identified
    load = np.sqrt(battery.load_median)
    assert airframe.battery_factor((load,) * 4) == pytest.approx(1.0, abs=0.03)
    assert airframe.battery_factor((1.0,) * 4) < 0.8  # a punch to full throttle loses a fifth of the thrust
    no_voltage = airframe_from_log_fit(result.fit, battery_reference_v=None, battery=battery)
    assert "battery_rest_v" not in no_voltage and no_voltage["battery_sag_v"] == 0.0
