"""What an installation of aerobat has, what it lacks, and setting up the rest: ``aerobat setup``.

A pip user gets the Python package and its declared dependencies; three more pieces make the
commands start at once and fly every plant: the numba kernels compiled into their on-disk cache,
the Betaflight 4.6 SITL built with aerobat's lockstep patch (``--plant betaflight``), and the
optional packages of each extra. :func:`check_installation` looks without installing anything;
:func:`set_up` builds the SITL (when a C compiler is there) and compiles the kernels, then looks.
No step needs root: the SITL goes to the user's cache folder, the kernels beside the package.
"""

from __future__ import annotations

import enum
import importlib.util
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "EXTRAS",
    "InstallationReport",
    "Piece",
    "PieceKind",
    "SetupResult",
    "SetupStep",
    "check_installation",
    "set_up",
]

Progress = Callable[[str], None]


class PieceKind(enum.Enum):
    """Whether aerobat's core needs a piece, or only some commands or tests do."""

    REQUIRED = "required"
    OPTIONAL = "optional"


@dataclass(frozen=True)
class Piece:
    """One piece of an installation: a package, a tool, the SITL, the compiled kernels."""

    name: str
    kind: PieceKind
    present: bool
    detail: str  #: where it was found, or what was looked for
    enables: str  #: what works with it (and what does not without it)
    how_to_get: str  #: one command or step that provides it; "" when present


@dataclass(frozen=True)
class InstallationReport:
    """Every piece :func:`check_installation` looked at, in a fixed order."""

    pieces: tuple[Piece, ...]

    @property
    def missing(self) -> tuple[Piece, ...]:
        return tuple(p for p in self.pieces if not p.present)

    @property
    def ok(self) -> bool:
        """True when every required piece is present (optional ones may be missing)."""
        return all(p.present for p in self.pieces if p.kind is PieceKind.REQUIRED)

    def piece(self, name: str) -> Piece:
        for p in self.pieces:
            if p.name == name:
                return p
        raise KeyError(name)


#: pyproject's extras: the import names each brings, and what they enable
EXTRAS: dict[str, tuple[tuple[str, ...], str]] = {
    "rotorpy": (("rotorpy",), "--plant rotorpy (RotorPy's Hummingbird as the vehicle)"),
    "fc": (("serial", "motioncapture"), "--plant fc (a Betaflight board on a serial port with motion capture, "
                                        "and its real-time rehearsal)"),
    "dask": (("distributed",), "studies on a Dask cluster (--scheduler tcp://HOST:PORT)"),
    "baselines": (("cma", "bayes_opt"), "the rules study's CMA-ES and Bayesian-optimisation baselines"),
    "replay": (("plotly",), "aerobat replay: the 3D replay page"),
    "logs": (("pyulog", "orangebox"), "aerobat log and identify --log for PX4 ULog and Betaflight blackbox logs"),
    "viewers": (("jinja2", "mcap", "mcap_protobuf", "foxglove_schemas_protobuf"),
                "aerobat browse (the store's web pages) and aerobat export --format mcap (Foxglove)"),
    "test": (("pytest", "xdist", "hypothesis"), "the test suite (make test, on every core with pytest-xdist)"),
    "docs": (("mkdocs", "material", "mkdocstrings", "mkdocs_jupyter", "nbclient"),
             "the documentation site (mkdocs build) and the executed tutorial"),
}

_CORE_MODULES = ("numpy", "scipy", "numba", "matplotlib", "rich", "tomli_w", "casadi", "threadpoolctl")


def _module_present(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, ValueError):
        return False


def _core_piece() -> Piece:
    absent = [m for m in _CORE_MODULES if not _module_present(m)]
    return Piece("python dependencies", PieceKind.REQUIRED, not absent,
                 "all of " + ", ".join(_CORE_MODULES) if not absent else "missing: " + ", ".join(absent),
                 "every command", "" if not absent else "pip install aerobat (its dependencies)")


def _extra_pieces() -> list[Piece]:
    pieces = []
    for extra, (modules, enables) in EXTRAS.items():
        absent = [m for m in modules if not _module_present(m)]
        pieces.append(Piece(f"extra [{extra}]", PieceKind.OPTIONAL, not absent,
                            ", ".join(modules) if not absent else "missing: " + ", ".join(absent), enables,
                            "" if not absent else f"pip install 'aerobat[{extra}]'"))
    return pieces


def _tool(name: str, *candidates: str) -> str | None:
    for c in candidates:
        found = shutil.which(c)
        if found:
            return found
    return None


def _compiler_piece() -> Piece:
    cc = _tool("cc", os.environ.get("CC", "gcc"), "gcc", "cc")
    make = _tool("make", "make")
    patch = _tool("patch", "patch")
    absent = [n for n, f in (("a C compiler (gcc or cc)", cc), ("make", make), ("patch", patch)) if f is None]
    return Piece("C compiler, make, patch", PieceKind.OPTIONAL, not absent,
                 ", ".join(f for f in (cc, make, patch) if f) if not absent else "missing: " + ", ".join(absent),
                 "building the Betaflight SITL (only needed once; a built SITL keeps working without them)",
                 "" if not absent else "install gcc, make and patch (Debian: apt-get install build-essential patch)")


def _sitl_path() -> Path:
    from aerobat.firmware.betaflight.build import BINARY_NAME, build_dir_for, find_patch

    return build_dir_for(find_patch()) / BINARY_NAME


def _sitl_piece() -> Piece:
    binary = _sitl_path()
    present = binary.is_file() and os.access(binary, os.X_OK)
    return Piece("Betaflight 4.6 SITL", PieceKind.OPTIONAL, present,
                 str(binary) if present else f"not built ({binary} absent)",
                 "--plant betaflight and its tests (skipped with the reason without it)",
                 "" if present else "aerobat setup (needs a C compiler, make, patch and PyPI access)")


def _kernel_cache_dirs() -> list[Path]:
    import aerobat

    dirs = [Path(aerobat.__file__).parent]
    if os.environ.get("NUMBA_CACHE_DIR"):
        dirs.append(Path(os.environ["NUMBA_CACHE_DIR"]))
    return dirs


def _compiled_kernels() -> int:
    """How many numba cache index files (``*.nbi``) aerobat's kernels have on disk."""
    return sum(1 for d in _kernel_cache_dirs() if d.is_dir() for _ in d.rglob("*.nbi"))


def _kernels_piece() -> Piece:
    count = _compiled_kernels()
    return Piece("compiled kernels", PieceKind.OPTIONAL, count > 0,
                 f"{count} cached kernel index files" if count else "no cached kernels found",
                 "commands start at once (without it the first command compiles for one to two minutes)",
                 "" if count else "aerobat setup (or python -m aerobat.experiments.warmup)")


def _chromium_piece() -> Piece:
    found = _tool("chromium", "chromium", "chromium-browser", "google-chrome")
    return Piece("chromium", PieceKind.OPTIONAL, found is not None, found or "not on PATH",
                 "only the tests that render the replay and browser pages in a headless browser "
                 "(skipped with the reason without it); replay files are written without it",
                 "" if found else "apt-get install chromium (Debian; as root), or any Chromium on PATH")


def check_installation() -> InstallationReport:
    """Look at every piece without installing, building or compiling anything."""
    return InstallationReport((_core_piece(), _kernels_piece(), _compiler_piece(), _sitl_piece(),
                               *_extra_pieces(), _chromium_piece()))


class SetupStep(enum.Enum):
    """What :func:`set_up` did with one of its steps."""

    DONE = "done"
    SKIPPED = "skipped"
    FAILED = "failed"


@dataclass(frozen=True)
class SetupResult:
    """The steps :func:`set_up` took (name → outcome, message) and the installation afterwards."""

    steps: tuple[tuple[str, SetupStep, str], ...]
    report: InstallationReport

    @property
    def failed(self) -> bool:
        return any(outcome is SetupStep.FAILED for _, outcome, _ in self.steps)


def set_up(*, betaflight: bool = True, kernels: bool = True, progress: Progress | None = None,
           kernel_groups: tuple[str, ...] | None = None) -> SetupResult:
    """Build the Betaflight SITL (where a C compiler is there) and compile the kernels, then check.

    A missing compiler skips the SITL with the reason (every other plant still works); a build
    that was tried and failed is a failed step. Compiling the kernels takes one to two minutes of
    CPU the first time and seconds when they are cached; ``kernel_groups`` compiles only those
    (:data:`aerobat.experiments.warmup.PARTS`; default: all).
    """
    say = progress or (lambda line: None)
    steps: list[tuple[str, SetupStep, str]] = []
    if betaflight:
        steps.append(_build_sitl(say))
    if kernels:
        from aerobat.experiments.warmup import warm_up

        say("compiling the kernels (one to two minutes the first time, seconds when cached)")
        start = time.perf_counter()
        try:
            warm_up(progress=say, parts=kernel_groups)
        except Exception as exc:  # noqa: BLE001 - a failed compile is reported as the step's outcome
            steps.append(("kernels", SetupStep.FAILED, f"{type(exc).__name__}: {exc}"))
        else:
            steps.append(("kernels", SetupStep.DONE, f"compiled or loaded in {time.perf_counter() - start:.1f} s"))
    return SetupResult(tuple(steps), check_installation())


def _build_sitl(say: Progress) -> tuple[str, SetupStep, str]:
    from aerobat.firmware.betaflight.build import ensure_sitl
    from aerobat.firmware.betaflight.errors import FirmwareUnavailable

    if _sitl_piece().present:
        done = f"already built: {_sitl_path()}"
    else:
        compiler = _compiler_piece()
        if not compiler.present:
            return ("betaflight", SetupStep.SKIPPED, f"not built: {compiler.detail} ({compiler.how_to_get})")
        say("building the Betaflight 4.6 SITL (a few minutes, once)")
        try:
            done = f"built: {ensure_sitl(progress=say)}"
        except FirmwareUnavailable as exc:
            return ("betaflight", SetupStep.FAILED, " ".join(str(exc).splitlines()[:2]))
    failed = _build_shm_helper()
    return ("betaflight", SetupStep.FAILED, failed) if failed else ("betaflight", SetupStep.DONE, done)


def _build_shm_helper() -> str:
    """The shared-memory exchange's C helper (a second, cached): "" when built, else why not.

    The plant's default exchange needs it (``firmware.exchange = "shm"``); ``"udp"`` does not.
    """
    from aerobat.firmware.betaflight.errors import FirmwareUnavailable
    from aerobat.firmware.betaflight.shm import ensure_library

    try:
        ensure_library()
    except FirmwareUnavailable as exc:
        return ("the shared-memory helper (firmware.exchange = \"shm\", the default) did not build: "
                + " ".join(str(exc).splitlines()[:2]) + '; firmware.exchange = "udp" flies without it')
    return ""
