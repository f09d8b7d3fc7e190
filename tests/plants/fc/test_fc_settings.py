"""``--fc FILE``: the room's settings file as docs/real-vehicle.md shows it, read as the plant reads it."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from aerobat.errors import ConfigError
from aerobat.plants.fc.settings import FC_SETTLE_TIMEOUT_S, LinkKind, fc_params, load_fc

DOC = Path(__file__).resolve().parents[3] / "docs" / "real-vehicle.md"


def _room_toml() -> str:
    """The TOML block docs/real-vehicle.md introduces as `room.toml`."""
    match = re.search(r"`room\.toml`:\s*```toml\n(.*?)```", DOC.read_text(), re.S)
    assert match, "docs/real-vehicle.md shows no room.toml"
    return match.group(1)


def test_the_documented_room_file_reads_and_keeps_the_wall_clocks_settle_time(tmp_path):
    path = tmp_path / "room.toml"
    path.write_text(_room_toml())
    settings = load_fc(path)
    assert settings.link.kind is LinkKind.SERIAL and settings.link.port == "/dev/ttyACM0"
    assert settings.mocap.system == "vicon" and settings.limits.fence_z_m == (-0.1, 3.0)
    assert settings.betaflight.pilot.vehicle_mass_kg == 0.75
    # a [betaflight.pilot] table that does not name the settle time keeps the wall clock's, not lockstep's
    assert settings.betaflight.pilot.settle_timeout_s == FC_SETTLE_TIMEOUT_S


def test_a_settle_time_given_in_the_file_is_kept(tmp_path):
    path = tmp_path / "room.toml"
    path.write_text(_room_toml() + "settle_timeout_s = 12.5\n")  # the block ends inside [betaflight.pilot]
    assert load_fc(path).betaflight.pilot.settle_timeout_s == 12.5
    assert fc_params().pilot.settle_timeout_s == FC_SETTLE_TIMEOUT_S


def test_a_bad_field_in_the_room_file_names_the_file_and_the_field(tmp_path):
    path = tmp_path / "room.toml"
    path.write_text(_room_toml().replace("latency_s = 0.005", "latency_s = 0.5"))
    with pytest.raises(ConfigError, match=r"room\.toml.*latency_s"):
        load_fc(path)


def test_the_command_line_refuses_a_bad_room_file_in_one_line_before_anything_flies(tmp_path, capsys):
    from aerobat.cli import main

    path = tmp_path / "room.toml"
    path.write_text(_room_toml().replace('kind = "serial"', 'kind = "radio"'))
    code = main(["learn", "flip", "--flips", "1", "--dims", "2", "--plant", "fc", "--fc", str(path),
                 "--trials", "1", "--db", str(tmp_path / "s.sqlite"), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert code != 0 and len(err.splitlines()) == 1, err
    assert "room.toml" in err and "kind" in err and "'rehearsal', 'serial'" in err, err
    assert code == 2 and not (tmp_path / "out").exists() and not (tmp_path / "s.sqlite").exists()
