"""`aerobat export --output FILE` in every format (issue 45 E2): never through a link, whole or not at all.

CSV and JSON went through ``aerobat.fileio.write_output``; MCAP opened the file itself, so ``--force``
wrote through a symbolic link and a full disk left a partial file (exit 70). Every format now writes
a temporary file that replaces the name.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import sqlite3
from pathlib import Path

import pytest

from aerobat.cli import main
from aerobat.cli.app import exit_status
from aerobat.errors import DiskFull
from aerobat.store import Store
from browse_fixtures import build_store
from full_disk import fill_up

FORMATS = ("csv", "json", "mcap")


@pytest.fixture(scope="module")
def store(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("export-outputs") / "v.sqlite"
    build_store(path, sessions=1, study_vehicles=0, failed_jobs=0)
    return path


def call(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def looks_like(fmt: str, data: bytes) -> bool:
    """A whole file of the format (a partial one fails: MCAP ends with its magic, JSON parses)."""
    if fmt == "mcap":
        return data.startswith(b"\x89MCAP0\r\n") and data.endswith(b"\x89MCAP0\r\n") and len(data) > 1000
    if fmt == "json":
        return json.loads(data)["session_id"] == 1
    return data.startswith(b"session,i,") and data.count(b"\n") == 4


def export(store: Path, fmt: str, output: Path, *extra: str) -> tuple[int, str, str]:
    return call(["export", "1", "--db", str(store), "--format", fmt, "--output", str(output), *extra])


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("how", ["symlink", "hardlink"])
def test_force_replaces_a_link_and_never_writes_through_it(store, tmp_path, fmt, how):
    victim = tmp_path / "victim.txt"
    victim.write_text("somebody's file\n")
    output = tmp_path / f"out.{fmt}"
    (os.symlink if how == "symlink" else os.link)(victim, output)
    code, _, err = export(store, fmt, output)
    assert code == 2 and "exists" in err and err.count("\n") == 1, err
    code, _, err = export(store, fmt, output, "--force")
    assert code == 0, err
    assert victim.read_text() == "somebody's file\n"
    assert not output.is_symlink() and output.stat().st_nlink == 1 and looks_like(fmt, output.read_bytes())
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["victim.txt", output.name])  # no temporary file


@pytest.mark.parametrize("fmt", FORMATS)
def test_a_link_to_the_store_or_its_log_is_refused_even_with_force(store, tmp_path, fmt):
    conn = sqlite3.connect(store)  # open elsewhere, as while `learn` runs: the -wal and -shm exist
    try:
        conn.execute("SELECT count(*) FROM sessions").fetchone()
        for k, (target, how) in enumerate([(store, os.symlink), (store, os.link), (Path(f"{store}-wal"), os.link),
                                           (Path(f"{store}-shm"), os.symlink)]):
            before = target.read_bytes()
            output = tmp_path / f"{k}.{fmt}"
            how(target, output)
            code, _, err = export(store, fmt, output, "--force")
            assert code == 2 and err.count("\n") == 1 and "experiment store" in err, (target, err)
            assert target.read_bytes() == before or target.name.endswith("-shm"), target  # readers mark the -shm
            assert target.read_bytes()[:4] != b"\x89MCA"
    finally:
        conn.close()
    with Store(store, create=False) as opened:
        assert [s.id for s in opened.list_sessions()] == [1]


@pytest.mark.parametrize("fmt", FORMATS)
def test_a_full_disk_is_a_failure_and_the_old_file_stays_whole(store, small_tmpfs, fmt):
    disk = small_tmpfs("256k")
    output = disk / f"old.{fmt}"
    output.write_bytes(b"the previous export\n")
    assert fill_up(disk) == 0
    code, out, err = export(store, fmt, output, "--force")
    assert code == 1 and out == "" and err.count("\n") == 1, err
    assert err.startswith(f"aerobat: failed: --output {output}: cannot write: the disk is full"), err
    assert output.read_bytes() == b"the previous export\n"
    assert sorted(p.name for p in disk.iterdir()) == [".filler", output.name]  # no partial temporary file
    (disk / ".filler").unlink()  # room again: the same command now succeeds
    code, _, err = export(store, fmt, output, "--force")
    assert code == 0 and looks_like(fmt, output.read_bytes()), err


def test_a_full_disk_is_exit_status_1_not_bad_input():
    assert exit_status(DiskFull("x: cannot write: the disk is full")) == 1
