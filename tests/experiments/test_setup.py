"""`aerobat setup [--check]` (issue 28): what an installation has, what it lacks, and what still works."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest

from aerobat.experiments.installation import PieceKind, SetupStep, check_installation, set_up


def _check(env_path: str, tmp_path) -> tuple[int, str]:
    env = {**os.environ, "PATH": env_path, "XDG_CACHE_HOME": str(tmp_path / "cache")}
    result = subprocess.run([sys.executable, "-m", "aerobat", "setup", "--check"], capture_output=True, text=True,
                            env=env, timeout=120, cwd=tmp_path)
    return result.returncode, result.stdout + result.stderr


def test_check_without_a_compiler_or_chromium_names_them_and_what_still_works(tmp_path):
    empty = tmp_path / "bin"
    empty.mkdir()
    code, text = _check(str(empty), tmp_path)
    assert code == 0, text  # aerobat works: only optional pieces are missing
    lines = text.splitlines()
    compiler = next(line for line in lines if "C compiler, make, patch" in line)
    assert compiler.startswith("missing") and "a C compiler (gcc or cc)" in compiler
    assert any("apt-get install build-essential" in line for line in lines)
    assert any(line.startswith("missing") and "chromium" in line for line in lines)
    assert any(line.startswith("missing") and "Betaflight 4.6 SITL" in line for line in lines)  # no SITL in the cache
    assert "aerobat works;" in lines[-1] and "optional pieces missing" in lines[-1]


def test_check_json_on_this_machine_matches_what_is_on_path(tmp_path):
    env = {**os.environ}
    result = subprocess.run([sys.executable, "-m", "aerobat", "setup", "--check", "--json"], capture_output=True,
                            text=True, env=env, timeout=120)
    assert result.returncode == 0
    pieces = {p["name"]: p for p in json.loads(result.stdout)["pieces"]}
    assert pieces["python dependencies"]["present"] and pieces["python dependencies"]["kind"] == "required"
    assert pieces["chromium"]["present"] == (shutil.which("chromium") is not None
                                             or shutil.which("chromium-browser") is not None
                                             or shutil.which("google-chrome") is not None)
    assert pieces["C compiler, make, patch"]["present"] == all(shutil.which(t) for t in ("make", "patch")) and bool(
        shutil.which(os.environ.get("CC", "gcc")) or shutil.which("cc"))
    for piece in pieces.values():
        assert piece["present"] or piece["how_to_get"], piece


def test_set_up_without_a_compiler_skips_the_sitl_with_the_reason(tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    result = set_up(betaflight=True, kernels=False)
    assert result.steps[0][0] == "betaflight" and result.steps[0][1] is SetupStep.SKIPPED
    assert "C compiler" in result.steps[0][2] and "build-essential" in result.steps[0][2]
    assert not result.failed and result.report.ok
    assert not result.report.piece("Betaflight 4.6 SITL").present


def test_the_report_says_required_from_optional():
    report = check_installation()
    kinds = {p.name: p.kind for p in report.pieces}
    assert kinds["python dependencies"] is PieceKind.REQUIRED
    assert all(kind is PieceKind.OPTIONAL for name, kind in kinds.items() if name != "python dependencies")
    with pytest.raises(KeyError):
        report.piece("no such piece")


def test_setup_compiles_only_the_kernel_groups_asked_for_and_names_the_groups_it_knows(capsys):
    """make demo compiles the playback and arena groups only (`aerobat setup --kernels playback,arena`)."""
    from aerobat.cli import main
    from aerobat.experiments.warmup import PARTS, warm_up

    assert PARTS == ("playback", "arena", "plants", "firmware")
    assert main(["setup", "--no-betaflight", "--kernels", "playback,sitl"]) == 2
    err = capsys.readouterr().err
    assert "--kernels playback,sitl: unknown group(s) sitl; allowed: playback, arena, plants, firmware" in err
    with pytest.raises(ValueError, match="unknown kernel group"):
        warm_up(parts=("nope",))
    lines: list[str] = []
    warm_up(workers=1, progress=lines.append, parts=("playback",))  # cached here: seconds
    assert [line.split()[0] for line in lines] == ["playback"]
