"""Blackbox headers and frames an adversary wrote (issue 45 E4, E5, E6, E9): refused in one line, in bounded time
and memory, and a Ctrl-C stops any decode.

Each file is a real log (../shared/data/flight-logs) with one header line changed, written to a temporary folder;
a clone without the shared logs skips these tests.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from aerobat.cli import main

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "flight-logs" / "betaflight"
ZEEZ = DATA / "zeezf7-short.bbl"
pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"the real flight logs are not here ({DATA} is absent)")
SRC = Path(__file__).resolve().parents[2] / "src"


def _crafted(tmp_path: Path, line: bytes, replacement: bytes, name: str = "crafted.bbl") -> Path:
    data = ZEEZ.read_bytes()
    assert line in data
    path = tmp_path / name
    path.write_bytes(data.replace(line, replacement))
    return path


def _one_line(capsys, argv: list[str], *words: str) -> str:
    code = main(argv)
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("aerobat: error: "), (code, captured.err[-2000:])
    assert all(w in err[0] for w in words), err[0]
    return err[0]


@pytest.mark.parametrize("line,replacement,name", [
    (b"H I interval:256\n", b"H I interval:2000000000\n", "I interval"),
    (b"H I interval:256\n", b"H I interval:0\n", "I interval"),
    (b"H P interval:16\n", b"H P interval:1/2000000000\n", "P interval"),
    (b"H P interval:16\n", b"H P interval:-1\n", "P interval"),
    (b"H P interval:16\n", b"H P interval:nan\n", "P interval"),
    (b"H minthrottle:1070\n", b"H minthrottle:" + b"9" * 30 + b"\n", "minthrottle"),
    (b"H motorOutput:158,2047\n", b"H motorOutput:" + b"9" * 30 + b",2047\n", "motorOutput"),
    (b"H Data version:2\n", b"H Data version:" + b"9" * 30 + b"\n", "Data version"),
    (b"H vbatref:2466\n", b"H vbatref:-5\n", "vbatref"),
    (b"H Field I encoding:1,1,", b"H Field I encoding:1," + b"9" * 30 + b",", "Field I encoding"),
    (b"H Field I predictor:0,0,", b"H Field I predictor:0,-3,", "Field I predictor"),
    (b"H Field I signed:0,0,", b"H Field I signed:0,2,", "Field I signed"),
    (b"H acc_1G:2048\n", b"H acc_1G:abc\n", "acc_1G"),
    (b"H acc_1G:2048\n", b"H acc_1G:\n", "acc_1G"),
], ids=lambda x: x if isinstance(x, str) else None)
def test_a_header_number_out_of_betaflights_range_is_one_line_naming_it(tmp_path, capsys, line, replacement, name):
    # E6: these were OverflowError / ValueError (exit 70), or accepted (I interval 2e9 with P interval 1/2e9 hung)
    path = _crafted(tmp_path, line, replacement)
    _one_line(capsys, ["log", "info", str(path)], str(path), "log 1", f"header field 'H {name}'", "allowed")


@pytest.mark.parametrize("value", [b"0", b"nan", b"inf", b"-2048"])
def test_an_accelerometer_scale_of_zero_or_not_finite_is_refused_before_anything_is_written(tmp_path, capsys,
                                                                                          value):
    # E9: acc_1G 0 wrote ±inf specific force with numpy warnings and exit 0
    path = _crafted(tmp_path, b"H acc_1G:2048\n", b"H acc_1G:" + value + b"\n")
    out = tmp_path / "out.csv"
    _one_line(capsys, ["log", "export", str(path), "--index", "2", "--output", str(out)], "header field 'H acc_1G'",
              "allowed an integer from 1 to 65535")
    assert not out.exists()


def test_duplicated_and_too_many_field_names_are_refused(tmp_path, capsys):
    path = _crafted(tmp_path, b"accSmooth[1],", b"accSmooth[0],")
    _one_line(capsys, ["log", "info", str(path)], "header field 'H Field I name'", "'accSmooth[0]' is named twice")
    names = ["loopIteration", "time", *(f"f{i}" for i in range(2, 10_000))]
    path = tmp_path / "wide.bbl"
    lines = ["Product:Blackbox flight data recorder by Nicholas Sherlock", "Data version:2",
             "Field I name:" + ",".join(names)]
    path.write_bytes("".join(f"H {x}\n" for x in lines).encode() + b"I" * 1000)
    _one_line(capsys, ["log", "info", str(path)], "header field 'H Field I name'", "at most 128 fields")


def test_the_p_frame_skip_in_closed_form_is_betaflights_loop():
    # E4: the loop ran up to P-interval-denominator times per P frame (for ever, in effect, at 2e9)
    from aerobat.logs.blackbox_kernel import skipped_iterations

    def loop(last: int, interval: int, num: int, denom: int) -> int:
        index = last + 1
        while not (index % interval + num - 1) % denom < num:
            index += 1
        return index - last - 1

    rng = random.Random(45)
    cases = [(rng.randrange(0, 100_000), rng.choice([1, 2, 3, 32, 128, 256, 1000]), rng.randrange(1, 40),
              rng.randrange(1, 300)) for _ in range(3000)]
    cases += [(7, 256, 1, 16), (255, 256, 1, 16), (0, 1, 1, 1), (31, 32, 1, 2), (10, 32, 5, 3)]
    for case in cases:
        assert skipped_iterations(*case) == loop(*case), case


def _header(fields: list[str], predictor: str, encoding: str) -> bytes:
    n = len(fields)
    lines = ["Product:Blackbox flight data recorder by Nicholas Sherlock", "Data version:2", "I interval:32",
             "P interval:1", "Field I name:" + ",".join(fields), "Field I signed:" + ",".join(["0"] * n),
             "Field I predictor:" + ",".join([predictor] * n), "Field I encoding:" + ",".join([encoding] * n),
             "Field P predictor:" + ",".join([predictor] * n), "Field P encoding:" + ",".join([encoding] * n)]
    return "".join(f"H {x}\n" for x in lines).encode()


def _peak_rss_mb(argv: list[str]) -> tuple[int, float]:
    """(exit status, peak resident memory [MB]) of ``aerobat ARGV`` run alone in a fresh process."""
    probe = ("import resource, subprocess, sys; code = subprocess.run(sys.argv[1:]).returncode; "
             "print(code, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024)")
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    done = subprocess.run([sys.executable, "-c", probe, sys.executable, "-m", "aerobat", *argv], env=env,
                          capture_output=True, text=True, timeout=300)
    code, peak = done.stdout.split()[-2:]
    return int(code), float(peak)


def test_a_megabyte_of_frames_takes_memory_bounded_by_the_file(tmp_path):
    # E5: 102 fields of the increment predictor, then 10^6 one-byte I frames, took 1.8 GB (the decoder sized its
    # table as file length x fields x 8 bytes and copied it twice); the bound is 300 MB + 20 x the file
    names = ["loopIteration", "time", *(f"f{i}" for i in range(2, 102))]
    path = tmp_path / "frames.bbl"
    path.write_bytes(_header(names, "6", "1") + b"I" * 1_000_000)
    code, peak = _peak_rss_mb(["log", "info", str(path)])
    assert code == 0 and peak <= 300 + 20 * path.stat().st_size / 2**20, peak


def test_a_log_whose_frames_take_no_bytes_is_refused_when_they_outgrow_the_file(tmp_path, capsys):
    # the same, with the fields the reader keeps (gyro, motors, ...) and P frames one byte each (every field
    # incremented): a million of them would be 100 MB from 1 MB; refused once they pass 16 times the log's bytes
    from aerobat.logs.betaflight import FIELDS

    names = ["loopIteration", *FIELDS]
    path = tmp_path / "empty-frames.bbl"
    path.write_bytes(_header(names, "6", "1") + b"I" + b"P" * 200_000)
    _one_line(capsys, ["log", "info", str(path)], "log 1", "main frames of 36 fields", "one every 1.0 bytes",
              "would decode to more than 16 times the log's 200,001 bytes", "allowed frames of 18 bytes or more")
    code, peak = _peak_rss_mb(["log", "info", str(path)])
    assert code == 2 and peak <= 300 + 20 * path.stat().st_size / 2**20, peak


@pytest.mark.skipif(sys.platform != "linux", reason="POSIX signals")
def test_ctrl_c_during_a_long_decode_stops_within_a_second_with_exit_130(tmp_path):
    # E4: the compiled decoder ran for ever and ignored SIGINT. Every other byte here starts a frame that runs
    # 256 bytes and is dropped (the slowest input known, ~0.4 µs a byte: 32 MB take ~13 s to decode)
    from aerobat.logs.blackbox_decode import warm_up

    warm_up()  # the subprocess loads the kernel from the cache, not compiling it
    names = ["loopIteration", "time", *(f"f{i}" for i in range(2, 128))]
    path = tmp_path / "slow.bbl"
    path.write_bytes(_header(names, "0", "0") + b"I\xff" * 16_000_000)
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    process = subprocess.Popen([sys.executable, "-m", "aerobat", "log", "info", str(path)], env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        time.sleep(4.0)  # start-up and loading the kernel take ~1.5 s: the decode is under way
        assert process.poll() is None, process.communicate()
        process.send_signal(signal.SIGINT)
        sent = time.perf_counter()
        out, err = process.communicate(timeout=30)
        waited = time.perf_counter() - sent
    finally:
        process.kill()
    assert process.returncode == 130 and err.strip() == "aerobat: interrupted", (process.returncode, err[-2000:])
    assert waited < 1.0, waited
