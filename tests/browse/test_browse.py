"""`aerobat browse` (issue 26): read-only pages of the store, served and exported, checked against the store."""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import re
import shutil
import socket
import sqlite3
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from aerobat.browse import Site, start
from aerobat.cli import main
from aerobat.store import Store
from browse_fixtures import build_store

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def store_path(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("browse") / "store.sqlite"
    build_store(path)  # 5 sessions, a study of 200 vehicles (198 sessions, 2 failed jobs)
    return path


def call(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def fetch(url: str) -> tuple[int, str, bytes]:
    try:
        with urllib.request.urlopen(url, timeout=60) as response:
            return response.status, response.headers["Content-Type"], response.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.headers["Content-Type"], exc.read()


def files_digest(path: Path) -> dict[str, str]:
    """The store's file and its write-ahead log, byte for byte. SQLite's shared-memory index (its lock table)
    is left out, and so is an empty log: a reader of a WAL database may open one, and it holds nothing."""
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in path.parent.glob(path.name + "*")
            if not p.name.endswith("-shm") and not (p.name.endswith("-wal") and p.stat().st_size == 0)}


def test_served_pages_show_what_the_store_holds_and_never_write_it(store_path):
    before = files_digest(store_path)
    with Store(store_path, create=False) as store:
        sessions = store.list_sessions()
        first = sessions[0]
        iterations = store.iterations(first.id)
        study = store.list_studies()[0]
        jobs = store.study_jobs(study.id)
    with start(store_path, port=0) as browser:
        assert browser.url.startswith("http://127.0.0.1:")
        status, kind, body = fetch(browser.url)
        page = body.decode()
        assert status == 200 and kind.startswith("text/html")
        rows = [int(r) for r in re.findall(r'<tr class="session" data-id="(\d+)"', page)]
        assert rows == [s.id for s in sessions if s.study_id is None] == [1, 2, 3, 4, 5]  # studies' hidden
        assert '<span id="shown">5</span> of 203 sessions match' in page and "198 more in studies" in page
        assert 'data-plant="rotorpy"' in page and 'data-rule="broyden"' in page
        assert '<option value="rotorpy">rotorpy (2)</option>' in page  # counts per filter value
        # every session, a page at a time, in the order asked for
        status, _, body = fetch(browser.url + "index.html?studies=1&sort=id&dir=desc&page=2")
        rows = [int(r) for r in re.findall(r'<tr class="session" data-id="(\d+)"', body.decode())]
        assert status == 200 and rows == list(range(103, 3, -1)) and "page 2 of 3" in body.decode()
        assert 'href="index.html?studies=1&amp;sort=id&amp;dir=desc&amp;page=3"' in body.decode()
        for bad in ("page=0", "page=x", "sort=colour", "dir=up", "study=abc", "from=2026-13-01"):
            status, _, body = fetch(browser.url + "index.html?" + bad)
            assert status in (400, 404) and body.count(b"\n") == 1, (bad, body)
        # a session: its trials table and figures
        status, _, body = fetch(browser.url + f"session-{first.id}.html")
        page = body.decode()
        assert status == 200 and page.count('<tr class="trial">') == len(iterations) == 3
        assert f"{first.id}/learning.png" in page and "replay-default.html" in page and "tags-notes" in page
        for name in ("learning", "side_views"):
            status, kind, body = fetch(browser.url + f"session-{first.id}/{name}.png")
            assert status == 200 and kind == "image/png" and body[:8] == b"\x89PNG\r\n\x1a\n" and len(body) > 10_000
        status, _, body = fetch(browser.url + f"session-{first.id}/replay-{iterations[-1].index}.html")
        assert status == 200 and b"plotly" in body and b"aerobat-replay-status" in body
        progress = json.loads(fetch(browser.url + f"api/session-{first.id}.json")[2])
        assert (progress["trials"], progress["measured"], progress["status"]) == (3, 3, "completed")
        # the study: its jobs and the failed ones
        status, _, body = fetch(browser.url + f"study-{study.id}.html")
        page = body.decode()
        assert status == 200 and page.count('<tr class="job">') == len(jobs) == 200
        assert '<span id="jobs-failed">2</span>' in page and page.count("diverged at") == 2 * 2  # failed + jobs tables
        # compare two sessions: what differs, the overlaid curves, parameters with meaning and bounds
        status, _, body = fetch(browser.url + "compare.html?ids=1,2")
        page = body.decode()
        assert status == 200 and "session 1: plant arena, feedback none, seed 1</a>" in page
        assert "They differ in: <strong>plant, feedback, seed, measured iterations" in page
        assert "plant setting feedback.scheme" in page and "accelerate collective" in page
        assert fetch(browser.url + "assets/plotly.min.js")[1].startswith("text/javascript")
        # a session's parameters say what they mean; the table has a seed column, sortable
        page = fetch(browser.url + "session-1.html")[2].decode()
        assert "<td>p0</td><td>accelerate collective</td><td>m/s²</td><td>[" in page
        assert 'href="index.html?sort=seed&amp;dir=asc"' in fetch(browser.url)[2].decode()
        assert fetch(browser.url + "compare/1-2.png")[2][:4] == b"\x89PNG"
        # pages that do not exist: one clear line
        status, _, body = fetch(browser.url + "session-9999.html")
        assert status == 404 and b"no session 9999" in body and body.count(b"\n") == 1
        assert fetch(browser.url + "compare.html?ids=1")[0] == 400
        assert fetch(browser.url + "../etc/passwd")[0] == 404
    with pytest.raises(OSError):  # the server is gone
        socket.create_connection(("127.0.0.1", int(browser.url.rsplit(":", 1)[1].strip("/"))), timeout=2)
    assert files_digest(store_path) == before


def test_export_writes_the_same_pages_as_static_files(store_path, tmp_path):
    before = files_digest(store_path)
    code, out, err = call(["browse", "--db", str(store_path), "--export", str(tmp_path / "site"), "--compare", "1,2",
                           "--json"])
    assert code == 0, err
    written = json.loads(out)
    site = tmp_path / "site"
    pages = sorted(p.relative_to(site).as_posix() for p in site.rglob("*") if p.is_file())
    assert written["files"] == len(pages)
    # index, 203 session pages, 5 × (2 figures + 1 replay), the study page, compare page and figure
    assert len([p for p in pages if re.fullmatch(r"session-\d+\.html", p)]) == 203
    assert len([p for p in pages if p.endswith(".png") and p.startswith("session-")]) == 10
    assert "study-1.html" in pages and "compare.html" in pages and "compare/1-2.png" in pages
    assert "assets/plotly.min.js" in pages  # the interactive figures work from the folder, offline
    assert 'href="compare.html">sessions 1, 2 side by side</a>' in (site / "index.html").read_text()
    with Site(store_path, static=True) as live:
        assert (site / "session-1.html").read_text() == live.get("session-1.html")[1].decode()
    assert files_digest(store_path) == before


def test_bad_input_gets_one_clear_line(store_path, tmp_path):
    text = tmp_path / "notes.txt"
    text.write_text("not a database\n")
    code, _, err = call(["browse", "--db", str(text), "--port", "0", "--seconds", "1"])
    assert code == 2 and err.count("\n") == 1 and "notes.txt" in err, err
    foreign = tmp_path / "other.sqlite"
    with sqlite3.connect(foreign) as conn:
        conn.execute("CREATE TABLE t (x)")
    code, _, err = call(["browse", "--db", str(foreign), "--export", str(tmp_path / "x")])
    assert code == 2 and err.count("\n") == 1 and "other.sqlite" in err, err
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        code, _, err = call(["browse", "--db", str(store_path), "--port", str(port), "--seconds", "1"])
    assert code == 2 and err.count("\n") == 1 and f"--port {port}: already in use" in err, err
    code, _, err = call(["browse", "--db", str(store_path), "--export", str(tmp_path / "y"), "--compare", "1,9999"])
    assert code == 2 and err.count("\n") == 1 and "no session 9999" in err, err
    code, _, err = call(["export", "9999", "--db", str(store_path), "--format", "mcap", "--output",
                         str(tmp_path / "a.mcap")])
    assert code == 2 and err.count("\n") == 1 and "no session 9999" in err, err


def test_browse_follows_a_learn_that_writes_the_same_store(tmp_path):
    """A real `aerobat learn` process writes while the server reads: no error in either, new trials appear."""
    db = tmp_path / "live.sqlite"
    learn = subprocess.Popen(
        [sys.executable, "-m", "aerobat.cli", "learn", "flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "800",
         "--plant", "arena", "--iterations", "30", "--db", str(db), "--out", str(tmp_path / "out")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 600
        def started() -> bool:
            if not db.exists():
                return False
            with Store(db, create=False) as store:
                return bool(store.list_sessions())

        while not started():
            assert learn.poll() is None and time.monotonic() < deadline, learn.communicate()
            time.sleep(0.2)
        seen = []
        with start(db, port=0) as browser:
            while True:
                status, _, body = fetch(browser.url + "api/session-1.json")
                assert status == 200, body
                progress = json.loads(body)
                seen.append(progress["trials"])
                if len(seen) % 10 == 0:  # the pages too, now and then, while the writer commits (not first: a
                    # first page under load takes long enough for a short learn to end before the next poll)
                    page = fetch(browser.url + "session-1.html")
                    assert page[0] == 200, page[2][:1000]
                    assert page[2].decode().count('<tr class="trial">') >= progress["trials"]
                    assert fetch(browser.url)[0] == 200
                if progress["status"] != "running" or time.monotonic() > deadline:
                    break
                time.sleep(0.02)
            status, _, body = fetch(browser.url + "session-1.html")
            with Store(db, create=False) as store:
                stored = store.session(1)
            assert status == 200 and body.decode().count('<tr class="trial">') == stored.n_records
            assert progress["measured"] == stored.n_measured == 30
        out, err = learn.communicate(timeout=600)
    finally:
        if learn.poll() is None:
            learn.kill()
            learn.communicate()
    assert learn.returncode == 0, err
    assert seen[-1] == stored.n_records and len(set(seen)) >= 3, seen  # the page saw the session grow, trial by trial
    assert "live: this page follows" not in body.decode()


def chromium(url: str, tmp: Path, *, screenshot: Path | None = None) -> str:
    if not CHROMIUM:  # CI installs it (.ci/run, as root); elsewhere: apt-get install chromium
        pytest.skip("Debian's chromium is not on PATH: the page is not rendered in a browser here")
    command = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
               "--disable-component-update", "--disable-sync", "--no-first-run", f"--user-data-dir={tmp / 'profile'}",
               "--virtual-time-budget=10000", "--window-size=1200,900"]
    command += [f"--screenshot={screenshot}"] if screenshot else ["--dump-dom"]
    result = subprocess.run([*command, url], capture_output=True, text=True, timeout=180)
    assert result.returncode == 0, result.stderr[-2000:]
    return result.stdout


def test_the_page_in_chromium_filters_and_draws_its_figures(store_path, tmp_path):
    with start(store_path, port=0) as browser:
        dom = chromium(browser.url, tmp_path)
        assert re.search(r'<span id="shown">5</span> of 203', dom)
        dom = chromium(browser.url + "index.html?plant=rotorpy", tmp_path)
        assert re.search(r'<span id="shown">2</span> of 203', dom)  # sessions 2 and 4 fly rotorpy
        dom = chromium(browser.url + "index.html?studies=1&q=broyden", tmp_path)
        assert re.search(r'<span id="shown">2</span> of 203', dom)
        dom = chromium(browser.url + "index.html?studies=1", tmp_path)
        assert re.search(r'<span id="shown">203</span> of 203', dom)
        dom = chromium(browser.url + "session-1.html", tmp_path)
        assert re.search(r'id="aerobat-page-status"[^>]*>ok: 2 figures<', dom), dom[-500:]
        assert re.search(r'id="errors-figure"[^>]*data-drawn="yes"', dom)  # plotly drew it
        dom = chromium(browser.url + "study-1.html", tmp_path)
        assert re.search(r'id="aerobat-page-status"[^>]*>ok: 0 figures<', dom)
        dom = chromium(browser.url + "compare.html?ids=1,2,3", tmp_path)
        assert re.search(r'id="errors-figure"[^>]*data-drawn="yes"', dom), dom[:2000]
        assert dom.count('class="scatterlayer') == 1 and dom.count('class="trace scatter') == 3  # three curves
        assert "They differ in: <strong>plant, feedback, seed, rule" in dom


@pytest.mark.slow
def test_browse_screenshots_for_the_docs(store_path, tmp_path):
    """Regenerates docs/figures/browse.png and browse_session.png (slow suite)."""
    with start(store_path, port=0) as browser:
        for name, page in (("browse.png", ""), ("browse_session.png", "session-1.html")):
            target = ROOT / "docs" / "figures" / name
            chromium(browser.url + page, tmp_path, screenshot=target)
            assert target.stat().st_size > 10_000
