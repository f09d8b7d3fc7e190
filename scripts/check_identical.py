"""Digest of what aerobat computes and stores, to show a refactoring changes no result.

Runs, in a new folder, the README demo (arena, 3D triple flip, seed 1, 30 trials), a session
learned 6 trials and resumed to 12 on the arena and on the nominal plant, a small robustness
study (4 vehicles, 10 trials) and a feedback study (2 seeds, 8 trials); then prints one SHA-256
per run over every number the store hands back through ``aerobat export --format json
--trajectories`` and the studies' reports and stored results, with identifiers, paths and
wall-clock times left out.

    python scripts/check_identical.py OUT_DIR > digest.json    # before
    python scripts/check_identical.py OUT_DIR2 > digest2.json  # after
    diff digest.json digest2.json                                # nothing: bit-identical

The digest reads values, not the store's layout, so it compares across schema changes. Each
scrubbed JSON it hashed is kept in OUT_DIR/scrubbed/, so two runs whose digests differ can be
compared with ``diff -r``.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

# keys whose values depend on when or where a run happened, not on what it computed
_VOLATILE = {
    "created",
    "created_at",
    "started_at",
    "ended_at",
    "updated_at",
    "finished_at",
    "time",
    "wall_s",
    "elapsed_s",
    "duration_wall_s",
    "db",
    "path",
    "store",
    "out",
    "host",
    "pid",
    "version",
    "aerobat_version",
    "firmware_cpu_s",
    "wall_per_firmware_cpu",
    "command",
    "argv",
    "out_dir",
    "session",  # a study's jobs finish, and get their session ids, in any order
    "session_id",
}


def _volatile(key: str) -> bool:
    return key in _VOLATILE or key.endswith("_at") or "wall" in key


def _scrub(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _scrub(v) for k, v in sorted(value.items()) if not _volatile(k)}
    if isinstance(value, list):
        return [_scrub(v) for v in value]
    if isinstance(value, float):
        return value.hex()
    return value


def _aerobat(*args: str, env: dict[str, str]) -> str:
    exe = Path(sys.executable).with_name("aerobat")
    done = subprocess.run([str(exe), *args], env=env, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"aerobat {' '.join(args)} failed ({done.returncode}): {done.stderr}")
    return done.stdout


def _session_digest(db: Path, session: str, env: dict[str, str]) -> str:
    raw = _aerobat("export", session, "--format", "json", "--trajectories", "--db", str(db), env=env)
    return _json_digest(raw)


_KEEP: list[Path] = []  # where the scrubbed documents go (main sets it)


def _json_digest(raw: str) -> str:
    blob = json.dumps(_scrub(json.loads(raw)), sort_keys=True, indent=1)
    if _KEEP:
        folder = _KEEP[0]
        folder.mkdir(exist_ok=True)
        (folder / f"{len(list(folder.iterdir())):02d}.json").write_text(blob)
    return hashlib.sha256(blob.encode()).hexdigest()


def _files_digest(folder: Path) -> dict[str, str]:
    """The study's reports: every CSV row and JSON value, volatile columns left out."""
    out: dict[str, str] = {}
    for path in sorted(folder.rglob("*.csv")):
        with path.open(newline="") as handle:
            rows = [{k: v for k, v in row.items() if not _volatile(k)} for row in csv.DictReader(handle)]
        out[str(path.relative_to(folder))] = hashlib.sha256(json.dumps(rows, sort_keys=True).encode()).hexdigest()
    for path in sorted(folder.rglob("*.json")):
        out[str(path.relative_to(folder))] = _json_digest(path.read_text())
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="a new folder for the runs' stores")
    args = parser.parse_args(argv)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=False)
    _KEEP.append(out / "scrubbed")
    env = {**os.environ, "AEROBAT_DB": str(out / "unused.sqlite")}
    digests: dict[str, Any] = {}

    demo_db = out / "demo.sqlite"
    _aerobat(
        "learn",
        "flip",
        "--flips",
        "3",
        "--max-rate-deg-s",
        "1800",
        "--dims",
        "3",
        "--plant",
        "arena",
        "--seed",
        "1",
        "--trials",
        "30",
        "--db",
        str(demo_db),
        env=env,
    )
    digests["demo"] = _session_digest(demo_db, "last", env)

    for plant in ("arena", "nominal"):
        db = out / f"resume-{plant}.sqlite"
        _aerobat(
            "learn",
            "flip",
            "--flips",
            "2",
            "--dims",
            "2",
            "--plant",
            plant,
            "--seed",
            "3",
            "--trials",
            "6",
            "--db",
            str(db),
            env=env,
        )
        _aerobat("learn", "--resume", "last", "--trials", "12", "--db", str(db), env=env)
        digests[f"resumed-{plant}"] = _session_digest(db, "last", env)

    study_db = out / "study.sqlite"
    _aerobat(
        "study",
        "robustness",
        "flip",
        "--flips",
        "2",
        "--dims",
        "2",
        "--vehicles",
        "4",
        "--trials",
        "10",
        "--seed",
        "2",
        "--workers",
        "2",
        "--out",
        str(out / "robustness"),
        "--db",
        str(study_db),
        env=env,
    )
    _aerobat(
        "study",
        "feedback",
        "flip",
        "--flips",
        "2",
        "--dims",
        "2",
        "--seeds",
        "2",
        "--trials",
        "8",
        "--workers",
        "2",
        "--out",
        str(out / "feedback"),
        "--db",
        str(study_db),
        env=env,
    )
    for name in ("robustness", "feedback"):
        digests[f"study-{name}-files"] = _files_digest(out / name)
    digests["studies"] = [
        _json_digest(_aerobat("studies", str(i), "--json", "--db", str(study_db), env=env).replace(str(out), "OUT"))
        for i in (1, 2)
    ]

    json.dump(digests, sys.stdout, indent=1, sort_keys=True)
    print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
