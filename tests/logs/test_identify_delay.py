"""How much of the fitted command-to-thrust delay a log decides (issue 42: "explain the 12 ms, or bound it").

The ROMA F5's first flight fits a 12 ms delay and a 5.3 ms motor time constant. Held at other delays
(the time constant, thrust curve and every linear coefficient refitted), the fit trades delay for lag
along a ridge where their sum stays near 17–19 ms; only the log's gyro filters (1.5 ms) or no delay at all
cost a third more, so a dead time well beyond the filters is in the log (docs/plants.md gives the table,
``scripts/results_whatif.py delay`` prints it).
"""

from __future__ import annotations

import pytest
from test_identify_excitation import GEOMETRY, ROMA, needs_data  # the ROMA F5's log and geometry, as identified there

from aerobat.experiments.log_identify import identify_from_logs
from aerobat.quadrotor.identification.logfit import delay_profile


@needs_data
def test_the_roma_flight_needs_a_dead_time_beyond_its_gyro_filters():
    result = identify_from_logs([f"{ROMA}:1"], GEOMETRY)
    fit = result.fit
    assert fit.model.delay_s == pytest.approx(0.012, abs=0.001)
    delays = (0.0, 0.0015, 0.008, fit.model.delay_s, 0.016)
    none, filters, shorter, free, longer = delay_profile(result.prepared, fit.layout, GEOMETRY, fit, delays)
    assert free.cost == pytest.approx(1.0, abs=0.005)  # held at its own delay, the fit comes back
    assert none.cost > 1.3 and filters.cost > 1.25  # a lag alone, or the filters' delay, fit far worse
    assert 1.0 < shorter.cost < 1.1 and longer.cost > 1.1  # 8 ms is nearly as good; 16 ms is not
    for point in (none, filters, shorter, free):  # the ridge: delay traded for the motor's lag
        assert 0.016 < point.delay_s + point.tau_s < 0.024, point
    assert none.tau_s > 4 * free.tau_s
    assert none.holdout[1].r2 < free.holdout[1].r2 - 0.3  # and the held-out pitch says so too
