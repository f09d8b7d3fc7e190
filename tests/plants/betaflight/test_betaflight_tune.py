"""A real quad's tune: parsing, translation to 4.6 and the report (no firmware)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from aerobat.firmware.betaflight.settings import load_settings
from aerobat.firmware.betaflight.sitl_table import load_table
from aerobat.firmware.betaflight.translate import translate
from aerobat.firmware.betaflight.tune import (
    TuneError,
    load_tune,
    parse_cli,
    read_blackbox_headers,
    tune_from_blackbox_header,
)
from aerobat.plants import PlantChoice
from aerobat.plants.fpv.params import Airframe, BetaflightParams
from aerobat.plants.fpv.pilot import StickMap, stick_for_rate, throttle_for_collective

DATA = Path("/work/shared/data")
DIFF = DATA / "betaflight-configs" / "tii-racing-kakuteh7-4.3.1-diff.txt"
ROMA = DATA / "flight-logs" / "betaflight" / "diatone-roma-f5.bbl"
needs_data = pytest.mark.skipif(not DIFF.is_file() or not ROMA.is_file(), reason="the shared real data is absent")


@needs_data
def test_the_real_431_diff_is_translated_and_every_line_accounted_for() -> None:
    tune = load_tune(DIFF)
    assert tune.version == (4, 3, 1) and tune.active_profile == 0 and tune.active_rateprofile == 1
    report = translate(tune)
    values = report.values()
    # PIDs as the file states them; before 4.6 d_roll was the maximum D, d_min_roll the base (equal: inactive)
    assert (values["p_roll"], values["i_roll"], values["d_roll"], values["d_max_roll"]) == ("63", "67", "46", "46")
    assert (values["p_pitch"], values["d_pitch"], values["d_max_pitch"]) == ("75", "47", "47")
    # the active rate profile (1), not profile 0
    assert values["rates_type"] == "BETAFLIGHT" and values["roll_rc_rate"] == "202" and values["roll_srate"] == "0"
    assert values["simplified_d_max_gain"] == "0" and values["feedforward_averaging"] == "3_POINT"
    refused = {name: why for name, _, _, why in report.refused}
    assert "board alignment" not in refused and "align_board_roll" in refused
    assert "not compiled into the SITL" in refused["dyn_notch_count"]
    assert "battery" in refused["vbat_sag_compensation"] and "serial" in refused
    assert "not the active rateprofile" in refused["rateprofile 0: roll_rc_rate"]
    pinned = {name for name, _, _ in report.pinned}
    assert {"aux", "small_angle", "pwr_on_arm_grace", "min_check"} <= pinned
    assert "small_angle" not in values  # the tune's 180 stays aerobat's 25
    # every setting line of the file is in exactly one list
    accounted = len(report.applied) + len(report.refused) + len(report.pinned) - 7  # 7 pins not in the file
    pairs = 2  # d_roll/d_min_roll and d_pitch/d_min_pitch: one translated entry per pair of lines
    assert accounted + len({line for *_, line, _ in report.translated}) + pairs == sum(
        1 for line in DIFF.read_text().splitlines()
        if line.split(" ")[0] in ("set", "feature", "serial", "beacon", "aux", "board_name", "manufacturer_id",
                                  "mcu_id", "signature"))
    # every value applied is one the SITL build accepts
    table = load_table()
    assert all(table.get(name).check(value) is None for name, value in values.items())
    text = report.text()
    assert "translated  simplified_dmax_gain = 0 -> simplified_d_max_gain = 0" in text and "refused" in text
    # what `--tune` prints: the lines that matter, refused settings grouped by why (issue 44: not 87 lines)
    summary = report.summary("aerobat tune FILE").splitlines()
    assert summary[0] == text.splitlines()[0] and len(summary) <= 25 < len(text.splitlines())
    assert [line for line in summary if line.startswith("  translated")] == [
        line for line in text.splitlines() if line.startswith("  translated")]
    assert "  refused     2 × a 4.6 setting not compiled into the SITL build (its hardware is absent): " \
           "dyn_notch_count, dyn_notch_q" in summary
    assert sum(int(line.split()[1]) for line in summary if line.startswith("  refused")) == len(report.refused)
    assert summary[-1] == (f"  ({len(report.applied)} applied and {len(report.pinned)} pinned settings not listed: "
                           "`aerobat tune FILE` prints every setting)")


@needs_data
def test_blackbox_headers_are_read_and_translated() -> None:
    headers = read_blackbox_headers(ROMA.read_bytes())
    assert len(headers) == 3 and headers[0]["rollPID"] == "47,85,38"
    tune = tune_from_blackbox_header(headers[0], source="roma#1")
    assert tune.version == (4, 2, 9)
    values = translate(tune).values()
    assert (values["p_roll"], values["i_roll"], values["d_roll"], values["d_max_roll"]) == ("47", "85", "23", "38")
    assert values["rates_type"] == "BETAFLIGHT" and values["roll_rc_rate"] == "100" and values["roll_srate"] == "70"
    assert values["f_pitch"] == "95" and values["dterm_lpf1_static_hz"] == "150" and values["motor_idle"] == "550"
    assert values["gyro_lpf1_dyn_min_hz"] == "190" and values["gyro_lpf2_static_hz"] == "238"
    assert values["feedforward_averaging"] == "2_POINT" and values["tpa_breakpoint"] == "1350"
    with pytest.raises(TuneError, match=r"bbl:4: no such log; the file holds 3 log\(s\), allowed .*bbl:1 … .*bbl:3"):
        load_tune(ROMA, log_index=4)
    assert load_tune(ROMA, log_index=2).source.endswith("#log2")


def test_header_mapping_given_by_another_reader() -> None:
    header = {"Firmware revision": "Betaflight 4.2.9 (e097f4ab7) STM32F7X2", "rollPID": "47,85,38",
              "rates_type": "0", "rc_rates": "100,100,100", "rates": "70,70,70", "rc_expo": "0,0,0",
              "feedforward_weight": "90,95,90", "dterm_lowpass_hz": "150", "tpa_rate": "65", "tpa_breakpoint": "1350",
              "dshot_idle_value": "550", "motorOutput": "158,2047", "d_min": "23,25,0"}
    report = translate(tune_from_blackbox_header(header, source="mem"))
    assert report.values()["d_roll"] == "23" and report.values()["motor_idle"] == "550"
    assert ("motorOutput", "", 12, "recorded in the log, not a setting") in report.refused
    with pytest.raises(TuneError, match=r"mem: header field rollPID:'47,85': expected 3"):
        tune_from_blackbox_header({**header, "rollPID": "47,85"}, source="mem")
    with pytest.raises(TuneError, match="no 'Firmware revision'"):
        tune_from_blackbox_header({"rollPID": "1,2,3"}, source="mem")


@pytest.mark.parametrize(("text", "message"), [
    ("# Betaflight / X 4.3.1\nset p_roll = 50\nfrobnicate 3\n", r"f\.txt: line 3: unknown CLI command 'frobnicate'"),
    ("set p_roll 50\n", r"f\.txt: line 1: malformed set line"),
    ("set p_rol = 50\n", r"f\.txt: line 1: unknown setting 'p_rol'"),
    ("profile x\n", r"f\.txt: line 1: malformed profile line"),
])
def test_unknown_or_malformed_lines_name_the_file_and_line(text: str, message: str) -> None:
    with pytest.raises(TuneError, match=message):
        translate(parse_cli(text, source="f.txt"))


def test_out_of_range_values_are_refused_not_flown() -> None:
    report = translate(parse_cli("# Betaflight / X 4.6.0\nset p_roll = 300\nset rates_type = NOPE\n", source="f"))
    assert report.values() == {}
    reasons = [why for *_, why in report.refused]
    assert "allowed 0..250" in reasons[0] and "allowed BETAFLIGHT, RACEFLIGHT, KISS, ACTUAL, QUICK" in reasons[1]


@pytest.mark.parametrize(("kind", "rc_rate", "srate", "expo", "stick", "deg_s"), [
    ("BETAFLIGHT", 202, 0, 0, 1.0, 200 * (2.02 + 14.54 * 0.02)),
    ("BETAFLIGHT", 80, 70, 0, 1.0, 160 / 0.3),
    ("ACTUAL", 20, 67, 0, 0.5, 100 + 470 * 0.25),
    ("RACEFLIGHT", 37, 80, 0, 1.0, 370 * 1.8),
    ("KISS", 70, 50, 0, 0.5, 2000 / 0.75 * 0.035),
    ("QUICK", 100, 67, 0, 1.0, 670),
])
def test_rate_curves_of_every_type_and_the_pilot_inverts_them(kind: str, rc_rate: int, srate: int, expo: int,
                                                              stick: float, deg_s: float) -> None:
    axes = "".join(f"set {a}_rc_rate = {rc_rate}\nset {a}_srate = {srate}\nset {a}_expo = {expo}\n"
                   for a in ("roll", "pitch", "yaw"))
    text = f"# Betaflight / X 4.6.0\nset rates_type = {kind}\n{axes}"
    settings = load_settings().with_tune(translate(parse_cli(text, source="t")))
    assert settings.rate_deg_s("roll", stick) == pytest.approx(deg_s, rel=1e-6)
    limits = StickMap.from_settings(settings, Airframe(), 0.752).limits(max_tilt_rad=0.6, max_climb_m_s=2.5,
                                                                       gravity_m_s2=9.81)
    for x in (0.1, 0.35, 0.8):
        for axis, name in enumerate(("roll", "pitch", "yaw")):
            rate = settings.rate_deg_s(name, x)
            assert settings.rate_deg_s(name, stick_for_rate(math.radians(rate), axis, limits)) == pytest.approx(
                rate, rel=2e-3)
    assert stick_for_rate(-math.radians(settings.rate_deg_s("roll", 0.35)), 0, limits) == pytest.approx(-0.35,
                                                                                                       abs=2e-3)


def test_throttle_curve_of_a_tune_is_inverted_by_the_pilot() -> None:
    text = "# Betaflight / X 4.6.0\nset thr_mid = 40\nset thr_hover = 30\nset thr_expo = 50\nset motor_idle = 400\n"
    settings = load_settings().with_tune(translate(parse_cli(text, source="t")))
    assert not settings.linear_throttle()
    sticks = StickMap.from_settings(settings, Airframe(), 0.752)
    limits = sticks.limits(max_tilt_rad=0.6, max_climb_m_s=2.5, gravity_m_s2=9.81)
    hover_us = throttle_for_collective(9.81, limits)
    motor = settings.motor_for_throttle_us(hover_us)
    # the pilot's model: 4 rotors give m g at that motor command
    assert 4 * Airframe().thrust_n(motor) == pytest.approx(0.752 * 9.81, rel=5e-3)
    assert settings.motor_for_throttle_us(1000) == pytest.approx(0.04)


def test_default_settings_keep_the_linear_maps() -> None:
    sticks = StickMap.from_settings(load_settings(), Airframe(), 0.752)
    assert sticks.rate_tables_rad_s is None and sticks.motor_table is None
    assert sticks.full_rates_deg_s() == pytest.approx((1998.0,) * 3)


@needs_data
def test_the_tune_is_stored_with_the_plant_and_comes_back() -> None:
    tune = load_tune(DIFF)
    choice = PlantChoice("betaflight", BetaflightParams(tune=tune))
    table = json.loads(json.dumps(choice.to_table()))
    assert table["settings"]["tune"]["source"] == str(DIFF)
    assert PlantChoice.from_table(table, source="stored").settings.tune == tune
    assert "tune" not in PlantChoice("betaflight").to_table()["settings"]  # no tune: the table as before


@needs_data
def test_a_settings_file_keeps_the_tune(tmp_path: Path) -> None:
    from aerobat.plants.fpv.params import load_betaflight, save_betaflight

    tune = load_tune(DIFF)
    save_betaflight(BetaflightParams(tune=tune), tmp_path / "bf.toml")
    assert load_betaflight(tmp_path / "bf.toml").tune == tune
    save_betaflight(BetaflightParams(), tmp_path / "plain.toml")
    assert "tune" not in (tmp_path / "plain.toml").read_text() and load_betaflight(tmp_path / "plain.toml").tune is None
