"""`aerobat replay`: one self-contained HTML file that renders in headless Chromium without errors (issue 16)."""

from __future__ import annotations

import contextlib
import io
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from aerobat.cli import main

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def call(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def render(html: Path, tmp: Path, *, screenshot: Path | None = None) -> str:
    """The page's status after Chromium ran it headless (``ok``, or ``error: …``)."""
    if not CHROMIUM:
        pytest.skip("no chromium on PATH: only the rendering is skipped (CI installs Debian's chromium; "
                    "locally: apt-get install chromium as root)")
    command = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
               "--disable-component-update", "--disable-sync", "--no-first-run", f"--user-data-dir={tmp / 'profile'}",
               "--virtual-time-budget=20000", "--window-size=1100,800"]
    command += [f"--screenshot={screenshot}"] if screenshot else ["--dump-dom"]
    result = subprocess.run([*command, html.resolve().as_uri()], capture_output=True, text=True, timeout=180)
    assert result.returncode == 0, result.stderr[-2000:]
    match = re.search(r'id="aerobat-replay-status"[^>]*>([^<]*)<', result.stdout)
    return match.group(1) if match else ("" if screenshot else "no status")


def test_replay_is_one_offline_file_that_renders_without_errors(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, _, err = call(["learn", "flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "800", "--plant", "arena",
                         "--iterations", "3"])
    assert code == 0, err
    code, out, err = call(["replay", "last"])
    assert code == 0, err
    html = next((tmp_path / "out").glob("aerobat-*/session-1")) / "replay.html"
    text = html.read_text()
    assert "plotly" in text and not re.search(r'<script[^>]+src="https?://', text)  # nothing fetched
    assert render(html, tmp_path) == "ok"


def test_replay_of_chosen_iterations_and_bad_ones(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert call(["learn", "flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "800", "--plant", "arena",
                 "--iterations", "3"])[0] == 0
    code, _, err = call(["replay", "1", "--iterations", "2", "--out", "r"])
    assert code == 0, err and (tmp_path / "r" / "replay.html").exists()
    code, _, err = call(["replay", "1", "--iterations", "99"])
    assert code == 2 and "99" in err


@pytest.mark.slow
def test_replay_screenshot_for_the_docs(tmp_path, monkeypatch):
    """Regenerates docs/figures/replay.png (slow suite)."""
    monkeypatch.chdir(tmp_path)
    assert call(["learn", "flip", "--flips", "3", "--dims", "3", "--plant", "arena", "--seed", "1",
                 "--iterations", "30"])[0] == 0
    assert call(["replay", "1"])[0] == 0
    target = Path(__file__).resolve().parents[2] / "docs" / "figures" / "replay.png"
    render(next((tmp_path / "out").glob("aerobat-*/session-1")) / "replay.html", tmp_path, screenshot=target)
    assert target.stat().st_size > 10_000
