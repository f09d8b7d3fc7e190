"""The command line's defaults and failures as a new user meets them.

Store commands work without ``--db``; a rules study refuses before any job when a baseline
package is missing and takes the RotorPy settings on RotorPy; a missing optional package gives
its install hint; a library's ValueError and a full disk are failures (exit 1), not bad input.
These are the five defects issue 12 ("The house") found: every test failed on the code before
that restructuring and passes after it.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import resource
import signal
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from aerobat.cli import main

ROOT = Path(__file__).resolve().parents[2]
SMALL_FLIP = ["flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "800"]


def call(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 2
    return code, out.getvalue(), err.getvalue()


def aerobat() -> list[str]:
    return [sys.executable, "-m", "aerobat.cli"]


# ------------------------------------------------------------------ defect 1


@pytest.mark.parametrize("argv", [
    ["benchmark", "map", "--y=1:2:2", "--z=1:1:1", "--workers", "1"],
    ["study", "envelope", "--flips", "1", "--rates-deg-s", "800", "--workers", "1"],
    ["study", "robustness", *SMALL_FLIP, "--vehicles", "1", "--iterations", "2", "--workers", "1"],
    ["study", "rules", *SMALL_FLIP, "--methods", "paper", "--seeds", "1", "--trials", "2", "--workers", "1"],
], ids=["benchmark-map", "study-envelope", "study-robustness", "study-rules"])
def test_store_commands_work_without_db(tmp_path, monkeypatch, argv):
    """Defect 1: without --db these crashed with a TypeError on ``None`` as a path."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("AEROBAT_DB", raising=False)
    code, out, err = call(argv)
    assert code == 0, err
    assert "internal error" not in err
    assert (tmp_path / "aerobat.sqlite").is_file()
    with sqlite3.connect(tmp_path / "aerobat.sqlite") as db:
        assert db.execute("SELECT count(*) FROM studies").fetchone()[0] == 1


def test_every_store_subcommand_works_without_db(tmp_path, monkeypatch):
    """Every command that touches the store uses ./aerobat.sqlite (or $AEROBAT_DB) when --db is not given."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("AEROBAT_DB", raising=False)
    steps = [
        ["learn", *SMALL_FLIP, "--plant", "nominal", "--iterations", "2"],
        ["learn", "--resume", "last", "--iterations", "3"],
        ["sessions"], ["sessions", "--json"], ["show", "last"], ["show", "1", "--json"], ["plot", "1"],
        ["export", "1"], ["export", "1", "--format", "json", "--output", "s1.json"],
        ["study", "envelope", "--flips", "1", "--rates-deg-s", "800", "--workers", "1"],
        ["studies"], ["studies", "last"], ["sessions", "--study", "1"],
    ]
    for argv in steps:
        code, out, err = call(argv)
        assert code == 0, (argv, err)
    assert (tmp_path / "aerobat.sqlite").is_file() and (tmp_path / "s1.json").is_file()
    assert next((tmp_path / "out").glob("aerobat-*/session-1")).joinpath("learning.png").is_file()  # per store, session
    monkeypatch.setenv("AEROBAT_DB", str(tmp_path / "other.sqlite"))
    code, out, err = call(["learn", *SMALL_FLIP, "--plant", "nominal", "--iterations", "1"])
    assert code == 0, err
    assert (tmp_path / "other.sqlite").is_file()


# ------------------------------------------------------------------ defect 2


def test_rules_study_refuses_before_any_job_when_a_baseline_package_is_missing(tmp_path, monkeypatch):
    """Defect 2: a missing ``cma`` made every CMA-ES job fail silently, filtered out, exit 0."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setitem(sys.modules, "cma", None)  # `import cma` fails as if it were not installed
    code, out, err = call(["study", "rules", *SMALL_FLIP, "--methods", "paper,cma", "--seeds", "1",
                           "--trials", "2", "--workers", "1", "--db", "s.sqlite"])
    assert code != 0
    assert "cma" in err and "pip install" in err and "internal error" not in err
    if (tmp_path / "s.sqlite").exists():
        with sqlite3.connect(tmp_path / "s.sqlite") as db:
            assert db.execute("SELECT count(*) FROM study_jobs").fetchone()[0] == 0


def test_rules_study_reports_every_method_with_the_baselines_installed(tmp_path, monkeypatch):
    """Defect 2: on a fresh install all four methods of the README's command are reported."""
    pytest.importorskip("cma")
    pytest.importorskip("bayes_opt")
    monkeypatch.chdir(tmp_path)
    code, out, err = call(["study", "rules", *SMALL_FLIP, "--methods", "paper,tsvd,cma,bayesopt", "--seeds",
                           "1", "--trials", "3", "--workers", "2", "--json"])
    assert code == 0, err
    report = json.loads(out)
    assert sorted(row["method"] for row in report["methods"]) == ["bayesopt", "cma", "paper", "tsvd"]
    assert all(row["runs"] == 1 for row in report["methods"])
    code, out, err = call(["study", "rules", *SMALL_FLIP, "--methods", "paper", "--seeds", "1", "--trials", "2",
                           "--workers", "1", "--db", "plain.sqlite"])
    assert code == 0, err
    assert "[1/1] " in err and "[1/1] " not in out  # issue 44: progress on standard error, as docs/cli.md says


# ------------------------------------------------------------------ defect 4


def test_rules_study_on_rotorpy_takes_the_rotorpy_settings(tmp_path, monkeypatch):
    """Defect 4: ``study rules --plant rotorpy`` ignored the RotorPy settings; a bad file must be refused."""
    monkeypatch.chdir(tmp_path)
    settings = tmp_path / "rp.toml"
    settings.write_text("[simulation]\nno_such_field = 1\n")
    code, out, err = call(["study", "rules", *SMALL_FLIP, "--methods", "paper", "--seeds", "1", "--trials", "2",
                           "--plant", "rotorpy", "--rotorpy", str(settings), "--workers", "1"])
    assert code == 2, err
    assert str(settings) in err and "no_such_field" in err


# ------------------------------------------------------------------ defect 5


def test_a_missing_optional_package_gives_its_install_hint_not_an_internal_error(tmp_path, monkeypatch):
    """Defect 5: a missing RotorPy was reported as ``internal error: ImportError``."""
    monkeypatch.chdir(tmp_path)
    for name in ("rotorpy", "rotorpy.vehicles", "rotorpy.vehicles.multirotor", "rotorpy.vehicles.hummingbird_params"):
        monkeypatch.setitem(sys.modules, name, None)
    code, out, err = call(["learn", *SMALL_FLIP, "--plant", "rotorpy", "--iterations", "1"])
    assert code == 1, err
    assert "internal error" not in err
    assert "pip install 'aerobat[rotorpy]'" in err


def test_a_value_error_from_a_library_is_a_failure_not_bad_input(tmp_path, monkeypatch):
    """Defect 5: any ``ValueError`` (numpy, scipy, a bug) became a usage error with exit 2."""
    monkeypatch.chdir(tmp_path)
    import numpy as np

    def broken(*args, **kwargs):
        raise np.linalg.LinAlgError("SVD did not converge")  # a ValueError subclass from numpy

    monkeypatch.setattr(np.linalg, "svd", broken)
    code, out, err = call(["design", *SMALL_FLIP])
    assert code not in (0, 2), err
    assert "internal error" in err and "LinAlgError" in err


def _limit_file_size(limit: int):
    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    return apply


def test_a_full_disk_while_writing_output_is_a_failure_not_bad_input(tmp_path):
    """Defect 5: a full disk (here: the file size limit) was reported as bad input (exit 2)."""
    result = subprocess.run([*aerobat(), "simulate", str(ROOT / "examples" / "single_flip.toml"), "--plot",
                             str(tmp_path / "flip.png")], capture_output=True, text=True, timeout=300,
                            preexec_fn=_limit_file_size(2000), cwd=tmp_path, env={**os.environ, "MPLBACKEND": "Agg"})
    assert result.returncode == 1, result.stderr
    assert "Traceback" not in result.stderr
    assert result.stderr.startswith("aerobat: failed:") and ("disk" in result.stderr or "too large" in result.stderr)


def test_a_ctrl_c_that_lands_in_a_finalizer_still_stops_the_command(capfd) -> None:
    """The full fuzz campaign (issue 45): a Ctrl-C delivered while the garbage collector ran a weak reference's
    callback was dropped by Python ("Exception ignored in …", a traceback) and the command went on."""
    import gc
    import time

    from aerobat.cli.app import _interrupts_redelivered

    class Finalized:
        def __del__(self) -> None:
            raise KeyboardInterrupt  # what Python's SIGINT handler raises wherever the main thread is

    with _interrupts_redelivered(), pytest.raises(KeyboardInterrupt):
        Finalized()  # dropped at once: its finalizer's exception cannot propagate
        gc.collect()
        for _ in range(100):
            time.sleep(0.01)
    assert "Exception ignored" not in capfd.readouterr().err
