"""What-if replays (issue 42): a logged flight's sticks flown with another tune beside the log's own.

The log is the ROMA F5's first flight and the 4.3.1 diff of ../shared/data (skipped with the reason when
absent); flying needs the SITL (the ``firmware`` fixture skips when it cannot be built).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from aerobat.cli import main
from aerobat.errors import ConfigError
from aerobat.experiments.log_replay import replay_log
from aerobat.experiments.log_whatif import tune_differences, what_if
from aerobat.firmware.betaflight.tune import TuneError, load_tune, with_settings
from aerobat.quadrotor.log_analysis import estimate_step_response

SHARED = Path(__file__).resolve().parents[3].parent / "shared" / "data"
ROMA = SHARED / "flight-logs" / "betaflight" / "diatone-roma-f5.bbl"
KAKUTE = SHARED / "betaflight-configs" / "tii-racing-kakuteh7-4.3.1-diff.txt"
needs_data = pytest.mark.skipif(not ROMA.is_file(), reason=f"the real flight logs are not here ({SHARED} is absent)")
WINDOW = (40.0, 62.0)  # the first flight's roll moves (three set-point steps of 100 °/s and more)


@needs_data
def test_a_change_lands_where_the_tune_sets_it_and_is_named_in_messages():
    own = load_tune(ROMA, log_index=1)
    changed = with_settings(own, ["p_roll=94", "D_ROLL = 40"])
    assert [d.name for d in tune_differences(own, changed)] == ["d_max_roll", "p_roll"]  # 4.2's d_roll is D max
    assert changed.where(-1) == "--set p_roll=94" and changed.where(-2) == "--set d_roll=40"
    assert tune_differences(own, own) == ()
    with pytest.raises(TuneError, match="expected NAME=VALUE"):
        with_settings(own, ["p_roll"])


@needs_data
def test_a_change_the_firmware_would_refuse_is_refused_before_anything_flies():
    with pytest.raises(ConfigError, match=r"--set p_roll=9000: refused: .*allowed 0\.\.250"):
        what_if(f"{ROMA}:1", changes=["p_roll=9000"])  # translated alone it falls back to the default: never here
    with pytest.raises(ConfigError, match="unknown setting 'p_rol'"):
        what_if(f"{ROMA}:1", changes=["p_rol=9"])
    with pytest.raises(ConfigError, match="needs --tune OTHER or --set"):
        what_if(f"{ROMA}:1")


@needs_data
def test_doubling_p_on_roll_shortens_the_rise_and_the_sandbox_sees_overshoot_move(firmware) -> None:
    """Doubling P (47 → 94) on the ROMA F5's roll: the simulated step response rises faster. The issue expected
    more overshoot as well; the firmware gives less (the overshoot of this loop comes from its I term, which
    stiffer P damps: docs/plants.md). Doubling I instead raises it, so the measure does see overshoot move."""
    result = what_if(f"{ROMA}:1", changes=["p_roll=94"], window_s=WINDOW)
    assert [(d.name, d.flown, d.what_if) for d in result.differences] == [("p_roll", "47", "94")]
    log, twin, doubled = (r.axes[0] for r in result.readings)
    assert doubled.rise_s < 0.8 * twin.rise_s
    assert doubled.overshoot < twin.overshoot  # the finding, measured: see the docstring
    own = load_tune(ROMA, log_index=1)
    more_i = replay_log(ROMA, index=1, window_s=WINDOW, tune=with_settings(own, ["i_roll=170"]))
    r = estimate_step_response(more_i.time_s, more_i.setpoint_sim[:, 0], more_i.gyro_sim[:, 0])
    assert r is not None and r.overshoot > twin.overshoot + 0.03
    assert log.steps == twin.steps == doubled.steps >= 1  # the same sticks, the same steps found


@needs_data
@pytest.mark.skipif(not KAKUTE.is_file(), reason=f"the 4.3.1 diff is not here ({KAKUTE} is absent)")
def test_a_4_3_1_diff_flown_on_a_roma_log_says_which_settings_differ(firmware, tmp_path, capsys) -> None:
    code = main(["log", "replay", f"{ROMA}:3", "--tune", str(KAKUTE), "--window-s", "20", "24",
                 "--out", str(tmp_path), "--json"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    differ = {d["name"]: (d["flown"], d["what_if"]) for d in out["differences"]}
    assert differ["p_roll"] == ("47", "63") and differ["f_roll"] == ("90", "0")
    assert differ["roll_rc_rate"] == ("100", "202") and len(differ) > 20
    assert [r["name"] for r in out["readings"]] == ["log", "SITL, the log's tune", "SITL, what-if"]
    assert Path(out["figure"]).stat().st_size > 20_000


@needs_data
def test_the_replay_turns_the_props_the_way_the_logs_mixer_does(firmware) -> None:
    """The ROMA F5 flies props out (its yaw mixing says so). Flown props in, the SITL's motor yaw mix
    (M1 + M4 − M2 − M3) ran against the log's (−0.55 on flight 3, 20–60 s); following the log it runs with it.
    The gyro is the same either way: the spins and the mixer turn together."""
    own = replay_log(ROMA, index=3, window_s=(20.0, 60.0))
    forced_in = replay_log(ROMA, index=3, window_s=(20.0, 60.0), props_out=False)
    assert own.props.startswith("out (mixer QUADX with props out") and forced_in.props == "in (as asked)"
    mix = np.array([1.0, -1.0, -1.0, 1.0])

    def r(result):
        return float(np.corrcoef(result.motors_sim @ mix, result.motors_log @ mix)[0, 1])

    assert r(own) > 0.45 and r(forced_in) < -0.45
    for a, b in zip(own.gyro, forced_in.gyro, strict=True):
        assert abs(a.rms - b.rms) < 0.1


@needs_data
def test_thrust_follows_the_logged_battery(firmware) -> None:
    """Flight 3 flies on a battery that sags from 23.2 to 16 V; replayed on an airframe whose thrust holds at
    23.69 V, every rotor's thrust is scaled by (V/23.69)², and the flight differs from one at constant thrust."""
    import dataclasses

    from aerobat.plants.fpv.params import BetaflightParams

    base = BetaflightParams()
    params = dataclasses.replace(base, airframe=dataclasses.replace(base.airframe, battery_reference_v=23.69))
    sagging = replay_log(ROMA, index=3, window_s=(20.0, 24.0), params=params)
    constant = replay_log(ROMA, index=3, window_s=(20.0, 24.0), params=params, battery=False)
    assert sagging.battery.startswith("thrust × (V/23.69 V)²") and "battery_reference_v" in sagging.battery
    assert constant.battery == "not followed (as asked)"
    low, high = (float(x) for x in sagging.battery.split(": ")[1].split(",")[0].split("–"))
    assert 0.4 < low < high < 1.0  # the battery never reaches the reference in this flight
    assert not np.allclose(sagging.gyro_sim, constant.gyro_sim)
    own = replay_log(ROMA, index=3, window_s=(20.0, 24.0))  # the default airframe: the log's own median
    assert "the log's median in flight" in own.battery
