"""What aerobat reads and writes (issue 31 D1–D8, I1, I4, E2, H1, H2; issue 25 item 2).

Every output is checked before any work and never written over the store (whatever the links);
inputs are regular files of bounded size; default folders are unique per store and session.
Each test reproduces the issue's command and failed on the code before ``aerobat.fileio``.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import os
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from aerobat.cli import main

ROOT = Path(__file__).resolve().parents[2]
PROGRAM = ROOT / "src" / "aerobat" / "examples" / "single_flip.toml"
SMALL = ["flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "800"]


def call(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 2
    return code, out.getvalue(), err.getvalue()


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def refused(result: tuple[int, str, str], *fragments: str) -> str:
    code, _, err = result
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("aerobat: error:"), err
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


def sessions_in(db: Path) -> int:
    with contextlib.closing(sqlite3.connect(db)) as conn:
        return conn.execute("SELECT count(*) FROM sessions").fetchone()[0]


@pytest.fixture(scope="module")
def stored(tmp_path_factory) -> Path:
    """A store holding one (one-iteration, nominal-plant) session."""
    folder = tmp_path_factory.mktemp("stored")
    code, _, err = call(["learn", *SMALL, "--plant", "nominal", "--iterations", "1", "--db",
                         str(folder / "s.sqlite"), "--out", str(folder / "o")])
    assert code == 0, err
    return folder / "s.sqlite"


@pytest.fixture
def here(tmp_path, monkeypatch, stored) -> Path:
    """A scratch folder as the working directory, with the store as ./s.sqlite and as the default ./aerobat.sqlite."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("AEROBAT_DB", raising=False)
    shutil.copyfile(stored, tmp_path / "s.sqlite")
    shutil.copyfile(stored, tmp_path / "aerobat.sqlite")
    return tmp_path


# ------------------------------------------------------------------ D1, D2, D3: single files


def test_design_program_never_overwrites_the_default_store(here, monkeypatch):
    """D1: `design flip --program aerobat.sqlite --force` wrote TOML over the default store."""
    before = digest(here / "aerobat.sqlite")
    refused(call(["design", *SMALL, "--program", "aerobat.sqlite", "--force"]), "--program", "experiment store")
    assert digest(here / "aerobat.sqlite") == before
    monkeypatch.setenv("AEROBAT_DB", str(here / "s.sqlite"))  # $AEROBAT_DB is the default store then
    before = digest(here / "s.sqlite")
    refused(call(["design", *SMALL, "--program", "s.sqlite", "--force"]), "experiment store")
    assert digest(here / "s.sqlite") == before


@pytest.mark.parametrize("link", ["symlink", "hardlink"])
@pytest.mark.parametrize("argv", [
    ["simulate", str(PROGRAM)],
    ["fly", str(PROGRAM), "--plant", "nominal", "--trials", "1"],
    ["benchmark", "translation", "--to-m", "1,0"],
])
def test_plot_through_a_link_to_the_store_is_refused(here, argv, link):
    """D2: `ln -s aerobat.sqlite fig.png; simulate program.toml --plot fig.png` wrote a PNG over the store."""
    before = digest(here / "aerobat.sqlite")
    (os.symlink if link == "symlink" else os.link)("aerobat.sqlite", here / "fig.png")
    refused(call([*argv, "--plot", "fig.png"]), "--plot fig.png")
    assert digest(here / "aerobat.sqlite") == before


def test_plot_refuses_an_existing_file_and_writes_a_new_one(here):
    """D2: --plot replaced any existing file."""
    (here / "mine.png").write_bytes(b"precious")
    refused(call(["simulate", str(PROGRAM), "--plot", "mine.png"]), "--plot mine.png", "exists")
    assert (here / "mine.png").read_bytes() == b"precious"
    code, _, err = call(["simulate", str(PROGRAM), "--plot", "new.png"])
    assert code == 0, err
    assert (here / "new.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_identify_checks_its_figure_before_flying(here):
    """D3: with --figure linked to the store, the flights were stored, then the store became a PNG (exit 0)."""
    os.symlink("s.sqlite", here / "link.png")
    before, count = digest(here / "s.sqlite"), sessions_in(here / "s.sqlite")
    refused(call(["identify", "--plant", "nominal", "--output", "v.toml", "--figure", "link.png", "--db", "s.sqlite"]),
            "--figure link.png", "experiment store")
    assert digest(here / "s.sqlite") == before and sessions_in(here / "s.sqlite") == count
    (here / "v.png").write_bytes(b"an earlier figure")  # the default figure, v.png, exists: not replaced silently
    refused(call(["identify", "--plant", "nominal", "--output", "v.toml", "--db", "s.sqlite"]), "--figure v.png",
            "--force")
    assert (here / "v.png").read_bytes() == b"an earlier figure" and sessions_in(here / "s.sqlite") == count


def test_identify_output_that_cannot_be_created_is_refused_before_flying(here):
    """E2: `identify --output /proc/x.toml` flew and stored 12 s of flights before it exited 2."""
    count = sessions_in(here / "s.sqlite")
    refused(call(["identify", "--output", "/proc/x.toml", "--plant", "nominal", "--db", "s.sqlite"]),
            "--output /proc/x.toml")
    assert sessions_in(here / "s.sqlite") == count


def test_identify_output_that_is_a_folder_is_bad_input(here):
    """I4: `identify --output / --plant nominal` raised ValueError (… empty name)."""
    refused(call(["identify", "--output", "/", "--plant", "nominal", "--db", "s.sqlite"]), "--output /", "folder")


# ------------------------------------------------------------------ D4, D5: files inside folders


@pytest.mark.parametrize(("argv", "name"), [
    (["plot", "1", "--db", "s.sqlite", "--out", "F"], "learning.png"),
    (["plot", "1", "--db", "s.sqlite", "--out", "F"], "side_views.png"),
    (["replay", "1", "--db", "s.sqlite", "--out", "F"], "replay.html"),
    (["benchmark", "map", "--y-m", "1:1:1", "--z-m", "1:1:1", "--workers", "1", "--db", "s.sqlite", "--out", "F"],
     "benchmark_map.csv"),
    (["learn", *SMALL, "--plant", "nominal", "--iterations", "1", "--db", "s.sqlite", "--out", "F"], "session.json"),
])
@pytest.mark.parametrize("link", ["symlink", "hardlink"])
def test_a_file_in_an_output_folder_linked_to_the_store_is_refused_before_any_work(here, argv, name, link):
    """D4: plot, replay and benchmark map wrote over the store through a link in their folder; learn left the
    store "database disk image is malformed" with exit 0."""
    (here / "F").mkdir()
    if link == "symlink":
        os.symlink("../s.sqlite", here / "F" / name)
    else:
        os.link(here / "s.sqlite", here / "F" / name)
    before, count = digest(here / "s.sqlite"), sessions_in(here / "s.sqlite")
    refused(call(argv), f"F/{name}", "experiment store")
    assert digest(here / "s.sqlite") == before and sessions_in(here / "s.sqlite") == count
    with contextlib.closing(sqlite3.connect(here / "s.sqlite")) as conn:
        assert conn.execute("PRAGMA quick_check").fetchone()[0] == "ok"


def test_examples_never_write_through_a_link_to_the_store(here):
    """D5: `ln -s ../aerobat.sqlite E/single_flip.toml; aerobat examples E --force` overwrote the store."""
    (here / "E").mkdir()
    os.symlink("../aerobat.sqlite", here / "E" / "single_flip.toml")
    before = digest(here / "aerobat.sqlite")
    refused(call(["examples", "E", "--force"]), "E/single_flip.toml", "experiment store")
    assert digest(here / "aerobat.sqlite") == before
    assert not (here / "E" / "hover.toml").exists()  # refused before the first copy


def test_a_dangling_link_in_a_plot_folder_is_bad_input(here):
    """I1: a dangling symlink in a plot folder gave FileNotFoundError."""
    (here / "F").mkdir()
    os.symlink("../no/such/folder/x.png", here / "F" / "learning.png")
    refused(call(["plot", "1", "--db", "s.sqlite", "--out", "F"]), "F/learning.png", "does not exist")


def test_writes_replace_a_link_and_never_follow_it(tmp_path):
    """The library's writers replace a link named like their output; the file it points to is untouched."""
    from aerobat.plotting import new_figure, save_figure, write_text

    (tmp_path / "target.txt").write_text("keep me")
    os.symlink("target.txt", tmp_path / "out.json")
    os.link(tmp_path / "target.txt", tmp_path / "hard.json")
    write_text(tmp_path / "out.json", "{}")
    write_text(tmp_path / "hard.json", "[]")
    assert (tmp_path / "target.txt").read_text() == "keep me"
    assert not (tmp_path / "out.json").is_symlink() and (tmp_path / "out.json").read_text() == "{}"
    assert (tmp_path / "hard.json").read_text() == "[]"
    os.symlink("target.txt", tmp_path / "fig.png")
    save_figure(new_figure(), tmp_path / "fig.png")
    assert (tmp_path / "target.txt").read_text() == "keep me"
    assert (tmp_path / "fig.png").read_bytes()[:4] == b"\x89PNG"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig.png", "hard.json", "out.json", "target.txt"]


def test_character_devices_stay_usable_as_outputs(here):
    """`--output /dev/null` keeps working (a previous attempt broke it)."""
    code, _, err = call(["export", "1", "--db", "s.sqlite", "--output", "/dev/null"])
    assert code == 0, err
    code, _, err = call(["export", "1", "--db", "s.sqlite", "--output", "/dev/null", "--format", "json"])
    assert code == 0, err


def test_writers_refuse_an_sqlite_file_even_unnamed(tmp_path):
    """A file that starts like an SQLite database is never written over, even when no --db names it."""
    from aerobat.errors import ConfigError
    from aerobat.plotting import write_text

    db = tmp_path / "elsewhere.sqlite"
    with contextlib.closing(sqlite3.connect(db)) as conn:
        conn.execute("CREATE TABLE t (x)")
    before = digest(db)
    with pytest.raises(ConfigError, match="SQLite"):
        write_text(db, "not a database")
    assert digest(db) == before


# ------------------------------------------------------------------ D6


@pytest.mark.parametrize("suffix", ["-wal", "-shm", "-journal"])
def test_db_named_like_a_journal_is_refused(here, suffix):
    """D6: `learn --db runs.sqlite-wal` was accepted; the next `learn --db runs.sqlite` deleted it."""
    refused(call(["learn", *SMALL, "--plant", "nominal", "--iterations", "1", "--db", f"runs.sqlite{suffix}"]),
            f"--db runs.sqlite{suffix}", suffix)
    assert not (here / f"runs.sqlite{suffix}").exists()
    from aerobat.errors import StoreAccessError
    from aerobat.store import Store

    with pytest.raises(StoreAccessError, match=suffix):
        Store(here / f"s.sqlite{suffix}")


def test_an_output_named_like_a_journal_is_refused(here):
    refused(call(["export", "1", "--db", "s.sqlite", "--output", "x.sqlite-wal"]), "--output x.sqlite-wal")


# ------------------------------------------------------------------ D7 (issue 25 item 2)


def test_two_stores_never_share_a_default_folder(here):
    """D7: session 1 of two stores both wrote out/session-1, one over the other."""
    for db in ("a.sqlite", "b.sqlite"):
        code, _, err = call(["learn", *SMALL, "--plant", "nominal", "--iterations", "1", "--db", db])
        assert code == 0, err
    folders = sorted((here / "out").glob("*/session-1"))
    assert [f.parent.name.split("-")[0] for f in folders] == ["a", "b"]
    assert all((f / "session.json").is_file() and (f / ".aerobat-owner").is_file() for f in folders)
    a_json = (folders[0] / "session.json").read_bytes()
    code, _, err = call(["plot", "1", "--db", "b.sqlite"])  # b's plot goes to b's folder
    assert code == 0, err
    assert (folders[0] / "session.json").read_bytes() == a_json
    code, _, err = call(["replay", "1", "--db", "a.sqlite"])
    assert code == 0, err
    assert (folders[0] / "replay.html").is_file() and not (folders[1] / "replay.html").exists()


def test_a_default_folder_left_by_an_earlier_store_is_not_reused(here):
    """A new store at the same path starts at session 1 again: the old folder is kept, a new one is used."""
    code, _, err = call(["learn", *SMALL, "--plant", "nominal", "--iterations", "1", "--db", "c.sqlite"])
    assert code == 0, err
    (old,) = (here / "out").glob("c-*/session-1")
    old_json = (old / "session.json").read_bytes()
    (here / "c.sqlite").unlink()
    code, _, err = call(["learn", *SMALL, "--plant", "nominal", "--iterations", "1", "--db", "c.sqlite"])
    assert code == 0, err
    assert (old / "session.json").read_bytes() == old_json
    new = old.with_name("session-1-2")
    assert (new / "session.json").is_file()
    code, out, err = call(["plot", "1", "--db", "c.sqlite", "--json"])
    assert code == 0 and f"{new.parent.name}/session-1-2" in out, err


# ------------------------------------------------------------------ D8


def test_a_study_records_its_folder_at_start_and_resume_writes_there(here, monkeypatch):
    """D8: a study recorded its --out only when it finished; after a kill --resume wrote elsewhere."""
    from aerobat.experiments.studies import runner
    from aerobat.store import Store

    def killed(*args, **kwargs):
        raise KeyboardInterrupt  # as SIGINT would, while the first job's result is being recorded

    record = runner._record
    monkeypatch.setattr(runner, "_record", killed)
    argv = ["benchmark", "map", "--y-m", "1:2:2", "--z-m", "1:1:1", "--workers", "1", "--db", "s.sqlite",
            "--out", "mine"]
    code, _, err = call(argv)
    assert code != 0
    with Store(here / "s.sqlite", create=False) as store:
        (study,) = store.list_studies()
        assert study.out_dir == "mine"
    monkeypatch.setattr(runner, "_record", record)
    code, _, err = call(["benchmark", "map", "--y-m", "1:2:2", "--z-m", "1:1:1", "--workers", "1", "--db", "s.sqlite",
                         "--resume", str(study.id)])
    assert code == 0, err
    assert (here / "mine" / "benchmark_map.csv").is_file() and not (here / "out").exists()


# ------------------------------------------------------------------ H1, H2


def _aerobat(*argv: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    return subprocess.run([sys.executable, "-m", "aerobat.cli", *argv], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=120)


@pytest.mark.parametrize("special", ["fifo", "/dev/zero", "/dev/urandom"])
def test_special_files_as_inputs_are_refused_at_once(tmp_path, special):
    """H1/H2: a FIFO blocked forever; /dev/zero and /dev/urandom hung or grew memory until killed."""
    path = special
    if special == "fifo":
        path = str(tmp_path / "f.toml")
        os.mkfifo(path)
    for argv in (["simulate", path], ["fly", str(PROGRAM), "--plant", "arena", "--arena", path],
                 ["design", "--maneuver", path], ["simulate", str(PROGRAM), "--vehicle", path]):
        result = _aerobat(*argv, cwd=tmp_path)
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(lines) == 1 and "not a regular file" in lines[0], (argv, result.stderr)


def test_an_input_larger_than_the_cap_is_refused(tmp_path):
    from aerobat.errors import ConfigError
    from aerobat.fileio import MAX_INPUT_BYTES
    from aerobat.quadrotor.program import load_program

    big = tmp_path / "big.toml"
    with open(big, "wb") as handle:
        handle.truncate(MAX_INPUT_BYTES + 1)  # sparse: no disk used
    with pytest.raises(ConfigError, match="larger than"):
        load_program(big)


@pytest.mark.parametrize("argv", [["plot", "1", "--db", "s.sqlite", "--out", ""],
                                  ["replay", "1", "--db", "s.sqlite", "--out="],
                                  ["export", "1", "--db", "s.sqlite", "--output", ""],
                                  ["simulate", str(PROGRAM), "--out", " "], ["examples", ""]])
def test_an_empty_output_name_is_refused_not_taken_for_the_working_folder(here, argv):
    """`Path("")` is ".": an empty --out wrote into the working folder, an empty --output printed to stdout."""
    def listing() -> list[str]:  # the store's -wal/-shm files come and go with any reader
        return sorted(p.name for p in here.iterdir() if not p.name.endswith(("-wal", "-shm")))

    before = listing()
    refused(call(argv), "empty")
    assert listing() == before


@pytest.mark.parametrize(("argv", "named"), [
    (["simulate", str(PROGRAM), "--vehicle="], "vehicle"),
    (["fly", str(PROGRAM), "--plant", "arena", "--arena="], "--arena"),
    (["learn", *SMALL, "--plant", "nominal", "--plant-vehicle=", "--db", "s.sqlite"], "--plant-vehicle"),
    (["study", "robustness", *SMALL, "--ranges=", "--db", "s.sqlite"], "--ranges"),
])
def test_an_empty_input_name_is_refused_naming_the_option(here, argv, named):
    """Found by the campaign's files phase: an empty name read the working folder (".: is a directory"),
    and an empty --ranges was ignored (the default ranges ran)."""
    refused(call(argv), named, "empty")
