"""Damaged Crazyflie and ULog files, and what the log commands print about them (issue 45 E6, E9, E10, E13).

Each file is a real log (../shared/data/flight-logs) with a few bytes changed, written to a temporary folder;
a clone without the shared logs skips these tests.
"""

from __future__ import annotations

import dataclasses
import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest

from aerobat.cli import main
from aerobat.logs import Channel, read_log

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "flight-logs"
pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"the real flight logs are not here ({DATA} is absent)")
CF = DATA / "crazyflie" / "log16"
CF10 = DATA / "crazyflie" / "log10"
PX4 = DATA / "px4" / "auav-x21-quad.ulg"
RECORD = 50  # bytes of a record of the shared Crazyflie logs: id, timestamp, 6 floats, 4 uint32


def _no_constant(text: str) -> None:
    raise ValueError(f"not JSON: {text}")


def strict_json(text: str) -> object:
    """``text`` parsed as JSON that any parser reads: NaN and Infinity refused."""
    return json.loads(text, parse_constant=_no_constant)


def _records(path: Path) -> tuple[bytes, np.ndarray]:
    data = path.read_bytes()
    start = data.index(b"motor.m4(I)\x00") + len(b"motor.m4(I)\x00")
    n = (len(data) - start) // RECORD
    return data[:start], np.frombuffer(data[start: start + n * RECORD], dtype=np.uint8).reshape(n, RECORD).copy()


def _write(tmp_path: Path, name: str, head: bytes, records: np.ndarray) -> Path:
    path = tmp_path / name
    path.write_bytes(head + records.tobytes())
    return path


def _one_line(capsys, argv: list[str], *words: str) -> None:
    code = main(argv)
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("aerobat: error: "), (code, captured.err[-2000:])
    assert all(w in err[0] for w in words), err[0]
    assert captured.out == "", captured.out


def test_a_crazyflie_variable_declared_twice_is_one_line_and_exit_2(tmp_path, capsys):
    # E6: ValueError "field 'acc.x' occurs more than once" (exit 70)
    head, records = _records(CF)
    path = _write(tmp_path, "twice", head.replace(b"acc.y(f)", b"acc.x(f)"), records)
    _one_line(capsys, ["log", "info", str(path)], str(path), "header field 'acc.x(f)'", "declared twice",
              "allowed each variable name once")


@pytest.mark.parametrize("name", [b"t", b"id"])
def test_a_crazyflie_variable_named_t_or_id_is_read_as_any_other(tmp_path, name):
    # E6: these collided with the record's own columns (exit 70). The uSD deck writes group.name, but older
    # decks wrote `tick(I)` without a group: a name without one is a variable like any other
    head, records = _records(CF)
    path = _write(tmp_path, name.decode(), head.replace(b"acc.y(f)", name + b"(f)"), records)
    log = read_log(path)
    assert log.duration_s == pytest.approx(46.7, abs=0.1) and log.signal(Channel.GYRO).samples == len(records)
    assert not log.has(Channel.SPECIFIC_FORCE)  # acc.y is gone: no accelerometer vector
    assert f"{name.decode()}(f)" in log.metadata.parameters["variables"]


@pytest.mark.parametrize("record,bit", [(1000, 40), (-1, 40), (0, 40), (0, 63), (1, 24), (500, 10), (-2, 12)])
def test_one_flipped_bit_in_a_crazyflie_timestamp_costs_one_record_at_most_and_says_which(tmp_path, record, bit):
    # E9: a flipped bit 40 in the last timestamp made the 46.7 s log last 1,099,558 s with no note
    head, records = _records(CF)
    at = record % len(records)
    records[at, 2 + bit // 8] ^= 1 << (bit % 8)  # the uint64 timestamp: bytes 2-9
    log = read_log(_write(tmp_path, "flipped", head, records))
    assert log.duration_s == pytest.approx(46.7, abs=0.1)
    notes = [n for n in log.notes if "timestamp" in n]
    assert log.signal(Channel.GYRO).samples == len(records) - len(notes)
    if bit >= 24:  # 16.8 s or more: always out of step
        assert len(notes) == 1 and notes[0].startswith("1 record left out") and f"record {at} at " in notes[0], notes
    if notes:
        assert notes[0].startswith("1 record left out") and "numbered from 0" in notes[0], notes


def test_a_crazyflie_record_with_a_damaged_event_id_costs_only_itself(tmp_path):
    head, records = _records(CF)
    records[100, 0] ^= 0x04
    log = read_log(_write(tmp_path, "badid", head, records))
    assert log.signal(Channel.GYRO).samples == len(records) - 1
    assert any(n.startswith("1 record with an unknown event id left out (record 100;") for n in log.notes), log.notes


def test_nan_and_infinite_crazyflie_values_are_counted_in_the_notes(tmp_path):
    # E9: they passed without a note
    head, records = _records(CF)
    nan = np.frombuffer(struct.pack("<f", math.nan), dtype=np.uint8)
    records[2000:2500, 10:14] = nan  # acc.x
    records[3000, 14:18] = np.frombuffer(struct.pack("<f", math.inf), dtype=np.uint8)  # acc.y
    log = read_log(_write(tmp_path, "nan", head, records))
    assert f"acc.x holds 500 of {len(records)} values NaN or infinite (kept as read)" in log.notes
    assert f"acc.y holds 1 of {len(records)} values NaN or infinite (kept as read)" in log.notes


@pytest.mark.parametrize("damage,words", [
    ("nan", "the motors spin for 35.8 s, but the gyro or specific force is NaN or infinite in every one"),
    ("impact", "the motors spin for 35.8 s, but the specific force is above 12 g"),
])
def test_identify_says_why_a_flight_whose_motors_spin_cannot_be_fitted(tmp_path, capsys, damage, words):
    # E9: it said "the motors never spin ... did not fly" about a flight whose motors spin
    head, records = _records(CF10)
    value = math.nan if damage == "nan" else 50.0  # acc.z: NaN, or 50 g
    records[:, 18:22] = np.frombuffer(struct.pack("<f", value), dtype=np.uint8)
    path = _write(tmp_path, damage, head, records)
    _one_line(capsys, ["identify", "--log", str(path), "--output", str(tmp_path / "v.toml")], str(path), words)
    assert not (tmp_path / "v.toml").exists()


def test_identify_refuses_a_vtol_ulog_in_one_line_and_nothing_else(tmp_path, capsys):
    # E13: "identifying from ... mass 0.468 kg, motors at ..." came before the refusal
    from pyulog import ULog

    ulog = ULog(str(PX4))
    ulog.initial_parameters["MAV_TYPE"] = 22  # the same recording, declared a VTOL
    path = tmp_path / "vtol.ulg"
    ulog.write_ulog(str(path))
    _one_line(capsys, ["identify", "--log", str(path), "--output", str(tmp_path / "v.toml")], str(path),
              "is of a VTOL, not a multirotor")


def _damaged_ulog(tmp_path: Path) -> Path:
    data = bytearray(PX4.read_bytes())
    data[200_000:260_000] = bytes(60_000)  # a block of the data section zeroed: pyulog prints warnings
    path = tmp_path / "damaged.ulg"
    path.write_bytes(bytes(data))
    return path


@pytest.mark.parametrize("command", ["info", "export", "plot"])
def test_pyulogs_warnings_on_a_damaged_ulog_become_notes_not_lines_on_stdout(tmp_path, capsys, command):
    # E10: "Warning: no subscription found ..." came first on stdout, before the JSON (and the CSV)
    path = _damaged_ulog(tmp_path)
    argv = ["log", command, str(path)]
    if command == "plot":
        argv += ["--out", str(tmp_path / "figures")]
    if command != "export":
        argv.append("--json")
    assert main(argv) == 0
    out = capsys.readouterr().out
    if command == "export":
        assert out.startswith("time_s,gyro.x[rad/s]")
        return
    document = strict_json(out)  # nothing before the JSON
    if command == "info":
        notes = document["logs"][0]["notes"]
        assert any(n.startswith("pyulog: Warning: no subscription found for message id") for n in notes), notes


def _replay_with_nothing_to_compare(window: tuple[float, float]):
    """A LogReplay of a flat second: constant series (no correlation) and no set-point step (no rise time)."""
    from aerobat.experiments.log_replay import AxisMatch, LogReplay

    n = 250
    zero = np.zeros((n, 3))
    flat = AxisMatch.of(np.zeros(n), np.zeros(n))
    assert math.isnan(flat.correlation)
    return LogReplay(log="flat.bbl#1", window_s=window, airframe="test", tune_report=None,
                     time_s=np.linspace(*window, n), setpoint_log=zero, setpoint_model=zero, setpoint_sim=zero,
                     gyro_log=zero, gyro_sim=zero, motors_log=np.zeros((n, 4)), motors_sim=np.zeros((n, 4)),
                     pid_log=np.zeros((n, 4, 3)), pid_sim=np.zeros((n, 4, 3)), setpoint=(flat,) * 3,
                     setpoint_curve=(flat,) * 3, pid=((flat,) * 3,) * 4, gyro=(flat,) * 3, tracking=(flat,) * 3,
                     motors=(flat,) * 4, steps=(), wall_s=1.0, lockstep_steps=1000)


def test_log_replay_json_writes_null_where_a_number_does_not_exist(tmp_path, capsys, monkeypatch):
    # E10: `log replay ... --json` printed NaN (rise times with no step, correlations of constant series)
    import aerobat.experiments.log_replay as log_replay

    def replay(file, *, window_s, **kwargs):
        return _replay_with_nothing_to_compare(window_s)

    monkeypatch.setattr(log_replay, "replay_log", replay)
    assert main(["log", "replay", "flat.bbl", "--window-s", "22", "23", "--out", str(tmp_path), "--json"]) == 0
    summary = strict_json(capsys.readouterr().out)
    assert summary["steps"]["roll"] == {"steps": 0.0, "rise_log_s": None, "rise_sim_s": None, "overshoot_log": None,
                                        "overshoot_sim": None}
    assert summary["gyro"]["pitch"]["correlation"] is None and summary["gyro"]["pitch"]["rms"] == 0.0


def test_the_json_of_every_log_command_is_strict_json():
    from aerobat.cli.json_output import json_ready, json_text

    @dataclasses.dataclass
    class Row:
        value: float

    text = json_text({"a": math.nan, "b": [np.float32(math.inf), np.int64(3), np.bool_(True)], "c": (Row(-math.inf),),
                      "d": np.array([1.5, math.nan]), "e": Path("x")})
    assert strict_json(text) == {"a": None, "b": [None, 3, True], "c": [{"value": None}], "d": [1.5, None], "e": "x"}
    with pytest.raises(TypeError):
        json_ready(object())


@pytest.mark.slow  # the Betaflight SITL flies the second (~50 s)
def test_log_replay_json_of_a_real_second_is_strict_json(tmp_path, capsys):
    roma = DATA / "betaflight" / "diatone-roma-f5.bbl"
    assert main(["log", "replay", f"{roma}:1", "--window-s", "22", "23", "--out", str(tmp_path), "--json"]) == 0
    summary = strict_json(capsys.readouterr().out)
    assert summary["window_s"] == [22.0, 23.0]


def test_identify_log_json_that_fails_says_one_line_on_stderr(tmp_path, capsys):
    # the fuzz campaign's logs phase: `identify --log ... --json` printed its progress line on stderr (stdout
    # carries the JSON), so a fit that failed said two lines there
    zeez = DATA / "betaflight" / "zeezf7-short.bbl"
    path = tmp_path / "idle0.bbl"
    path.write_bytes(zeez.read_bytes().replace(b"H motorOutput:158,2047\n", b"H motorOutput:0,0\n"))
    code = main(["identify", "--log", f"{path}:2", "--output", str(tmp_path / "v.toml"), "--json"])
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert code == 1 and len(err) == 1 and err[0].startswith("aerobat: failed: idle0.bbl#2: the motors do not "
                                                              "explain"), captured.err
    assert captured.out == ""
