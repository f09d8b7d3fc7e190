"""Documented means tested: every command and snippet in README.md and docs/*.md runs here.

Each document's shell commands run in order, in a fresh folder (the repository's
``examples`` linked in, no ``$AEROBAT_DB``), so a document's later commands see what its
earlier ones stored. The fast suite runs them with smaller sizes (fewer iterations, seeds,
vehicles, grid points; the rule is :func:`smaller`); the slow suite runs them as written.
Python blocks run too: a document's blocks, in order, are saved as one script in that folder and run
by the venv's Python in a process of their own, as a reader would save and run them (issue 44).
A command the suite cannot run is listed in ``NOT_RUN`` with the reason.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import shlex
import signal
import socket
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from aerobat.cli import main

ROOT = Path(__file__).resolve().parents[2]
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
VENV_BIN = Path(sys.executable).parent
SHARED = ROOT.parent / "shared"  # real data recorded by others, beside the clone (../shared/data)

NOT_RUN = {
    "make test": "the suite itself (CI runs it)",
    "make test-slow": "the slow suite (it contains this test's slow variant)",
    "make bench": "benchmarks rewrite docs/performance.md; run by hand",
    "make test-release": "builds and installs the wheel in a new venv (minutes); CI runs it (.ci/run)",
    "make docs": "tests/docs/test_docs_site.py builds the site with mkdocs --strict; CI runs it too",
    "make lint": "ruff, mypy and the import contracts: tests/house/test_architecture.py runs the contracts",
    "pip install": "installs packages; `make setup` installs the same extras on every machine",
}


def blocks(path: Path) -> list[tuple[str, str]]:
    """(language, body) of every fenced block."""
    return re.findall(r"```(\w*)\n(.*?)```", path.read_text(), re.S)


def commands(path: Path) -> list[str]:
    """The shell commands of a document, continuation lines joined, comments dropped, `;` split."""
    out: list[str] = []
    for language, body in blocks(path):
        if language not in ("sh", "bash"):
            continue
        for line in body.replace("\\\n", " ").splitlines():
            line = re.sub(r"\s+#.*$", "", line).strip()
            if not line or line.startswith("#"):
                continue
            out += [part.strip() for part in line.split(";") if part.strip()]
    return out


def _shrink_iterations(match: re.Match[str]) -> str:
    n = int(match.group(2))
    return f"{match.group(1)}{2 if n <= 30 else 2 + (n - 30) // 5}"


def smaller(command: str) -> str:
    """The same command with sizes a test can afford (documented in this module's docstring)."""
    command = re.sub(r"(--(?:trials|iterations)[ =])(\d+)", _shrink_iterations, command)
    command = re.sub(r"(--seeds[ =])(\d+)", r"\g<1>1", command)
    command = re.sub(r"(--vehicles[ =])(\d+)", r"\g<1>2", command)
    command = re.sub(r"(--[yz](?:-m)?[ =]-?[\d.]+:-?[\d.]+:)(\d+)", r"\g<1>2", command)
    command = re.sub(r"(--rates-deg-s[ =][\d.]+:[\d.]+:)(\d+)", r"\g<1>2", command)
    if " study rules" in command and "--trials" not in command:
        command += " --trials 3"
    return command


SLOW_ONLY = {
    ".venv/bin/python benchmarks/": "regenerates published results (minutes); runs in the slow suite as written",
    "aerobat learn flip --flips 3 --max-rate-deg-s 1800 --dims 3 --plant fc": (
        "flies the real-time rehearsal (30 trials, about 9 minutes; 2 trials still take 40 s of wall clock); the "
        "fast suite flies --plant fc through the CLI in tests/plants/betaflight/test_fc_rehearsal.py"),
    ".venv/bin/python scripts/results_fc.py summary": "summarizes the session the command above stored",
}


def _not_run(command: str) -> str | None:
    return next((why for prefix, why in NOT_RUN.items() if command.startswith(prefix)), None)


def _demo_command() -> str:
    """`make demo` is the Makefile's demo recipe: run its aerobat command."""
    recipe = re.search(r"^demo:.*?\n((?:\t.*\n)+)", (ROOT / "Makefile").read_text(), re.M)
    assert recipe, "the Makefile has no demo recipe"
    line = " ".join(part.strip().rstrip("\\") for part in recipe.group(1).splitlines())
    return line.replace("$(VENV)/bin/", "").replace("$(OUT)", "out")


@contextlib.contextmanager
def _dask_cluster(tmp: Path):
    """A real scheduler and worker on loopback, as docs/scaling.md starts them (ended afterwards)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    scheduler = subprocess.Popen([str(VENV_BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                                  "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp,
                                 start_new_session=True)
    worker = subprocess.Popen([str(VENV_BIN / "dask"), "worker", f"tcp://127.0.0.1:{port}", "--nworkers", "2",
                               "--nthreads", "1", "--no-dashboard"], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, cwd=tmp, start_new_session=True)
    try:
        yield f"tcp://127.0.0.1:{port}"
    finally:
        for proc in (worker, scheduler):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGTERM)
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=20)
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)


def run_document(path: Path, tmp: Path, *, small: bool) -> list[str]:
    """Run every command of ``path`` in ``tmp``; returns the commands run (as run)."""
    (tmp / "examples").symlink_to(ROOT / "examples")
    (tmp / "benchmarks").symlink_to(ROOT / "benchmarks")
    (tmp / "scripts").symlink_to(ROOT / "scripts")
    env = dict(os.environ)  # as written: no test plugin on the path (docs/maneuvers.md names a file instead)
    env.pop("AEROBAT_DB", None)
    ran: list[str] = []
    cluster: contextlib.ExitStack = contextlib.ExitStack()
    address = None
    sqlite_db = None
    with cluster:
        for command in commands(path):
            if _not_run(command) or (small and any(command.startswith(p) for p in SLOW_ONLY)):
                continue
            if "../shared/" in command:
                if not (SHARED / "data").is_dir():
                    pytest.skip(f"{path.name} reads ../shared/data (real flight logs), absent beside this clone")
                command = command.replace("../shared/", f"{SHARED}/")
            if command == "make demo":
                command = _demo_command()
            if small:
                command = smaller(command)
            if command.startswith("dask scheduler"):
                address = cluster.enter_context(_dask_cluster(tmp))
                continue
            if command.startswith("dask worker"):
                assert address, "a worker without a scheduler"
                continue
            command = command.replace("tcp://SCHEDULER_HOST:8786", address or "tcp://SCHEDULER_HOST:8786")
            if command.startswith("sqlite3 "):
                sqlite_db = str(tmp / shlex.split(command)[-1])
                continue
            if command.startswith("sqlite> "):
                assert sqlite_db, "sqlite> without `sqlite3 FILE`"
                statement = command.removeprefix("sqlite> ")
                if statement.startswith("."):
                    result = subprocess.run(["sqlite3", "-readonly", sqlite_db, statement], capture_output=True,
                                            text=True, timeout=60)
                    assert result.returncode == 0, (command, result.stderr)
                else:
                    with sqlite3.connect(f"file:{sqlite_db}?mode=ro", uri=True) as conn:
                        conn.execute(statement.rstrip(";")).fetchall()
                ran.append(command)
                continue
            argv = shlex.split(command)
            if argv[0] == "aerobat":
                out, err = io.StringIO(), io.StringIO()
                cwd = os.getcwd()
                os.chdir(tmp)
                try:
                    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                        code = main(argv[1:])
                finally:
                    os.chdir(cwd)
                assert code == 0, f"{path.name}: `{command}` exited {code}:\n{err.getvalue()[-2000:]}"
            else:
                if argv[0].startswith(".venv/bin/"):
                    argv[0] = str(VENV_BIN / Path(argv[0]).name)
                result = subprocess.run(argv, capture_output=True, text=True, timeout=3600, cwd=tmp, env=env)
                assert result.returncode == 0, f"{path.name}: `{command}`:\n{result.stderr[-2000:]}"
            ran.append(command)
        snippets = [re.sub(r"iterations=30", "iterations=3", body) if small else body
                    for language, body in blocks(path) if language == "python"]
        if snippets:  # saved to a file in the folder and run as a reader would (issue 44), not exec'd in here
            script = tmp / f"{path.stem.lower()}_snippets.py"
            script.write_text("\n\n".join(snippets))
            result = subprocess.run([sys.executable, script.name], capture_output=True, text=True, timeout=1800,
                                    cwd=tmp, env=env)
            assert result.returncode == 0, f"{path.name}: its python blocks, saved as {script.name}:\n" \
                                           f"{result.stderr[-3000:]}"
            ran += ["python block"] * len(snippets)
    return ran


def _ids(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


def test_every_document_has_been_looked_at():
    """A new document's commands are picked up automatically; this names the ones with commands."""
    with_commands = {_ids(p) for p in DOCUMENTS if commands(p) or any(lang == "python" for lang, _ in blocks(p))}
    assert {"README.md", "docs/store.md", "docs/maneuvers.md", "docs/scaling.md"} <= with_commands


REAL_TIME = {"docs/real-vehicle.md"}
"""Documents whose commands fly on the wall clock (the real-time rehearsal): they run in the suite's one
``real_time`` group of tests (tests/conftest.py), never beside another real-time flight."""


def _documents() -> list:
    return [pytest.param(p, marks=pytest.mark.xdist_group("real_time")) if _ids(p) in REAL_TIME else p
            for p in DOCUMENTS]


@pytest.mark.parametrize("path", _documents(), ids=_ids)
def test_documented_commands_run(tmp_path, path):
    started = time.perf_counter()
    ran = run_document(path, tmp_path, small=True)
    assert ran or all(_not_run(c) or any(c.startswith(p) for p in SLOW_ONLY) for c in commands(path))
    assert time.perf_counter() - started < 600


@pytest.mark.slow
@pytest.mark.parametrize("path", DOCUMENTS, ids=_ids)
def test_documented_commands_run_as_written(tmp_path, path):
    run_document(path, tmp_path, small=False)


def test_the_study_snippet_runs_as_a_saved_script_and_refuses_to_run_without_its_guard(tmp_path):
    """Issue 44: docs/feedback.md's study, saved to a file in an empty folder and run as a reader would. Without its
    ``if __name__ == "__main__":`` every spawned worker died at start and the study printed "2 of 2 runs failed"
    with exit status 0; now nothing that did not run is reported, and the script fails."""
    body = next(code for language, code in blocks(ROOT / "docs" / "feedback.md")
                if language == "python" and "feedback_study" in code)
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    guarded, bare = tmp_path / "guarded", tmp_path / "bare"
    guarded.mkdir()
    bare.mkdir()
    (guarded / "study.py").write_text(body)
    result = subprocess.run([sys.executable, "study.py"], cwd=guarded, capture_output=True, text=True, timeout=600,
                            env=env)
    assert result.returncode == 0, result.stderr[-2000:]
    assert [line.split()[0] for line in result.stdout.splitlines()] == ["none", "tracking"]
    assert "0 of 2 runs failed" in result.stdout
    top_level = body.split("\n\nif __name__")[0].replace("def main() -> None:\n", "if True:\n") + "\n"
    (bare / "study.py").write_text(top_level)
    result = subprocess.run([sys.executable, "study.py"], cwd=bare, capture_output=True, text=True, timeout=600,
                            env=env)
    assert result.returncode != 0
    assert "WorkersUnavailable" in result.stderr and "nothing ran" in result.stderr
    assert "runs failed" not in result.stdout
