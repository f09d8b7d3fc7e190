"""`aerobat browse --export DIR` (issue 45 E1, E2): links in DIR, and a full disk, never cost the store or a file.

The export writes every page through ``aerobat.fileio``: a link to the store (or its ``-wal``/``-shm``)
under a name it writes is refused before anything is written; any other file or link there is
replaced, the file a link points to untouched; a full disk fails the export (exit 1) with every file
either whole or absent.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import os
import sqlite3
from collections.abc import Iterator
from pathlib import Path

import pytest

from aerobat.cli import main
from aerobat.store import Store
from browse_fixtures import build_store
from full_disk import fill_up


@pytest.fixture(scope="module")
def store(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("export-safety") / "v.sqlite"
    build_store(path, sessions=2, study_vehicles=1, failed_jobs=0)  # sessions 1, 2 flown; study 1 with session 3
    return path


def call(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


@contextlib.contextmanager
def held_open(path: Path) -> Iterator[None]:
    """The store open in another connection, as while `learn` runs: its -wal and -shm exist."""
    conn = sqlite3.connect(path)
    try:
        conn.execute("SELECT count(*) FROM sessions").fetchone()
        assert Path(f"{path}-wal").exists() and Path(f"{path}-shm").exists()
        yield
    finally:
        conn.close()


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def tree(folder: Path) -> dict[str, str]:
    """Every entry under ``folder``: files by digest, links by target, folders as such."""
    out = {}
    for entry in sorted(folder.rglob("*")):
        name = entry.relative_to(folder).as_posix()
        out[name] = (f"-> {os.readlink(entry)}" if entry.is_symlink() else "dir" if entry.is_dir()
                     else digest(entry))
    return out


def assert_store_whole(store: Path, before: str) -> None:
    assert digest(store) == before, "the store's file changed"
    code, _, err = call(["sessions", "--all", "--db", str(store)])
    assert code == 0, err
    with Store(store, create=False) as opened:
        assert [s.id for s in opened.list_sessions()] == [1, 2, 3]


def complete(path: Path) -> bool:
    """A page or figure written to its end (what a half-written file never is)."""
    data = path.read_bytes()
    if path.suffix == ".png":
        return data.startswith(b"\x89PNG") and data.endswith(b"IEND\xaeB`\x82")
    return data.rstrip().endswith(b"</html>")


@pytest.mark.parametrize("suffix", ["", "-wal", "-shm"])
@pytest.mark.parametrize("how", ["symlink", "hardlink"])
@pytest.mark.parametrize("name", ["index.html", "session-1/learning.png"])
def test_a_link_to_the_store_under_an_exported_name_is_refused_before_anything_is_written(store, tmp_path, name,
                                                                                          how, suffix):
    site = tmp_path / "site"
    (site / name).parent.mkdir(parents=True)
    (site / "session-2.html").write_text("an earlier export's page\n")
    with held_open(store):
        target = Path(f"{store}{suffix}")
        before = {p: digest(p) for p in (store, target)}
        (os.symlink if how == "symlink" else os.link)(target, site / name)
        listing = tree(site)
        code, out, err = call(["browse", "--db", str(store), "--export", str(site)])
        assert code == 2 and out == "" and err.count("\n") == 1, err
        assert err.startswith(f"aerobat: error: --export {site / name}: that is the experiment store"), err
        assert tree(site) == listing  # nothing written, nothing replaced
        assert {p: digest(p) for p in (store, target)} == before
    assert_store_whole(store, before[store])


def test_files_and_links_to_other_files_are_replaced_and_what_they_point_to_is_untouched(store, tmp_path):
    site, others = tmp_path / "site", tmp_path / "others"
    (site / "session-1").mkdir(parents=True)
    others.mkdir()
    victims = {name: others / f"{k}.txt" for k, name in enumerate(
        ["index.html", "session-1.html", "session-1/learning.png", "session-2.html"])}
    for victim in victims.values():
        victim.write_text(f"{victim.name}: somebody's file\n")
    os.symlink(victims["index.html"], site / "index.html")
    os.link(victims["session-1.html"], site / "session-1.html")
    os.symlink(os.path.relpath(victims["session-1/learning.png"], site / "session-1"), site / "session-1/learning.png")
    (site / "study-1.html").write_text("an earlier export's page\n")
    before = digest(store)
    code, out, err = call(["browse", "--db", str(store), "--export", str(site)])
    assert code == 0, err
    for name, victim in victims.items():
        assert victim.read_text() == f"{victim.name}: somebody's file\n", name
        page = site / name
        if page.exists():
            assert not page.is_symlink() and page.stat().st_nlink == 1 and complete(page), name
    assert "somebody" not in (site / "study-1.html").read_text() and complete(site / "study-1.html")
    assert not [p for p in site.rglob("*.tmp")]
    assert_store_whole(store, before)


def test_a_dangling_link_a_linked_subfolder_or_a_file_where_a_folder_goes_is_refused(store, tmp_path):
    before = digest(store)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    cases = {  # what is put in the export folder → what the one line names
        "dangling": (lambda site: os.symlink(elsewhere / "nothing.html", site / "index.html"), "index.html"),
        "linked subfolder": (lambda site: os.symlink(elsewhere, site / "session-1"), "session-1"),
        "linked store folder": (lambda site: os.symlink(store.parent, site / "session-2"), "session-2"),
        "file for a folder": (lambda site: (site / "session-1").write_text("x\n"), "session-1"),
        "folder for a file": (lambda site: (site / "index.html").mkdir(), "index.html"),
    }
    for what, (make, named) in cases.items():
        site = tmp_path / what.replace(" ", "-")
        site.mkdir()
        make(site)
        listing, outside = tree(site), tree(elsewhere)
        code, _, err = call(["browse", "--db", str(store), "--export", str(site)])
        assert code == 2 and err.count("\n") == 1 and f"--export {site / named}:" in err, (what, err)
        assert tree(site) == listing and tree(elsewhere) == outside and not elsewhere.joinpath("nothing.html").exists()
    assert sorted(p.name for p in store.parent.iterdir() if not p.name.startswith("v.sqlite")) == []
    assert_store_whole(store, before)


def test_a_full_disk_fails_the_export_and_leaves_no_half_written_file(store, tmp_path, small_tmpfs):
    disk = small_tmpfs("256k")  # the pages fit, the first figure does not
    site = disk / "site"
    site.mkdir()
    (site / "index.html").write_text("<html>the last export's index</html>\n")
    before = digest(store)
    code, out, err = call(["browse", "--db", str(store), "--export", str(site)])
    assert code == 1 and out == "" and err.count("\n") == 1, err
    assert err.startswith(f"aerobat: failed: --export {site}/") and "disk is full" in err, err
    assert (site / "index.html").read_text() == "<html>the last export's index</html>\n"  # written last: not reached
    files = [p for p in site.rglob("*") if p.is_file()]
    assert len(files) >= 3 and all(complete(p) for p in files if p.name != "index.html"), files
    assert not [p for p in site.rglob("*") if p.is_dir() and not any(p.iterdir())]  # no empty folder left
    fill_up(disk)
    code, _, err = call(["browse", "--db", str(store), "--export", str(site)])  # not even a page fits
    assert code == 1 and "disk is full" in err and err.count("\n") == 1, err
    assert_store_whole(store, before)
