"""aerobat's blackbox decoder against orangebox 0.4.0 (the reference) on every shared log, and on damaged files.

The shared logs are at ../shared/data/flight-logs (a clone without them skips these tests).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from aerobat.cli import main
from aerobat.errors import ConfigError
from aerobat.logs import Channel, read_logs
from aerobat.logs.betaflight import quiet_orangebox, raw_headers
from aerobat.logs.blackbox_decode import decode_blackbox, header_end, log_starts

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "flight-logs" / "betaflight"
pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"the real flight logs are not here ({DATA} is absent)")
LOGS = [("diatone-roma-f5.bbl", 1), ("diatone-roma-f5.bbl", 2), ("diatone-roma-f5.bbl", 3),
        ("zeezf7-short.bbl", 1), ("zeezf7-short.bbl", 2), ("aikonf7-gecko.bbl", 1)]


def _ours(data: bytes, index: int):
    starts = log_starts(data)
    end = starts[index] if index < len(starts) else len(data)
    return decode_blackbox(data, starts[index - 1], end, raw_headers(data, starts[index - 1]), f"log {index}")


def _reference(path: Path, index: int, fields: int) -> np.ndarray:
    pytest.importorskip("orangebox")
    from orangebox import Parser
    from orangebox.reader import Reader

    with quiet_orangebox():
        reader = Reader(str(path))
        reader.set_log_index(index)
        rows = [frame.data[:fields] for frame in Parser(reader).frames()]
    return np.array(rows, dtype=np.int64)


@pytest.mark.parametrize("name,index", LOGS, ids=[f"{n}#{i}" for n, i in LOGS])
def test_main_frames_are_orangebox_s_bit_for_bit(name, index):
    path = DATA / name
    ours = _ours(path.read_bytes(), index)
    reference = _reference(path, index, len(ours.names))
    assert ours.log_end and ours.corrupt_frames == 0 and ours.notes() == []
    if name != "aikonf7-gecko.bbl":
        assert ours.main.shape == reference.shape
        assert np.array_equal(ours.main, reference)
        return
    # The Gecko log's data starts with a LOGGING_RESUME event, not an I frame. orangebox 0.4.0
    # reads the header up to the first newline byte, so it starts inside the first frames, loses the
    # I frame at iteration 4608 and its 15 P frames, and decodes 14 P frames against an empty history
    # (times of -131 µs and so on). From the next I frame (iteration 4864) on, the two agree.
    assert reference.shape == (66638, 34) and ours.main.shape == (66640, 34)
    assert (reference[:14, 1] < 0).all()
    assert np.array_equal(ours.main[16:], reference[14:])
    assert ours.events[0].tolist() == [0, 14, 4608, 17433272]     # resume: iteration, time [µs]
    assert ours.main[0, :2].tolist() == [4608, 17433272]
    assert np.array_equal(ours.main[:17, 0], 4608 + 16 * np.arange(17))
    assert (np.diff(ours.main[:, 1]) > 0).all()
    # 500 main frames a second (8 kHz loop, P interval 16), for 133.8 s: not the 151 s since power-on
    span = (ours.main[-1, 1] - ours.main[0, 1]) * 1e-6
    assert span == pytest.approx(133.8, abs=0.1) and len(ours.main) / span == pytest.approx(500, rel=0.01)


def test_the_gecko_flight_log_is_133_8_s_at_500_hz():
    (log,) = read_logs(DATA / "aikonf7-gecko.bbl")
    assert log.duration_s == pytest.approx(133.8, abs=0.2)
    assert log.signal(Channel.GYRO).samples == 66640
    assert not any("out of time order" in n for n in log.notes)


def test_a_corrupted_log_resynchronises_and_keeps_the_rest(tmp_path):
    data = bytearray((DATA / "zeezf7-short.bbl").read_bytes())
    clean = _ours(bytes(data), 2)
    rng = np.random.default_rng(3)
    start = log_starts(bytes(data))[1] + 5000
    for at in rng.integers(start, len(data) - 1000, 25):
        data[at] ^= 0xA5
    damaged = _ours(bytes(data), 2)
    assert damaged.corrupt_frames + damaged.rejected_frames > 0
    assert any("corrupt" in n or "left out" in n for n in damaged.notes())
    assert 0.9 * len(clean.main) < len(damaged.main) < len(clean.main)
    by_iteration = {int(r[0]): r for r in clean.main}
    same = sum(int(r[0]) in by_iteration and np.array_equal(r, by_iteration[int(r[0])]) for r in damaged.main)
    assert same / len(damaged.main) > 0.99
    path = tmp_path / "damaged.bbl"
    path.write_bytes(bytes(data))
    logs = read_logs(path)
    assert len(logs) == 2 and any("corrupt" in n or "left out" in n for n in logs[1].notes)


def test_a_truncated_log_keeps_every_frame_before_the_cut(tmp_path):
    data = (DATA / "zeezf7-short.bbl").read_bytes()
    clean = _ours(data, 2)
    cut = data[: len(data) - 200_001]
    truncated = _ours(cut, 2)
    n = len(truncated.main)
    assert 0.5 * len(clean.main) < n < len(clean.main)
    assert np.array_equal(truncated.main, clean.main[:n])
    assert not truncated.log_end and any("no end-of-log event" in x for x in truncated.notes())
    path = tmp_path / "cut.bbl"
    path.write_bytes(cut)
    assert main(["log", "info", str(path)]) == 0


def _one_error_line(capsys, path: Path, *words: str) -> None:
    code = main(["log", "info", str(path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and str(path) in err[0], err
    assert all(w in err[0] for w in words), err


def test_a_log_with_a_header_and_no_frames_is_one_line_and_exit_2(tmp_path, capsys):
    data = (DATA / "zeezf7-short.bbl").read_bytes()
    path = tmp_path / "header-only.bbl"
    path.write_bytes(data[: header_end(data, 0)])
    with pytest.raises(ConfigError, match="holds no frames"):
        read_logs(path)
    _one_error_line(capsys, path, "log 1", "holds no frames")


def test_an_encoding_the_decoder_does_not_read_is_one_line_and_exit_2(tmp_path, capsys):
    data = (DATA / "zeezf7-short.bbl").read_bytes()
    path = tmp_path / "elias.bbl"
    path.write_bytes(data.replace(b"H Field P encoding:9,0,", b"H Field P encoding:9,4,", 1))
    _one_error_line(capsys, path, "header field 'H Field P encoding'", "field 'time': '4'", "allowed")


def test_an_empty_file_is_one_line_and_exit_2(tmp_path, capsys):
    path = tmp_path / "empty.bbl"
    path.write_bytes(b"")
    _one_error_line(capsys, path, "empty")


def test_the_encodings_no_shared_log_uses():
    from aerobat.logs import blackbox_kernel as k

    values = np.zeros(8, dtype=np.int64)
    # tag2_3svariable, 5/5/4 bits: 01 00011 1 | 0010 1001 -> 3, 0b10010 = -14, 0b1001 = -7
    data = np.array([0b01000111, 0b00101001], dtype=np.uint8)
    assert k._tag2_3svariable(data, 0, 2, values) == 2 and values[:3].tolist() == [3, -14, -7]
    # 8/7/7 bits: 10 111111 | 11 000001 | 0 1111111 -> 0b11111111 = -1, 0b0000010 = 2, 0b1111111 = -1
    data = np.array([0b10111111, 0b11000001, 0b01111111], dtype=np.uint8)
    assert k._tag2_3svariable(data, 0, 3, values) == 3 and values[:3].tolist() == [-1, 2, -1]
    # tag8_4s16 of data version 1: 4-bit pairs low nibble first, 16 bits little-endian
    data = np.array([0b11_00_01_01, 0x7E, 0x34, 0x12], dtype=np.uint8)
    assert k._tag8_4s16(data, 0, 4, values, 1) == 4 and values[:4].tolist() == [-2, 7, 0, 0x1234]
    # zig-zag signed VB: 0x81 0x01 = 129 -> -65
    assert k._signed_vb(np.array([0x81, 0x01], dtype=np.uint8), 0, 2) == (-65, 2)
    # past the end of the data a read returns 0 and the position passes the end (the frame is dropped)
    assert k._unsigned_vb(np.array([0x80], dtype=np.uint8), 0, 1)[1] > 1


def test_the_warm_up_log_decodes_to_its_two_frames():
    from aerobat.logs.blackbox_decode import warm_up

    frames = warm_up()
    # I: iteration 7, time 10000 µs (0x90 0x4e); P: iteration 8 (increment), time 10000 (a straight line
    # through the I frame twice, plus a delta of 0)
    assert frames.main.tolist() == [[7, 10000], [8, 10000]]
    assert frames.log_end and frames.notes() == []


def test_a_file_cut_in_its_last_logs_header_or_first_frame_keeps_the_logs_before_it(tmp_path, capsys):
    # the recording stopped in log 2's header or first frame: log 1 is whole and read (the whole file was refused,
    # found by the fuzz campaign's cuts), and a note says so
    data = (DATA / "zeezf7-short.bbl").read_bytes()
    second = log_starts(data)[1]
    frames = header_end(data, second)
    for cut, where in ((second + 60, "header"), (second + 2000, "header"), (frames, "header"),
                       (frames + 1, "first frame"), (frames + 20, "first frame")):
        path = tmp_path / f"cut{cut}.bbl"
        path.write_bytes(data[:cut])
        (log,) = read_logs(path)
        assert log.index == 1 and log.logs_in_file == 1 and log.signal(Channel.GYRO).samples > 90
        assert log.notes[-1].startswith(f"the file ends in the {where} of a log after this one (log 2, at byte "
                                        f"{second})"), (cut, log.notes[-1])
    path = tmp_path / "only-header.bbl"
    path.write_bytes(data[second: second + 2000])  # a file of one log cut in its header is still refused
    _one_error_line(capsys, path, "log 1")
