"""Identification that says what a log cannot tell (issue 42): a poorly excited axis takes the prior's ratio.

The ROMA F5's first flight has little pitch (6 °/s rms in 1–20 Hz against 12 of roll); identified from it
alone, I_yy came out 1.6× I_xx with a 14 % jackknife spread, and the SITL flew flights 2 and 3 further from
the log on pitch than the default 5-inch did (17.3 and 12.3 °/s rms against 14.2 and 10.8).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from aerobat.experiments.log_excitation import (
    EXCITATION_MIN_DEG_S,
    PRIOR_RELATIVE_SIGMA,
    AxisExcitation,
    with_prior_for_poorly_excited_axes,
)
from aerobat.experiments.log_identify import identify_from_logs
from aerobat.quadrotor.identification.logfit import Geometry
from aerobat.quadrotor.vehicle import fpv5

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "flight-logs"
ROMA = DATA / "betaflight" / "diatone-roma-f5.bbl"
GEOMETRY = Geometry(mass_kg=0.55, motor_x_m=0.08, motor_y_m=0.08, inertia_zz_ratio=0.935)
needs_data = pytest.mark.skipif(not ROMA.is_file(), reason=f"the real flight logs are not here ({DATA} is absent)")


@needs_data
def test_a_flight_with_little_pitch_takes_i_yy_from_the_prior_and_says_so():
    prior = fpv5()
    plain = identify_from_logs([f"{ROMA}:1"], GEOMETRY)  # no prior: the fit as it is, its excitation measured
    assert plain.excitation.poorly_excited() == ("pitch", "yaw") and plain.excitation_notes == ()
    roll, pitch, _ = plain.excitation.rms_deg_s
    assert pitch < EXCITATION_MIN_DEG_S <= roll
    result = identify_from_logs([f"{ROMA}:1"], GEOMETRY, prior=prior)
    ixx, iyy = result.fit.value("inertia_xx_kg_m2"), result.fit.value("inertia_yy_kg_m2")
    ratio = prior.vehicle.inertia_yy_kg_m2 / prior.vehicle.inertia_xx_kg_m2
    assert iyy == pytest.approx(ixx * ratio, rel=1e-12)
    assert result.fit.values["inertia_yy_kg_m2"][1] == pytest.approx(PRIOR_RELATIVE_SIGMA * iyy)
    assert plain.fit.value("inertia_yy_kg_m2") > 1.5 * iyy  # what the fit alone gave
    assert result.fit.value("inertia_zz_kg_m2") == pytest.approx(GEOMETRY.inertia_zz_ratio * (ixx + iyy))
    assert any("pitch is poorly excited" in n for n in result.excitation_notes)
    assert any("pitch is poorly excited" in n for n in result.fit.notes)


@needs_data
def test_a_flight_that_flies_pitch_keeps_its_pitch_fit():
    """Flight 2 is mostly pitch (85 °/s rms) with little roll (8.7): pitch stays fitted, roll takes the ratio."""
    plain = identify_from_logs([f"{ROMA}:2"], GEOMETRY)
    result = identify_from_logs([f"{ROMA}:2"], GEOMETRY, prior=fpv5())
    assert result.excitation.poorly_excited() == ("roll", "yaw")
    assert result.fit.value("inertia_yy_kg_m2") == plain.fit.value("inertia_yy_kg_m2")
    assert any(n.startswith("roll is poorly excited") for n in result.excitation_notes)


def test_two_poorly_excited_axes_leave_the_fit_and_say_it_is_unchecked():
    class Fit:
        values = {"inertia_xx_kg_m2": (1e-3, 1e-4, "kg m²"), "inertia_yy_kg_m2": (2e-3, 1e-4, "kg m²")}

    fit, notes = with_prior_for_poorly_excited_axes(Fit(), AxisExcitation((3.0, 4.0, 20.0)), fpv5())
    assert fit.values["inertia_yy_kg_m2"][0] == 2e-3 and "both poorly excited" in notes[0]
    fit, notes = with_prior_for_poorly_excited_axes(Fit(), AxisExcitation((30.0, 40.0, 2.0)), fpv5())
    assert notes == []  # yaw's inertia is assumed anyway (the I_zz ratio)


GECKO = DATA / "betaflight" / "aikonf7-gecko.bbl"


@pytest.mark.skipif(not GECKO.is_file(), reason=f"the real flight logs are not here ({DATA} is absent)")
def test_part_of_a_log_is_fitted_and_the_rest_of_it_validates():
    result = identify_from_logs([GECKO], GEOMETRY, window_s=(0.0, 67.0), prior=fpv5())
    assert result.fitted == ("aikonf7-gecko.bbl@0-67s",)
    assert [name for name, _ in result.validations] == ["aikonf7-gecko.bbl@67-133.838s"]
    assert not isinstance(result.validations[0][1], str)  # validated, not refused
    assert result.battery_reference_v is not None and 13.0 < result.battery_reference_v < 17.0  # a 4S pack
    with pytest.raises(Exception, match="lasts 133.8 s"):
        identify_from_logs([GECKO], GEOMETRY, window_s=(200.0, 300.0))
