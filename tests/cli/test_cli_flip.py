"""CLI: design, learn and fly (issues 3 and 4)."""

from __future__ import annotations

import json
import math

import pytest

from aerobat.cli import main


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_design_json_keys_and_values(capsys):
    code, out, _ = run(capsys, "design", "flip", "--flips", "3", "--max-rate-deg-s", "1800", "--dims", "2", "--json")
    assert code == 0
    data = json.loads(out)
    for key in ("parameter_names", "p_guess", "p_nominal", "residual_norm", "converged", "duration_s",
                "jacobian", "correction", "condition_number"):
        assert key in data
    assert data["parameter_names"] == ["p0", "p1", "p2", "p3", "p4"]
    assert data["converged"] is True and data["residual_norm"] < 1e-6
    assert 1.3 <= data["duration_s"] <= 1.7
    assert len(data["jacobian"]) == 5 and len(data["correction"][0]) == 5


def test_design_table(capsys):
    code, out, _ = run(capsys, "design", "flip", "--flips", "1", "--max-rate-deg-s", "800", "--dims", "2")
    assert code == 0
    assert "accelerate collective" in out and "condition number" in out


def test_infeasible_design_exits_nonzero_naming_the_limit(capsys, tmp_path):
    vehicle = tmp_path / "weak.toml"
    vehicle.write_text("[vehicle]\ncollective_reduced_max_m_s2 = 11.0\n")
    code, _, err = run(capsys, "design", "flip", "--vehicle", str(vehicle))
    assert code == 1
    assert err.startswith("aerobat: failed:") and "β̄" in err and "Traceback" not in err


def test_learn_json_and_figures(capsys, tmp_path):
    out_dir = tmp_path / "out"
    code, out, _ = run(capsys, "learn", "flip", "--flips", "1", "--max-rate-deg-s", "800", "--dims", "2",
                       "--plant", "arena", "--seed", "1", "--iterations", "4", "--out", str(out_dir), "--json",
                       "--db", str(tmp_path / "s.sqlite"))
    assert code == 0
    data = json.loads(out)
    assert data["error_names"] == ["y", "vy", "z", "vz", "flip_angle"]
    assert len([it for it in data["iterations"] if it["status"] == "ok"]) == 4
    for it in data["iterations"]:
        assert set(it) >= {"i", "status", "params", "error", "gamma", "scale"}
    assert len(data["final_params"]) == 5
    assert (out_dir / "side_views.png").stat().st_size > 10_000
    assert (out_dir / "learning.png").stat().st_size > 10_000


def test_learn_on_nominal_plant_table(capsys, tmp_path):
    code, out, _ = run(capsys, "learn", "flip", "--dims", "2", "--plant", "nominal", "--iterations", "2",
                       "--out", str(tmp_path), "--db", str(tmp_path / "s.sqlite"))
    assert code == 0
    assert "p⁰" in out and "learned" in out
    # the parameters by meaning, unit and change (issue 44: not p0…p4 alone), and what γ and scale are
    rows = {line.split()[0]: line for line in out.splitlines() if line.startswith(("p0 ", "p2 "))}
    assert "accelerate collective" in rows["p0"] and "m/s²" in rows["p0"] and "coast duration" in rows["p2"]
    assert "γ is the update's step" in out and "scale the part of it kept inside the parameters' bounds" in out


@pytest.mark.parametrize("argv, fragment", [
    (["learn", "flip", "--iterations", "0"], "--iterations"),
    (["learn", "flip", "--gamma", "2"], "--gamma"),
    (["learn", "flip", "--gamma", "fast"], "--gamma"),
    (["design", "flip", "--flips", "0"], "flips"),
    (["design", "flip", "--max-rate-deg-s", "nan"], "--max-rate-deg-s"),
    (["design", "flip", "--vehicle", "nonexistent"], "unknown vehicle"),
    (["fly", "examples/hover.toml", "--trials", "0"], "--trials"),
    (["fly", "missing.toml"], "missing.toml"),
])
def test_bad_arguments_one_line_exit_2(capsys, argv, fragment):
    code, _, err = run(capsys, *argv)
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("aerobat: error:") and fragment in err


def test_fly_arena_json(capsys):
    code, out, _ = run(capsys, "fly", "examples/triple_flip_1800.toml", "--plant", "arena", "--seed", "3",
                       "--trials", "3", "--json")
    assert code == 0
    data = json.loads(out)
    assert len(data["trials"]) == 3
    for trial in data["trials"]:
        assert trial["status"] in ("ok", "no_trigger")
        if trial["status"] == "ok":
            roll = trial["final_state"]["rotation_angle_rad"][0]
            assert 5 * math.pi < roll < 7 * math.pi


def test_fly_nominal_matches_simulate(capsys):
    _, out, _ = run(capsys, "fly", "examples/single_flip.toml", "--plant", "nominal", "--json")
    fly = json.loads(out)["trials"][0]["final_state"]
    _, out, _ = run(capsys, "simulate", "examples/single_flip.toml", "--json")
    sim = json.loads(out)["final_state"]
    assert fly["position_m"] == pytest.approx(sim["position_m"], abs=1e-12)


@pytest.mark.parametrize("rule", ["tsvd", "kalman", "broyden"])
def test_learn_with_another_rule(capsys, tmp_path, rule):
    code, out, _ = run(capsys, "learn", "flip", "--flips", "1", "--max-rate-deg-s", "800", "--dims", "2",
                       "--plant", "arena", "--seed", "2", "--iterations", "4", "--rule", rule,
                       "--db", str(tmp_path / "db.sqlite"), "--out", str(tmp_path), "--json")
    assert code == 0
    data = json.loads(out)
    assert len([it for it in data["iterations"] if it["status"] == "ok"]) == 4


def test_learn_unknown_rule_is_bad_input(capsys, tmp_path):
    code, _, err = run(capsys, "learn", "flip", "--dims", "2", "--rule", "magic", "--db", str(tmp_path / "d.sqlite"),
                       "--out", str(tmp_path))
    assert code == 2 and "magic" in err
