"""The ``aerobat simulate`` command."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from aerobat.cli import main
from aerobat.quadrotor.program import load_program
from aerobat.quadrotor.simulate import simulate
from aerobat.quadrotor.vehicle import (
    ControllerParams,
    VehicleConfig,
    VehicleParams,
    hummingbird,
    save_vehicle,
)

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
SINGLE = str(EXAMPLES / "single_flip.toml")
TRIPLE = str(EXAMPLES / "triple_flip_1800.toml")


def _run_json(capsys, *argv: str) -> dict:
    code = main(["simulate", *argv, "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert err == ""
    return json.loads(out)


def _assert_one_line_error(capsys, code: int, *fragments: str) -> str:
    out, err = capsys.readouterr()
    assert code == 2
    assert out == ""
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("aerobat: error: "), err
    assert "Traceback" not in err
    for fragment in fragments:
        assert fragment in lines[0], err
    return lines[0]


def test_json_summary_of_single_flip(capsys):
    data = _run_json(capsys, SINGLE)
    assert set(data) == {"duration_s", "final_state"}
    fs = data["final_state"]
    assert set(fs) == {"position_m", "velocity_m_s", "euler_zyx_rad", "rotation_angle_rad"}
    for key in fs:
        assert len(fs[key]) == 3 and all(isinstance(v, float) and math.isfinite(v) for v in fs[key])
    program = load_program(SINGLE)
    assert data["duration_s"] == program.duration_s
    # the numbers are the simulator's, not rounded
    final = simulate(program, hummingbird()).final_state
    assert fs["position_m"] == final[0:3].tolist()
    assert fs["velocity_m_s"] == final[3:6].tolist()
    assert fs["rotation_angle_rad"][0] == pytest.approx(2 * math.pi, abs=0.01)


def test_json_triple_flip_rotation_is_six_pi(capsys):
    fs = _run_json(capsys, TRIPLE)["final_state"]
    assert fs["rotation_angle_rad"][0] == pytest.approx(6 * math.pi, abs=0.1)
    assert abs(fs["euler_zyx_rad"][0]) < 0.1


def test_sampled_mode_option(capsys):
    cont = _run_json(capsys, SINGLE)["final_state"]["position_m"]
    samp = _run_json(capsys, SINGLE, "--mode", "sampled")["final_state"]["position_m"]
    diff = np.linalg.norm(np.subtract(cont, samp))
    assert 0.0 < diff < 0.01  # measured 3.95e-3 m


def test_vehicle_file_option(capsys, tmp_path):
    heavy = VehicleParams(mass_kg=0.5)
    path = tmp_path / "heavy.toml"
    save_vehicle(
        VehicleConfig(vehicle=heavy, controller=ControllerParams.nominal_for(heavy), name="heavy"),
        path,
    )
    hb = _run_json(capsys, SINGLE)["final_state"]["position_m"]
    hv = _run_json(capsys, SINGLE, "--vehicle", str(path))["final_state"]["position_m"]
    assert hb != hv
    assert _run_json(capsys, SINGLE, "--vehicle", "hummingbird")["final_state"]["position_m"] == hb


def test_table_output(capsys):
    assert main(["simulate", SINGLE]) == 0
    out, err = capsys.readouterr()
    assert err == ""
    assert "on hummingbird" in out and "(continuous)" in out
    assert "+360.00" in out  # unwrapped roll in degrees
    assert "duration: 0.9390 s" in out


def test_table_output_shows_units(capsys):
    assert main(["simulate", SINGLE]) == 0
    out, _ = capsys.readouterr()
    assert "position [m]" in out
    assert "velocity [m/s]" in out


def test_plot_writes_png(capsys, tmp_path):
    png = tmp_path / "flip.png"
    data = _run_json(capsys, SINGLE, "--plot", str(png))  # stdout stays pure JSON
    assert data["final_state"]["rotation_angle_rad"][0] == pytest.approx(2 * math.pi, abs=0.01)
    blob = png.read_bytes()
    assert blob[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(blob) > 5000


def test_plot_without_json_reports_the_file(capsys, tmp_path):
    png = tmp_path / "hover.png"
    assert main(["simulate", str(EXAMPLES / "hover.toml"), "--plot", str(png)]) == 0
    out, _ = capsys.readouterr()
    assert f"figure written to {png}" in out
    assert png.read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize(
    ("text", "fragments"),
    [
        (
            "[program]\nduration_s = 1.0\n"
            '[[switch]]\ntime_s = -0.5\nchannel = "rate_p"\nvalue = 1.0\n',
            ["switch 0 (rate_p)", "time_s = -0.5"],
        ),
        (
            '[program]\nduration_s = 1.0\n[[switch]]\ntime_s = 0.5\nchannel = "yaw"\nvalue = 1.0\n',
            ["switch 0", "unknown channel 'yaw'"],
        ),
        ("[program]\nduration_s = nan\n", ["duration_s = nan"]),
        ('[program]\nname = "x"\n', ["missing required field duration_s"]),
        ("[program\n", ["invalid TOML"]),
    ],
)
def test_bad_program_file_exits_2_with_one_line(capsys, tmp_path, text, fragments):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    code = main(["simulate", str(path), "--json"])
    _assert_one_line_error(capsys, code, str(path), *fragments)


def test_missing_program_file_exits_2(capsys, tmp_path):
    path = tmp_path / "missing.toml"
    code = main(["simulate", str(path)])
    _assert_one_line_error(capsys, code, str(path), "file not found")


def test_bad_vehicle_exits_2(capsys, tmp_path):
    path = tmp_path / "v.toml"
    path.write_text("[vehicle]\nmass_kg = -1.0\n")
    _assert_one_line_error(
        capsys, main(["simulate", SINGLE, "--vehicle", str(path)]), str(path), "mass_kg"
    )
    _assert_one_line_error(
        capsys, main(["simulate", SINGLE, "--vehicle", "blimp"]), "unknown vehicle 'blimp'"
    )


def test_unwritable_plot_path_exits_2(capsys, tmp_path):
    (tmp_path / "no").write_text("a file, where the path needs a folder")
    target = tmp_path / "no" / "such" / "dir" / "x.png"
    _assert_one_line_error(capsys, main(["simulate", SINGLE, "--plot", str(target)]), str(target))


def test_a_plot_path_in_missing_folders_makes_them(capsys, tmp_path):
    """Issue 44: outputs make their parent folders, as --out DIR does."""
    target = tmp_path / "new" / "folders" / "x.png"
    assert main(["simulate", SINGLE, "--plot", str(target)]) == 0
    assert target.stat().st_size > 0


def test_debug_flag_shows_the_exception(tmp_path, capsys):
    """--debug prints the traceback and keeps the status of bad input, 2 (issue 31 E1)."""
    assert main(["--debug", "simulate", str(tmp_path / "missing.toml")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" in err and "ConfigError" in err and err.rstrip().endswith("file not found")


@pytest.mark.parametrize(
    ("argv", "fragment"),
    [
        (["simulate"], "the following arguments are required: program"),
        (["simulate", SINGLE, "--mode", "discrete"], "invalid choice: 'discrete'"),
    ],
)
def test_usage_errors_exit_2(capsys, argv, fragment):
    assert main(argv) == 2  # main() returns the status; it never raises SystemExit
    _assert_one_line_error(capsys, 2, fragment)
