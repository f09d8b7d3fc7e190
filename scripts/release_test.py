"""The release, as a pip user gets it: ``make test-release`` (CI runs it after ``make test``).

1. ``python -m build`` makes the sdist and the wheel from this clone into a temporary folder;
   the wheel must carry the vehicle presets, the Betaflight patch and settings, and the examples.
2. A new venv outside the clone installs the wheel (with the ``replay``, ``logs`` and ``viewers`` extras) from
   the package index, as ``pip install aerobat-*.whl`` would.
3. From a folder that is not the clone, with no PYTHONPATH: ``aerobat setup`` (reuses a built
   SITL in ``~/.cache/aerobat``; compiles the kernels), ``aerobat setup --check``, ``aerobat
   examples``, the README's quick-start learn (``make demo``'s command) and its first library
   snippet, and ``aerobat simulate`` on a shipped example.

Every step is printed with its time; the first failure ends the run with exit status 1.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXTRAS = "replay,logs,viewers"
MUST_SHIP = ("aerobat/quadrotor/vehicles/hummingbird.toml", "aerobat/firmware/betaflight/lockstep.patch",
             "aerobat/firmware/betaflight/sitl_settings.json", "aerobat/examples/single_flip.toml",
             "aerobat/examples/maneuvers/", "aerobat/py.typed")


class StepFailed(RuntimeError):
    pass


def run(what: str, command: list[str], *, cwd: Path, env: dict[str, str], timeout_s: float) -> str:
    start = time.perf_counter()
    print(f"--> {what}: {' '.join(command)}", flush=True)
    try:
        result = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        raise StepFailed(f"{what}: no result within {timeout_s:.0f} s") from None
    print(f"    {time.perf_counter() - start:.1f} s, exit {result.returncode}", flush=True)
    if result.returncode != 0:
        raise StepFailed(f"{what}: exit {result.returncode}\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}")
    return result.stdout


def readme_demo_command() -> list[str]:
    recipe = re.search(r"^demo:.*?\n((?:\t.*\n)+)", (ROOT / "Makefile").read_text(), re.M)
    if recipe is None:
        raise StepFailed("the Makefile has no demo recipe")
    line = " ".join(part.strip().rstrip("\\") for part in recipe.group(1).splitlines())
    return line.replace("$(VENV)/bin/", "").replace("$(OUT)", "out").split()


def readme_snippet() -> str:
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.S)
    if not blocks:
        raise StepFailed("README.md has no Python block")
    return blocks[0]


def check_wheel(wheel: Path) -> None:
    names = zipfile.ZipFile(wheel).namelist()
    for needed in MUST_SHIP:
        if not any(n.startswith(needed) for n in names):
            raise StepFailed(f"{wheel.name} does not carry {needed}")
    print(f"    {wheel.name}: {len(names)} files, carries {', '.join(MUST_SHIP)}", flush=True)


def release_test(work: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "AEROBAT_DB")}
    dist = work / "dist"
    run("build the sdist and the wheel", [sys.executable, "-m", "build", "--outdir", str(dist), str(ROOT)],
        cwd=work, env=env, timeout_s=900)
    wheels = sorted(dist.glob("aerobat-*.whl"))
    if len(wheels) != 1 or not list(dist.glob("aerobat-*.tar.gz")):
        raise StepFailed(f"expected one wheel and one sdist in {dist}, found {[p.name for p in dist.iterdir()]}")
    check_wheel(wheels[0])
    venv = work / "venv"
    python = shutil.which("python3") or sys.executable
    run("a new venv outside the clone", [python, "-m", "venv", str(venv)], cwd=work, env=env, timeout_s=300)
    bin_dir = venv / "bin"
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    run("pip install the wheel", [str(bin_dir / "python"), "-m", "pip", "install", "--quiet",
                                  f"{wheels[0]}[{EXTRAS}]"], cwd=work, env=env, timeout_s=1800)
    user = work / "user"
    user.mkdir()
    where = run("the package is the installed one", [str(bin_dir / "python"), "-c",
                                                     "import aerobat; print(aerobat.__file__)"],
                cwd=user, env=env, timeout_s=120).strip()
    if not where.startswith(str(venv)):
        raise StepFailed(f"aerobat was imported from {where}, not from the new venv")
    aerobat = str(bin_dir / "aerobat")
    run("aerobat setup", [aerobat, "setup"], cwd=user, env=env, timeout_s=1800)
    print(run("aerobat setup --check", [aerobat, "setup", "--check"], cwd=user, env=env, timeout_s=120), flush=True)
    run("aerobat examples", [aerobat, "examples", "examples"], cwd=user, env=env, timeout_s=120)
    run("aerobat simulate a shipped example", [aerobat, "simulate", "examples/single_flip.toml", "--json"],
        cwd=user, env=env, timeout_s=300)
    demo = readme_demo_command()
    run("the quick-start learn (make demo's command)", [aerobat, *demo[1:]], cwd=user, env=env, timeout_s=1800)
    if not (user / "out" / "demo" / "learning.png").is_file():
        raise StepFailed("the quick-start learn wrote no out/demo/learning.png")
    (user / "snippet.py").write_text(readme_snippet())
    run("README's library snippet", [str(bin_dir / "python"), "snippet.py"], cwd=user, env=env, timeout_s=1800)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", action="store_true", help="keep the temporary folder (default: remove it)")
    args = parser.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="aerobat-release-"))
    start = time.perf_counter()
    try:
        release_test(work)
    except StepFailed as exc:
        print(f"release test FAILED: {exc}", file=sys.stderr)
        return 1
    finally:
        if args.keep:
            print(f"kept {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)
    print(f"release test passed in {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
