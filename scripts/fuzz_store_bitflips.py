"""Bit flips inside the records of a real store: how many are caught, how many change output silently.

Builds a store with two learning sessions (nominal plant, a small flip), then, for each trial,
copies it, flips one random bit inside a random record — a table row's cell in SQLite's file
(its header, key and values, overflow pages included), chosen uniformly over every record byte
— and runs ``show --json`` and ``export`` (CSV and JSON) of both sessions, ``sessions --json``
and ``learn --resume`` on the copy. Each command's result is:

* ``caught``: refused (exit ≠ 0) or warned about on stderr;
* ``unchanged``: exit 0 and exactly the output of the undamaged store;
* ``silent``: exit 0, no warning, different output — the failure this campaign hunts.

A resume that goes on is ``silent`` when the flipped record is one the resumed session consists
of (its row, iterations, design, maneuver, plant or vehicles), else ``unaffected``.

    PYTHONPATH=src python scripts/fuzz_store_bitflips.py --flips 150 --seed 0
"""

from __future__ import annotations

import argparse
import contextlib
import io
import random
import shutil
import sqlite3
import struct
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

SMALL = ["flip", "--dims", "2", "--flips", "1", "--max-rate-deg-s", "800", "--plant", "nominal"]


def _varint(data: bytes, at: int) -> tuple[int, int]:
    value = 0
    for k in range(9):
        byte = data[at + k]
        if k == 8:
            return (value << 8) | byte, at + 9
        value = (value << 7) | (byte & 0x7F)
        if byte < 0x80:
            return value, at + k + 1
    raise AssertionError("unreachable")


def record_spans(path: Path) -> list[tuple[str, int, int, int]]:
    """``(table, rowid or -1, file offset, length)`` of every record byte range of every table's b-tree."""
    data = path.read_bytes()
    page_size = struct.unpack(">H", data[16:18])[0] or 65536
    page_size = 65536 if page_size == 1 else page_size
    usable = page_size - data[20]
    with contextlib.closing(sqlite3.connect(f"file:{path}?mode=ro&immutable=1", uri=True)) as conn:
        roots = conn.execute("SELECT name, rootpage FROM sqlite_master WHERE type = 'table' AND rootpage > 0 "
                             "AND name NOT LIKE 'sqlite_%'").fetchall()
    spans: list[tuple[str, int, int, int]] = []

    def overflow(table: str, rowid: int, page: int, remaining: int) -> None:
        while page and remaining > 0:
            start = (page - 1) * page_size
            take = min(remaining, usable - 4)
            spans.append((table, rowid, start + 4, take))
            remaining -= take
            page = struct.unpack(">I", data[start:start + 4])[0]

    def walk(table: str, page: int) -> None:
        base = (page - 1) * page_size
        hdr = base + (100 if page == 1 else 0)
        kind = data[hdr]
        ncells = struct.unpack(">H", data[hdr + 3:hdr + 5])[0]
        interior = kind in (0x02, 0x05)
        pointers = hdr + (12 if interior else 8)
        for k in range(ncells):
            cell = base + struct.unpack(">H", data[pointers + 2 * k:pointers + 2 * k + 2])[0]
            if kind == 0x05:
                walk(table, struct.unpack(">I", data[cell:cell + 4])[0])
                continue
            at = cell + (4 if kind == 0x02 else 0)
            if kind == 0x02:
                walk(table, struct.unpack(">I", data[cell:cell + 4])[0])
            size, at = _varint(data, at)
            rowid = -1
            if kind == 0x0D:
                rowid, at = _varint(data, at)
            table_leaf = kind == 0x0D
            x = usable - 35 if table_leaf else (usable - 12) * 64 // 255 - 23
            m = (usable - 12) * 32 // 255 - 23
            local = size if size <= x else (m + (size - m) % (usable - 4) if m + (size - m) % (usable - 4) <= x
                                            else m)
            spans.append((table, rowid, cell, at - cell + local))
            if local < size:
                overflow(table, rowid, struct.unpack(">I", data[at + local:at + local + 4])[0], size - local)
        if interior:
            walk(table, struct.unpack(">I", data[hdr + 8:hdr + 12])[0])

    for name, root in roots:
        walk(name, root)
    return spans


def _call(argv: list[str]) -> tuple[int, str, str]:
    from aerobat.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def _owned_by(db: Path, session_id: int) -> set[tuple[str, int]]:
    """(table, rowid) of every record session ``session_id`` consists of."""
    with contextlib.closing(sqlite3.connect(f"file:{db}?mode=ro&immutable=1", uri=True)) as conn:
        m, d, p = conn.execute("SELECT maneuver_id, design_id, plant_id FROM sessions WHERE id = ?",
                               (session_id,)).fetchone()
        vehicles = {conn.execute("SELECT vehicle_id FROM designs WHERE id = ?", (d,)).fetchone()[0],
                    conn.execute("SELECT vehicle_id FROM plants WHERE id = ?", (p,)).fetchone()[0]}
        owned = {("sessions", session_id), ("maneuvers", m), ("designs", d), ("plants", p)}
        owned |= {("vehicles", v) for v in vehicles}
        owned |= {("iterations", r[0]) for r in conn.execute("SELECT rowid FROM iterations WHERE session_id = ?",
                                                                (session_id,))}
    return owned


def bitflip_campaign(flips: int = 150, seed: int = 0, workdir: str | Path | None = None,
                     log: Any = None) -> dict[str, Any]:
    """Flip ``flips`` random single bits inside records of a real store; counts per outcome (see the module)."""
    started = time.monotonic()
    folder = Path(tempfile.mkdtemp(prefix="bitflips-", dir=workdir))
    pristine = folder / "pristine.sqlite"
    for argv in ([*SMALL, "--iterations", "3", "--seed", "1"], [*SMALL, "--iterations", "2", "--seed", "2"]):
        code, _, err = _call(["learn", *argv, "--db", str(pristine), "--out", str(folder / "learn")])
        if code != 0:
            raise RuntimeError(f"building the store failed: {err}")
    reads = [["show", "1", "--json"], ["show", "2", "--json"], ["export", "1"], ["export", "2", "--format", "json"],
             ["sessions", "--json", "--all"]]
    reference = {}
    db = folder / "store.sqlite"  # every run reads this name (the JSON names its store)
    shutil.copyfile(pristine, db)
    for argv in reads:
        code, out, err = _call([*argv, "--db", str(db)])
        assert code == 0 and not err, (argv, err)
        reference[tuple(argv)] = out
    spans = record_spans(pristine)
    owned = _owned_by(pristine, 2)
    total_bytes = sum(length for *_, length in spans)
    rng = random.Random(seed)
    counts = {"caught": 0, "unchanged": 0, "silent": 0}
    resume = {"refused": 0, "unaffected": 0, "silent": 0}
    silent_cases: list[str] = []
    for trial in range(flips):
        pick = rng.randrange(total_bytes * 8)
        byte, bit = divmod(pick, 8)
        for span in spans:
            if byte < span[3]:
                break
            byte -= span[3]
        table, rowid, offset, length = span
        shutil.copyfile(pristine, db)
        with db.open("r+b") as handle:
            handle.seek(offset + byte)
            value = handle.read(1)[0]
            handle.seek(offset + byte)
            handle.write(bytes([value ^ (1 << bit)]))
        where = f"flip {trial}: {table} rowid {rowid}, byte {byte} of {length}, bit {bit}"
        for argv in reads:
            code, out, err = _call([*argv, "--db", str(db)])
            if code != 0 or "warning" in err or "damaged" in err:
                counts["caught"] += 1
            elif out == reference[tuple(argv)]:
                counts["unchanged"] += 1
            else:
                counts["silent"] += 1
                silent_cases.append(f"{where}: `{' '.join(argv)}` changed its output")
        code, _, err = _call(["learn", "--resume", "2", "--trials", "3", "--db", str(db), "--out",
                              str(folder / f"resume-{trial}")])
        if code != 0:
            resume["refused"] += 1
        elif (table, rowid) in owned:
            resume["silent"] += 1
            silent_cases.append(f"{where}: `learn --resume 2` went on from a damaged record")
        else:
            resume["unaffected"] += 1
        for suffix in ("-wal", "-shm"):
            Path(f"{db}{suffix}").unlink(missing_ok=True)
        shutil.rmtree(folder / f"resume-{trial}", ignore_errors=True)
        if log is not None and (trial + 1) % 10 == 0:
            log(f"{trial + 1}/{flips} flips: reads {counts}, resumes {resume}")
    shutil.rmtree(folder, ignore_errors=True)
    return {"flips": flips, "seed": seed, "record_bytes": total_bytes, "reads": counts, "resumes": resume,
            "silent": counts["silent"] + resume["silent"], "silent_cases": silent_cases,
            "seconds": round(time.monotonic() - started, 1)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--flips", type=int, default=150, help="single-bit flips to try (default: 150)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    args = parser.parse_args(argv)
    report = bitflip_campaign(args.flips, args.seed, log=lambda line: print(line, file=sys.stderr, flush=True))
    for case in report["silent_cases"]:
        print(f"silent: {case}")
    print(f"{report['flips']} single-bit flips in {report['record_bytes']} record bytes (seed {report['seed']}): "
          f"reads {report['reads']}, resumes {report['resumes']}; silent: {report['silent']} "
          f"({report['seconds']} s)")
    return 1 if report["silent"] else 0


if __name__ == "__main__":
    sys.exit(main())
