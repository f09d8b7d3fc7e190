"""`aerobat export SESSION --format mcap` (issue 26): Foxglove's schemas, read back with the mcap reader."""

from __future__ import annotations

import contextlib
import io
import json

from aerobat.cli import main
from aerobat.store import Store
from browse_fixtures import build_store, check_session_mcap


def call(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def test_an_arena_session_reads_back_from_its_mcap_file(tmp_path):
    db = tmp_path / "s.sqlite"
    build_store(db, sessions=1, study_vehicles=0, failed_jobs=0)
    code, out, err = call(["export", "1", "--db", str(db), "--format", "mcap", "--output", str(tmp_path / "s.mcap"),
                           "--json"])
    assert code == 0, err
    written = json.loads(out)
    with Store(db, create=False) as store:
        counts = check_session_mcap(tmp_path / "s.mcap", store, 1)
    assert written["messages"] == counts and written["trials"] == 2  # trials 1 and 3 were flown
    code, _, err = call(["export", "1", "--db", str(db), "--format", "mcap", "--output", str(tmp_path / "s.mcap")])
    assert code == 2 and "exists" in err and err.count("\n") == 1, err
    code, _, err = call(["export", "1", "--db", str(db), "--format", "mcap"])
    assert code == 2 and "--format mcap: give --output" in err, err
