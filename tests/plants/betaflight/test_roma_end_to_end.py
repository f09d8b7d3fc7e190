"""Issue 24's last step: the ROMA F5 identified from its log learns a 3D triple flip on its own tune.

``scripts/results_roma.py`` does it (identify --log, then learn through Betaflight running the
log header's tune, open loop); this runs one seed of it (about 1.5 min) in ``make test-slow``, with the
pack's sag under load that identification found in the log (issue 42's learning on the twin).
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[3] / "scripts" / "results_roma.py"
DATA = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "flight-logs"
ROMA = DATA / "betaflight" / "diatone-roma-f5.bbl"


def _script():
    spec = importlib.util.spec_from_file_location("_aerobat_results_roma", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
@pytest.mark.skipif(not ROMA.is_file(), reason=f"the real flight logs are not here ({DATA} is absent)")
def test_the_roma_f5_learns_a_triple_flip_on_its_own_tune(firmware, tmp_path):
    result = _script().run([1], tmp_path, trials=30)
    assert result["battery"]["rest_v"] is not None and result["battery"]["sag_v"] > 0  # the twin's pack sags (issue 42)
    (row,) = result["seeds"]
    assert row["trials"] == 30 and row["lost"] == 0 and row["ended"] is None, row  # no trial lost, no crash
    assert row["last10_mean_m"] <= 0.15, row
    assert row["last10_mean_m"] < row["first_m"], row  # learning, not luck of the first attempt
