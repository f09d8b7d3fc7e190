"""Real flight logs: how long `aerobat log info` and `aerobat identify --log` take (issue "Real flights in").

Each figure is a whole process (interpreter, imports, reading, fitting), as a user runs it, from
the shared logs at ../shared/data/flight-logs. Wall time moves with the machine's load, so the
process's own CPU time (user + system) is given beside it, and the frame decoding alone, in-process:
aerobat's compiled decoder (:mod:`aerobat.logs.blackbox_decode`) and orangebox 0.4.0, which it
replaced (pure Python, the tests' reference). ``python benchmarks/bench_logs.py`` prints the rows.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "flight-logs"
GECKO = DATA / "betaflight" / "aikonf7-gecko.bbl"
ROMA = DATA / "betaflight" / "diatone-roma-f5.bbl"
CF15 = DATA / "crazyflie" / "log15"


def _process(argv: list[str]) -> tuple[float, float]:
    """(wall, CPU) seconds of one process running ``aerobat argv``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    subprocess.run([sys.executable, "-m", "aerobat.cli", *argv], check=True, capture_output=True, timeout=600)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _best(argv: list[str], rounds: int) -> tuple[float, float]:
    runs = [_process(argv) for _ in range(rounds)]
    return min(r[0] for r in runs), min(r[1] for r in runs)


def _decode_ours(path: Path) -> tuple[float, float, int]:
    """(wall s, CPU s, main frames) of aerobat's decoder on every log in ``path`` (compiled code from the cache)."""
    from aerobat.logs.betaflight import raw_headers
    from aerobat.logs.blackbox_decode import decode_blackbox, log_starts

    data = path.read_bytes()
    starts = log_starts(data)
    decode_blackbox(data, starts[0], len(data), raw_headers(data, starts[0]), "warm")  # load the kernel once
    started, cpu = time.perf_counter(), time.process_time()
    frames = 0
    for i, start in enumerate(starts):
        end = starts[i + 1] if i + 1 < len(starts) else len(data)
        frames += len(decode_blackbox(data, start, end, raw_headers(data, start), str(path)).main)
    return time.perf_counter() - started, time.process_time() - cpu, frames


def _decode_orangebox(path: Path) -> tuple[float, float]:
    """(wall s, CPU s) of orangebox 0.4.0 decoding every log in ``path``."""
    import orangebox.reader
    from orangebox import Parser

    from aerobat.logs.betaflight import quiet_orangebox

    started, cpu = time.perf_counter(), time.process_time()
    with quiet_orangebox():
        reader = orangebox.reader.Reader(str(path))
        for index in range(1, reader.log_count + 1):
            reader.set_log_index(index)
            for _ in Parser(reader).frames():
                pass
    return time.perf_counter() - started, time.process_time() - cpu


def run(rounds: int = 3) -> list[tuple[str, str, str]]:
    """Rows (what, target, measured)."""
    if not DATA.is_dir():
        return [("flight logs", "—", f"not measured: {DATA} is absent")]
    load = os.getloadavg()[0]
    info = _best(["log", "info", str(GECKO)], rounds)
    ours = min(_decode_ours(GECKO) for _ in range(rounds))
    reference = _decode_orangebox(GECKO)
    with tempfile.TemporaryDirectory() as tmp:
        roma = _best(["identify", "--log", f"{ROMA}:1", "--vehicle", "fpv5", "--mass-kg", "0.55", "--motor-x-m",
                      "0.08", "--motor-y-m", "0.08", "--output", f"{tmp}/r.toml", "--force"], 1)
        cf = _best(["identify", "--log", str(CF15), "--vehicle", "crazyflie21", "--mass-kg", "0.027",
                    "--motor-x-m", "0.028", "--motor-y-m", "0.028", "--output", f"{tmp}/c.toml", "--force"], 1)
    after = os.getloadavg()[0]
    return [
        ("`aerobat log info` on the Gecko blackbox log (133.8 s, 66,640 frames), a whole process", "≤ 3 s",
         f"**{info[0]:.2f} s** wall, {info[1]:.2f} s CPU (best of {rounds})"),
        ("… of which aerobat's compiled decoder decoding the frames, in-process", "—",
         f"{ours[0] * 1e3:.0f} ms wall, {ours[1] * 1e3:.0f} ms CPU ({ours[1] / ours[2] * 1e6:.2f} µs CPU a frame)"),
        ("orangebox 0.4.0 (pure Python, the decoder before; the tests' reference) on the same frames", "—",
         f"{reference[0]:.2f} s wall, {reference[1]:.2f} s CPU ({reference[1] / ours[2] * 1e6:.0f} µs CPU a frame)"),
        ("`aerobat identify --log` on the ROMA F5's first log (66 s, 250 Hz, 5 jackknife refits), a whole process",
         "≤ 15 s", f"**{roma[0]:.1f} s** wall, {roma[1]:.1f} s CPU"),
        ("`aerobat identify --log` on the Crazyflie's log15 (62 s at 1 kHz, averaged to 253 Hz)", "≤ 15 s",
         f"**{cf[0]:.1f} s** wall, {cf[1]:.1f} s CPU"),
        ("1-minute load average before / after these rows (2 cores: above 2 means shared)", "—",
         f"{load:.1f} / {after:.1f}"),
    ]


if __name__ == "__main__":
    for what, target, measured in run():
        print(f"| {what} | {target} | {measured} |")
