"""The experiment store: one SQLite file with every design, learning session and trial.

Layout and guarantees are described in ``docs/store.md``. In short:

* stdlib :mod:`sqlite3`, WAL journal, foreign keys on, ``busy_timeout`` and short
  ``BEGIN IMMEDIATE`` transactions (retried on ``SQLITE_BUSY``), so several
  ``aerobat learn`` processes can write one file at once;
* every iteration is one transaction (the iteration row and its session's summary
  row together), committed before the next trial starts: a killed process loses
  at most the trial in flight;
* the schema version is ``PRAGMA user_version``; older files are migrated in
  place (:mod:`aerobat.store_migrations`), newer, foreign or corrupted files are
  refused with a message and never modified.

The store knows nothing about quadrocopters: maneuvers and designs are taken
through the generic :class:`~aerobat.maneuvers.base.Maneuver` protocol and plain
JSON tables; arrays are stored as little-endian float64 bytes (exact), measured
trajectories as compressed float32.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import socket
import sqlite3
import time
import zlib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal
from urllib.parse import quote

import numpy as np

from .store_migrations import APPLICATION_ID, SCHEMA, SCHEMA_VERSION, TABLES, TABLES_SINCE, migrate

__all__ = [
    "DEFAULT_PATH",
    "SESSION_STATES",
    "DesignRecord",
    "IterationRecord",
    "ManeuverRecord",
    "PlantRecord",
    "SessionInUse",
    "SessionNotFound",
    "SessionRecord",
    "SessionSummary",
    "Store",
    "StoreAccessError",
    "StoreBusyError",
    "StoreError",
    "StoreFormatError",
    "StoreVersionError",
    "StoreWriteError",
    "VehicleRecord",
    "decode_trajectory",
    "default_path",
    "encode_trajectory",
]

DEFAULT_PATH = "aerobat.sqlite"
"""Default database file, relative to the working directory (``AEROBAT_DB`` overrides it)."""

SESSION_STATES = ("running", "completed", "interrupted", "crashed", "aborted", "failed")
"""States a session can be stored in. ``running`` sessions whose process is gone are shown as ``killed``."""

TRAJECTORY_CODEC = "f4-planes-zlib-hi2"
"""float32, column-major, split into byte planes; the two high planes zlib-compressed (level 1, RLE)."""

_SQLITE_MAGIC = b"SQLite format 3\x00"


def default_path() -> str:
    """The database used when ``--db`` is not given: ``$AEROBAT_DB`` or ``./aerobat.sqlite``."""
    return os.environ.get("AEROBAT_DB") or DEFAULT_PATH


# ------------------------------------------------------------------ errors


class StoreError(Exception):
    """A store problem; the message names the file and what is wrong.

    ``exit_code`` is what the command line exits with: 2 for a bad ``--db``
    argument or session reference, 1 for a failure while running.
    """

    exit_code = 1


class StoreAccessError(StoreError):
    """The file cannot be opened or created, or is read-only where writing is needed."""

    exit_code = 2


class StoreFormatError(StoreError):
    """Not an aerobat database: not SQLite at all, another application's SQLite file, or corrupted."""

    exit_code = 2


class StoreVersionError(StoreError):
    """Written by a newer aerobat (a schema version this one does not know)."""

    exit_code = 2


class SessionNotFound(StoreError):
    """No session with that id."""

    exit_code = 2


class SessionInUse(StoreError):
    """The session is being run by another live process."""

    exit_code = 2


class StoreWriteError(StoreError):
    """A write failed while running: disk full, file size limit, I/O error."""

    exit_code = 1


class StoreBusyError(StoreError):
    """Another process kept the database locked for longer than the busy timeout."""

    exit_code = 1


# ----------------------------------------------------------------- records


@dataclass(frozen=True)
class VehicleRecord:
    """A vehicle configuration (physical constants and onboard controller).

    Attributes
    ----------
    id : row id.
    name : the configuration's name.
    config : ``{"name", "vehicle": {...}, "controller": {...}}`` as written by the caller.
    """

    id: int
    name: str
    config: dict[str, Any]


@dataclass(frozen=True)
class PlantRecord:
    """A plant configuration: its kind, the vehicle it flies and its settings table."""

    id: int
    kind: str
    vehicle_id: int
    config: dict[str, Any]


@dataclass(frozen=True)
class ManeuverRecord:
    """A maneuver specification (``Maneuver.spec()``) with its parameter and error names.

    Attributes
    ----------
    spec : the specification table; :func:`aerobat.maneuvers.registry.from_spec` rebuilds the maneuver.
    parameter_names, parameter_units : per parameter.
    error_names, error_units, error_scales : per error component.
    """

    id: int
    kind: str
    name: str
    spec: dict[str, Any]
    parameter_names: tuple[str, ...]
    parameter_units: tuple[str, ...]
    error_names: tuple[str, ...]
    error_units: tuple[str, ...]
    error_scales: tuple[float, ...]


@dataclass(frozen=True)
class DesignRecord:
    """A nominal design, every array exactly as computed (float64).

    Attributes
    ----------
    p_guess, p_nominal : (n_par,) guess p^g and solution p⁰.
    residual : (n_err,) e(p⁰) on the model.
    jacobian : (n_err, n_par) J.
    correction : (n_par, n_err) C.
    singular_values : of J in scaled coordinates.
    """

    id: int
    maneuver_id: int
    vehicle_id: int
    p_guess: np.ndarray
    p_nominal: np.ndarray
    residual: np.ndarray
    residual_norm: float
    jacobian: np.ndarray
    correction: np.ndarray
    correction_kind: str
    singular_values: np.ndarray
    condition_number: float
    rank: int
    converged: bool
    status: str
    message: str
    duration_s: float
    compute_s: float
    evaluations: int
    created_at: str


@dataclass(frozen=True)
class SessionRecord:
    """A learning session and its running summary.

    Attributes
    ----------
    seed : the plant's seed (None if it has none).
    rule : the update rule and schedule, e.g. ``{"name": "paper", "schedule": {"kind": "paper", "minimum": 0.1}}``.
    target_iterations : measured iterations the session aims for.
    start_params : (n_par,) parameters of the first trial (p⁰, or a warm start).
    warm_start_from : the session whose learned parameters ``start_params`` are, if any.
    state : one of :data:`SESSION_STATES`.
    display_state : ``state``, except ``killed`` for a ``running`` session whose process is gone.
    owner : ``host:pid:start`` of the process that runs (or last ran) it.
    command : the command-line arguments that started it.
    n_records, n_measured : trials stored, and those that gave a measurement (``ok``).
    last_index, last_correction : counters to resume from.
    last_error : (n_err,) error of the last measured trial (None before the first).
    last_position_error_m : 2-norm of its position components [m].
    current_params : (n_par,) parameters the next trial flies.
    """

    id: int
    maneuver_id: int
    design_id: int
    plant_id: int
    seed: int | None
    rule: dict[str, Any]
    target_iterations: int
    start_params: np.ndarray
    warm_start_from: int | None
    state: str
    display_state: str
    message: str
    started_at: str
    updated_at: str
    ended_at: str | None
    host: str | None
    pid: int | None
    owner: str | None
    command: tuple[str, ...]
    aerobat_version: str | None
    n_records: int
    n_measured: int
    last_index: int
    last_correction: int
    last_error: np.ndarray | None
    last_position_error_m: float | None
    current_params: np.ndarray
    maneuver_name: str
    plant_kind: str


@dataclass(frozen=True)
class SessionSummary:
    """One row of ``aerobat sessions`` (read from the summary columns only)."""

    id: int
    maneuver_name: str
    plant_kind: str
    seed: int | None
    n_records: int
    n_measured: int
    target_iterations: int
    last_position_error_m: float | None
    state: str
    display_state: str
    started_at: str
    updated_at: str


@dataclass(frozen=True)
class IterationRecord:
    """One stored trial.

    Attributes
    ----------
    index : 1-based record number in its session (every trial, lost ones included).
    correction : number of the correction this trial drove (0 if none).
    status : ``ok``, ``rejected``, ``no_trigger``, ``crashed`` or ``aborted``.
    params : (n_par,) parameters flown.
    next_params : (n_par,) parameters after this record's correction (= ``params`` unless ``ok``).
    error : (n_err,) measured error (NaN if none).
    gamma, scale : step size and constraint scaling used.
    final_state, start_state : measured states (None if not stored).
    times_s, states : (M,), (M, n_state) measured trajectory, float32 precision; None unless
        loaded with ``trajectories=True`` (``trajectory_rows`` says how long it is).
    plant_state : the plant's state after this trial (JSON table), if loaded and stored.
    info : the plant's extras.
    """

    session_id: int
    index: int
    correction: int
    status: str
    params: np.ndarray
    next_params: np.ndarray
    error: np.ndarray
    gamma: float
    scale: float
    message: str
    final_state: np.ndarray | None
    start_state: np.ndarray | None
    trajectory_rows: int
    recorded_at: str
    times_s: np.ndarray | None = None
    states: np.ndarray | None = None
    plant_state: dict[str, Any] | None = None
    info: dict[str, Any] = field(default_factory=dict)


# ---------------------------------------------------------------- encoding


def _f8(values: Any) -> bytes:
    return np.ascontiguousarray(np.asarray(values, dtype=np.float64), dtype="<f8").tobytes()


def _from_f8(blob: bytes | None, shape: tuple[int, ...] | None = None) -> np.ndarray:
    array = np.frombuffer(blob or b"", dtype="<f8").astype(np.float64)
    return array.reshape(shape) if shape is not None else array


def encode_trajectory(times_s: np.ndarray, states: np.ndarray) -> tuple[int, int, bytes]:
    """Compress a trajectory: ``(rows, cols, blob)`` of the matrix ``[times_s | states]``.

    The matrix is rounded to float32 (~7 significant digits: µs on times of seconds, µm on
    metres, finer than any measurement), laid out column by column and split into its four
    byte planes. The two low-order planes are mantissa noise that no compressor shrinks, so
    they are stored as they are; the two high-order planes (sign, exponent, leading mantissa)
    change slowly along each column and go through zlib (level 1, run-length strategy). That
    compresses as well as deflating everything and costs a third of the time.
    """
    times = np.asarray(times_s, dtype=np.float64).reshape(-1)
    states2 = np.asarray(states, dtype=np.float64).reshape(times.size, -1)
    with np.errstate(over="ignore"):  # beyond float32's range is stored as ±inf
        matrix = np.column_stack([times, states2]).astype("<f4")
    rows, cols = matrix.shape
    flat = np.ascontiguousarray(matrix.T).reshape(-1)  # column-major
    planes = np.ascontiguousarray(flat.view(np.uint8).reshape(flat.size, 4).T)  # (4, n): byte k of every value
    packer = zlib.compressobj(1, zlib.DEFLATED, 15, 9, zlib.Z_RLE)
    return rows, cols, planes[:2].tobytes() + packer.compress(planes[2:].tobytes()) + packer.flush()


def decode_trajectory(blob: bytes, rows: int, cols: int) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`encode_trajectory`: ``(times_s (rows,), states (rows, cols - 1))`` as float64."""
    n = rows * cols
    low = np.frombuffer(blob, dtype=np.uint8, count=2 * n) if len(blob) >= 2 * n else None
    high = np.frombuffer(zlib.decompress(blob[2 * n:]), dtype=np.uint8)
    if low is None or high.size != 2 * n:
        raise ValueError(f"trajectory blob does not hold {rows} × {cols} float32 values")
    planes = np.concatenate([low, high]).reshape(4, n)
    flat = np.ascontiguousarray(planes.T).view("<f4").reshape(-1)
    matrix = flat.reshape(cols, rows).T.astype(np.float64)
    return matrix[:, 0].copy(), matrix[:, 1:].copy()


def _canonical(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"))


def _digest(*parts: Any) -> str:
    h = hashlib.sha256()
    for part in parts:
        h.update(part if isinstance(part, bytes) else str(part).encode())
        h.update(b"\x00")
    return h.hexdigest()


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def _json_ready(obj: Any) -> Any:
    """Plain JSON values (numpy scalars and arrays become floats and lists)."""
    return json.loads(json.dumps(obj, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))


# ---------------------------------------------------------- process owners


def _process_start(pid: int) -> str:
    """The process's start time in clock ticks since boot (Linux), "" where unknown."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as handle:
            stat = handle.read().decode(errors="replace")
    except OSError:
        return ""
    fields = stat[stat.rfind(")") + 2 :].split()
    if fields and fields[0] in ("Z", "X"):  # a zombie is dead, whatever kill(pid, 0) says
        return "zombie"
    return fields[19] if len(fields) > 19 else ""


def _owner_token() -> str:
    return f"{socket.gethostname()}:{os.getpid()}:{_process_start(os.getpid())}"


def owner_alive(owner: str | None) -> bool | None:
    """Is the process named by ``owner`` (``host:pid:start``) still running?

    None when it ran on another host (cannot tell).
    """
    if not owner:
        return False
    host, _, rest = owner.partition(":")
    pid_text, _, start = rest.partition(":")
    if host != socket.gethostname():
        return None
    try:
        pid = int(pid_text)
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except (ValueError, OSError):
        return False
    now = _process_start(pid)
    if now == "zombie":
        return False
    return not (start and now and now != start)  # a recycled pid is another process


# ------------------------------------------------------------------- store


class Store:
    """An aerobat experiment database.

    Parameters
    ----------
    path : the SQLite file; created (with its schema) if missing and ``create``.
    create : create the file if it does not exist; otherwise a missing file is an error.
    synchronous : ``"normal"`` (default): a committed iteration survives the process being
        killed at any instant; an operating-system crash or power loss may lose the last
        commits but never corrupts the file. ``"full"``: commits also survive power loss
        (an fsync per commit, a few milliseconds on ordinary disks).
    busy_timeout_s : how long a write waits for another process's transaction.

    Raises
    ------
    StoreFormatError
        The file is not SQLite, belongs to another application, or is corrupted.
    StoreVersionError
        The file was written by a newer aerobat.
    StoreAccessError
        The file or its directory cannot be opened, created or written.
    """

    def __init__(self, path: str | os.PathLike[str], *, create: bool = True,
                 synchronous: Literal["normal", "full"] = "normal", busy_timeout_s: float = 60.0) -> None:
        if synchronous not in ("normal", "full"):
            raise ValueError(f"synchronous = {synchronous!r}: allowed 'normal' or 'full'")
        if not str(path).strip():
            raise StoreAccessError("--db: empty database path")
        self.path = Path(path)
        self.busy_timeout_s = float(busy_timeout_s)
        self.owner = _owner_token()
        self.migrated_from: list[int] = []
        self._position_masks: dict[int, np.ndarray] = {}
        self._conn: sqlite3.Connection | None = None
        fresh = self._check_file(create)
        try:
            self._conn = sqlite3.connect(str(self.path), timeout=self.busy_timeout_s, isolation_level=None,
                                         check_same_thread=False)
        except sqlite3.Error as exc:
            raise self._translate(exc, "opening the database") from None
        try:
            with self._guard("opening the database"):
                self._conn.execute("PRAGMA foreign_keys = ON")
                self._conn.execute(f"PRAGMA synchronous = {synchronous.upper()}")
                if fresh:
                    self._initialize()
                else:
                    self._upgrade_if_needed()
        except BaseException:
            self.close()
            raise

    # ---------------------------------------------------------- opening
    def _check_file(self, create: bool) -> bool:
        """Validate an existing file without writing to it; True if a schema must be created."""
        path = self.path
        if path.is_dir():
            raise StoreAccessError(f"{path}: is a directory, expected a database file (--db PATH)")
        if not path.exists():
            if not create:
                raise StoreAccessError(f"{path}: no such database (--db); `aerobat learn` creates one")
            parent = path.parent if str(path.parent) else Path(".")
            if not parent.is_dir():
                raise StoreAccessError(f"{path}: cannot create the database: directory {parent} does not exist")
            return True
        if not path.is_file():
            raise StoreAccessError(f"{path}: not a regular file, expected a database file (--db PATH)")
        try:
            with path.open("rb") as handle:
                header = handle.read(100)
        except OSError as exc:
            raise StoreAccessError(f"{path}: cannot read the database: {exc.strerror or exc}") from None
        if not header:
            if not create:
                raise StoreAccessError(f"{path}: empty file, no aerobat database yet; `aerobat learn` creates one")
            return True  # an empty file is an empty database
        if not header.startswith(_SQLITE_MAGIC) or len(header) < 100:
            raise StoreFormatError(f"{path}: not an aerobat database (not an SQLite file); the file was not "
                                   f"modified — choose another --db path")
        return self._probe()

    def _probe(self) -> bool:
        """Read-only look inside an SQLite file: is it ours, and which version?"""
        path = self.path
        uri = f"file:{quote(str(path.resolve()))}?mode=ro"
        with path.open("rb") as handle:
            wal_format = handle.read(20)[18:20] == b"\x02\x02"
        side_files = any(Path(f"{path}{suffix}").exists() for suffix in ("-wal", "-shm"))
        if wal_format and not side_files:
            # nobody has it open and its WAL is empty: read the file alone, so that refusing
            # it leaves no -wal/-shm files behind
            uri += "&immutable=1"
        try:
            probe = sqlite3.connect(uri, uri=True, timeout=self.busy_timeout_s, isolation_level=None)
        except sqlite3.Error as exc:
            raise StoreAccessError(f"{path}: cannot open the database for reading: {exc}") from None
        try:
            app_id = probe.execute("PRAGMA application_id").fetchone()[0]
            version = probe.execute("PRAGMA user_version").fetchone()[0]
            tables = [r[0] for r in probe.execute(
                "SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE 'sqlite_%' ORDER BY name")]
            tagged = False
            if "meta" in tables:
                with contextlib.suppress(sqlite3.Error):
                    row = probe.execute("SELECT value FROM meta WHERE key = 'application'").fetchone()
                    tagged = bool(row and row[0] == "aerobat")
        except sqlite3.DatabaseError as exc:
            kind = getattr(exc, "sqlite_errorname", "")
            if kind.startswith(("SQLITE_BUSY", "SQLITE_LOCKED")):
                raise StoreBusyError(f"{path}: the database stayed locked by another process") from None
            raise StoreFormatError(f"{path}: not a usable aerobat database ({exc}); the file was not modified — "
                                   f"restore it from a backup or choose another --db path") from None
        finally:
            probe.close()
        ours = app_id == APPLICATION_ID or tagged
        if not ours:
            if not tables and app_id == 0:
                return True  # an empty SQLite database
            listed = ", ".join(tables[:6]) + (", …" if len(tables) > 6 else "")
            what = f"application_id {app_id:#x}" if app_id else f"tables {listed}"
            raise StoreFormatError(f"{path}: not an aerobat database (an SQLite file of another application: "
                                   f"{what}); the file was not modified — choose another --db path")
        if version > SCHEMA_VERSION:
            raise StoreVersionError(
                f"{path}: written by a newer aerobat (schema version {version}; this aerobat reads versions "
                f"1 to {SCHEMA_VERSION}); upgrade aerobat to use it — the file was not modified")
        if version < 1:
            raise StoreFormatError(f"{path}: aerobat database without a schema version (damaged); "
                                   f"the file was not modified")
        missing = [t for t in TABLES if t not in tables and TABLES_SINCE.get(t, 1) <= version]
        if missing:
            raise StoreFormatError(f"{path}: damaged aerobat database: missing table(s) {', '.join(missing)}; "
                                   f"the file was not modified")
        return False

    def _initialize(self) -> None:
        conn = self._db
        conn.execute("PRAGMA journal_mode = WAL")
        conn.execute("BEGIN IMMEDIATE")
        try:
            existing = conn.execute("SELECT count(*) FROM sqlite_master WHERE name NOT LIKE 'sqlite_%'").fetchone()[0]
            if existing == 0:  # another process may have created it meanwhile
                for statement in _statements(SCHEMA):
                    conn.execute(statement)
                conn.execute(f"PRAGMA application_id = {APPLICATION_ID}")
                conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
                from . import __version__

                conn.executemany("INSERT INTO meta (key, value) VALUES (?, ?)", [
                    ("application", "aerobat"), ("created_by", __version__), ("created_at", _now()),
                ])
            conn.execute("COMMIT")
        except BaseException:
            _rollback(conn)
            raise
        if existing:
            self._upgrade_if_needed()

    def _upgrade_if_needed(self) -> None:
        conn = self._db
        version = conn.execute("PRAGMA user_version").fetchone()[0]
        if version > SCHEMA_VERSION:  # changed since the probe
            raise StoreVersionError(f"{self.path}: written by a newer aerobat (schema version {version}); "
                                    f"upgrade aerobat to use it — the file was not modified")
        if version < SCHEMA_VERSION:
            conn.execute("BEGIN IMMEDIATE")
            try:
                version = conn.execute("PRAGMA user_version").fetchone()[0]  # another process may have migrated
                self.migrated_from = migrate(conn, version)
                if self.migrated_from:
                    conn.execute("INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)",
                                 (f"migrated_from_{version}", _now()))
                conn.execute("COMMIT")
            except BaseException:
                _rollback(conn)
                raise
        mode = conn.execute("PRAGMA journal_mode").fetchone()[0]
        if mode != "wal":
            with contextlib.suppress(sqlite3.OperationalError):  # read-only files stay as they are
                conn.execute("PRAGMA journal_mode = WAL")

    # ---------------------------------------------------------- plumbing
    @property
    def _db(self) -> sqlite3.Connection:
        if self._conn is None:
            raise StoreError(f"{self.path}: the store is closed")
        return self._conn

    def close(self) -> None:
        """Close the connection (idempotent)."""
        if self._conn is not None:
            with contextlib.suppress(sqlite3.Error):
                self._conn.close()
            self._conn = None

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def schema_version(self) -> int:
        """``PRAGMA user_version`` of the open database."""
        with self._guard("reading the schema version"):
            return int(self._db.execute("PRAGMA user_version").fetchone()[0])

    def _translate(self, exc: sqlite3.Error, action: str) -> StoreError:
        name = getattr(exc, "sqlite_errorname", "") or ""
        text = str(exc)
        where = f"{self.path}: {action} failed"
        if name.startswith("SQLITE_FULL") or "disk is full" in text:
            return StoreWriteError(f"{where}: the disk is full (or the file size limit was reached)")
        if name.startswith("SQLITE_READONLY") or "readonly" in text:
            return StoreAccessError(f"{where}: the database or its directory is read-only ({text})")
        if name.startswith("SQLITE_CANTOPEN") or "unable to open" in text:
            return StoreAccessError(f"{where}: cannot open or create the file; check that the directory "
                                    f"exists and is writable ({text})")
        if name.startswith(("SQLITE_BUSY", "SQLITE_LOCKED")) or "locked" in text:
            return StoreBusyError(f"{where}: another process kept the database locked for more than "
                                  f"{self.busy_timeout_s:g} s")
        if name.startswith(("SQLITE_CORRUPT", "SQLITE_NOTADB")) or "malformed" in text or "not a database" in text:
            return StoreFormatError(f"{where}: the database is corrupted ({text})")
        if name.startswith("SQLITE_IOERR") or "I/O error" in text:
            return StoreWriteError(f"{where}: disk I/O error ({name or text}): is the disk full or the file "
                                   f"size limit reached?")
        if name.startswith("SQLITE_PERM") or "permission" in text.lower():
            return StoreAccessError(f"{where}: permission denied ({text})")
        return StoreError(f"{where}: {text}")

    @contextlib.contextmanager
    def _guard(self, action: str) -> Iterator[None]:
        try:
            yield
        except sqlite3.Error as exc:
            raise self._translate(exc, action) from None

    def _write(self, action: str, fn: Any, *, attempts: int = 5) -> Any:
        """Run ``fn(conn)`` in one ``BEGIN IMMEDIATE`` transaction, retrying if the file stays busy."""
        conn = self._db
        for attempt in range(attempts):
            try:
                with self._guard(action):
                    conn.execute("BEGIN IMMEDIATE")
                    try:
                        result = fn(conn)
                        conn.execute("COMMIT")
                    except BaseException:
                        _rollback(conn)
                        raise
                return result
            except StoreBusyError:
                if attempt == attempts - 1:
                    raise
                time.sleep(0.05 * 2**attempt)
        raise AssertionError("unreachable")

    def integrity_check(self) -> list[str]:
        """``PRAGMA integrity_check`` and ``foreign_key_check``: an empty list if the file is sound."""
        with self._guard("checking integrity"):
            rows = [r[0] for r in self._db.execute("PRAGMA integrity_check")]
            problems = [] if rows == ["ok"] else rows
            problems += [f"foreign key: {r}" for r in self._db.execute("PRAGMA foreign_key_check")]
        return problems

    # ---------------------------------------------------------- writing
    @staticmethod
    def _upsert(conn: sqlite3.Connection, table: str, columns: dict[str, Any]) -> int:
        names = ", ".join(columns)
        marks = ", ".join("?" * len(columns))
        conn.execute(f"INSERT OR IGNORE INTO {table} ({names}) VALUES ({marks})", tuple(columns.values()))
        return int(conn.execute(f"SELECT id FROM {table} WHERE digest = ?", (columns["digest"],)).fetchone()[0])

    def create_session(
        self,
        *,
        vehicle: Mapping[str, Any],
        plant_kind: str,
        plant_config: Mapping[str, Any],
        maneuver: Any,
        design: Any,
        design_vehicle: Mapping[str, Any] | None = None,
        seed: int | None,
        rule: Mapping[str, Any],
        target_iterations: int,
        start_params: np.ndarray,
        warm_start_from: int | None = None,
        command: Sequence[str] = (),
    ) -> int:
        """Store a new session (with its vehicle, plant, maneuver and design, deduplicated); its id.

        Parameters
        ----------
        vehicle : the plant's vehicle configuration table (``{"name", "vehicle", "controller"}``).
        plant_kind, plant_config : the plant (e.g. ``"arena"``, ``{"arena": {...}}``).
        maneuver : a :class:`~aerobat.maneuvers.base.Maneuver` with ``spec()``.
        design : a :class:`~aerobat.design.Design` (any object with its attributes).
        design_vehicle : the design model's vehicle table (default: ``vehicle``).
        seed : the plant's seed.
        rule : the update rule and schedule as a JSON table.
        target_iterations : measured iterations to learn.
        start_params : (n_par,) parameters of the first trial.
        warm_start_from : session whose learned parameters ``start_params`` are.
        command : command-line arguments, kept for reference.
        """
        from . import __version__

        vehicle_json = _canonical(_json_ready(dict(vehicle)))
        model_json = _canonical(_json_ready(dict(design_vehicle if design_vehicle is not None else vehicle)))
        plant_json = _canonical(_json_ready(dict(plant_config)))
        spec_json = _canonical(_json_ready(maneuver.spec()))
        pnames = json.dumps([p.name for p in maneuver.parameters])
        punits = json.dumps([p.unit for p in maneuver.parameters])
        enames = json.dumps([e.name for e in maneuver.errors])
        eunits = json.dumps([e.unit for e in maneuver.errors])
        escales = json.dumps([float(e.scale) for e in maneuver.errors])
        n_par, n_err = len(maneuver.parameters), len(maneuver.errors)
        start = np.asarray(start_params, dtype=np.float64)
        if start.shape != (n_par,):
            raise ValueError(f"start_params: expected {n_par} values, got shape {start.shape}")
        if isinstance(target_iterations, bool) or not isinstance(target_iterations, int) or target_iterations < 1:
            raise ValueError(f"target_iterations = {target_iterations!r}: expected an integer >= 1")
        design_arrays = {
            "p_guess": _f8(design.p_guess), "p_nominal": _f8(design.p_nominal), "residual": _f8(design.residual),
            "jacobian": _f8(design.jacobian), "correction": _f8(design.correction),
            "singular_values": _f8(design.singular_values),
        }
        now = _now()

        def write(conn: sqlite3.Connection) -> int:
            vehicle_id = self._upsert(conn, "vehicles", {
                "name": str(vehicle.get("name", "")), "config": vehicle_json, "digest": _digest(vehicle_json)})
            model_id = vehicle_id if model_json == vehicle_json else self._upsert(conn, "vehicles", {
                "name": str((design_vehicle or {}).get("name", "")), "config": model_json,
                "digest": _digest(model_json)})
            plant_id = self._upsert(conn, "plants", {
                "kind": plant_kind, "vehicle_id": vehicle_id, "config": plant_json,
                "digest": _digest(plant_kind, vehicle_id, plant_json)})
            maneuver_id = self._upsert(conn, "maneuvers", {
                "kind": str(maneuver.spec().get("kind", "")), "name": maneuver.name, "spec": spec_json,
                "parameter_names": pnames, "parameter_units": punits, "error_names": enames,
                "error_units": eunits, "error_scales": escales, "digest": _digest(spec_json)})
            design_id = self._upsert(conn, "designs", {
                "maneuver_id": maneuver_id, "vehicle_id": model_id, "n_par": n_par, "n_err": n_err,
                **design_arrays,
                "residual_norm": float(design.residual_norm), "correction_kind": str(design.correction_kind),
                "condition_number": float(design.condition_number), "rank": int(design.rank),
                "converged": int(bool(design.converged)), "status": str(design.status),
                "message": str(design.message), "duration_s": float(design.duration_s),
                "compute_s": float(design.compute_s), "evaluations": int(getattr(design, "evaluations", 0)),
                "created_at": now,
                "digest": _digest(maneuver_id, model_id, design.correction_kind, *design_arrays.values()),
            })
            cursor = conn.execute(
                """INSERT INTO sessions (maneuver_id, design_id, plant_id, seed, rule, target_iterations,
                       start_params, warm_start_from, state, message, started_at, updated_at, host, pid, owner,
                       command, aerobat_version, current_params)
                   VALUES (?, ?, ?, ?, ?, ?, ?, ?, 'running', 'started', ?, ?, ?, ?, ?, ?, ?, ?)""",
                (maneuver_id, design_id, plant_id, seed, _canonical(_json_ready(dict(rule))), target_iterations,
                 _f8(start), warm_start_from, now, now, socket.gethostname(), os.getpid(), self.owner,
                 json.dumps(list(command)), __version__, _f8(start)))
            return int(cursor.lastrowid or 0)

        return int(self._write("creating a session", write))

    def append_iteration(
        self,
        session_id: int,
        *,
        index: int,
        correction: int,
        status: str,
        params: np.ndarray,
        next_params: np.ndarray,
        error: np.ndarray,
        gamma: float,
        scale: float,
        message: str,
        final_state: np.ndarray | None = None,
        start_state: np.ndarray | None = None,
        times_s: np.ndarray | None = None,
        states: np.ndarray | None = None,
        plant_state: Mapping[str, Any] | None = None,
        info: Mapping[str, Any] | None = None,
    ) -> None:
        """Store one trial and update its session's summary, in one committed transaction.

        Only the process that owns the session (created or resumed it) may append, and
        ``index`` must be the session's last index + 1: a gap or a duplicate is refused.

        Raises
        ------
        StoreWriteError
            The disk is full or the write failed; nothing of this iteration is stored.
        StoreError
            Wrong index, or the session belongs to another process.
        """
        traj: tuple[int, int, bytes | None] = (0, 0, None)
        if times_s is not None and states is not None and np.asarray(times_s).size:
            traj = encode_trajectory(times_s, states)
        err = np.asarray(error, dtype=np.float64)
        ok = status == "ok"
        mask = self._position_mask(session_id)
        position = float(np.linalg.norm(err[mask])) if ok and mask.shape == err.shape and mask.any() else None
        row = (
            session_id, index, correction, status, _f8(params), _f8(next_params), _f8(err), float(gamma),
            float(scale), message, None if final_state is None else _f8(final_state),
            None if start_state is None else _f8(start_state), traj[0], traj[1],
            TRAJECTORY_CODEC if traj[2] is not None else None, traj[2],
            json.dumps(_json_ready(dict(info or {}))), _now(),
            None if plant_state is None else json.dumps(plant_state, separators=(",", ":")),
        )

        def write(conn: sqlite3.Connection) -> None:
            cursor = conn.execute(
                """UPDATE sessions SET n_records = n_records + 1, n_measured = n_measured + ?,
                       last_index = ?, last_correction = CASE WHEN ? THEN ? ELSE last_correction END,
                       last_error = CASE WHEN ? THEN ? ELSE last_error END,
                       last_position_error_m = CASE WHEN ? THEN ? ELSE last_position_error_m END,
                       current_params = ?, updated_at = ?
                   WHERE id = ? AND owner = ? AND last_index = ?""",
                (int(ok), index, ok, correction, ok, row[6], ok, position, row[5], row[17], session_id,
                 self.owner, index - 1))
            if cursor.rowcount != 1:
                found = conn.execute("SELECT last_index, owner FROM sessions WHERE id = ?", (session_id,)).fetchone()
                if found is None:
                    raise SessionNotFound(f"{self.path}: no session {session_id}")
                if found[1] != self.owner:
                    raise StoreError(f"{self.path}: session {session_id} is now run by another process "
                                     f"({found[1]}); this process stops writing to it")
                raise StoreError(f"{self.path}: session {session_id}: iteration {index} does not follow the "
                                 f"stored iteration {found[0]} (no gaps, no duplicates)")
            conn.execute(
                """INSERT INTO iterations (session_id, idx, correction, status, params, next_params, error, gamma,
                       scale, message, final_state, start_state, traj_rows, traj_cols, traj_codec, trajectory,
                       info, recorded_at, plant_state)
                   VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)""", row)

        self._write(f"storing iteration {index} of session {session_id}", write)

    def replace_next_params(self, session_id: int, index: int, next_params: np.ndarray) -> None:
        """Correct the stored post-correction parameters of the session's last iteration."""
        blob = _f8(next_params)

        def write(conn: sqlite3.Connection) -> None:
            conn.execute("UPDATE iterations SET next_params = ? WHERE session_id = ? AND idx = ?",
                         (blob, session_id, index))
            conn.execute("UPDATE sessions SET current_params = ? WHERE id = ? AND last_index = ?",
                         (blob, session_id, index))

        self._write(f"updating iteration {index} of session {session_id}", write)

    def claim_session(self, session_id: int) -> SessionRecord:
        """Take over a session to resume it: it becomes ``running`` under this process.

        Raises
        ------
        SessionNotFound
            No such session.
        StoreError
            Its process is still running (exit code 2).
        """

        def write(conn: sqlite3.Connection) -> None:
            row = conn.execute("SELECT state, owner, pid, host FROM sessions WHERE id = ?", (session_id,)).fetchone()
            if row is None:
                raise SessionNotFound(f"{self.path}: no session {session_id} (see `aerobat sessions --db {self.path}`)")
            state, owner, pid, host = row
            if state == "running" and owner != self.owner and owner_alive(owner) is not False:
                raise SessionInUse(f"{self.path}: session {session_id} is still being run by process {pid} on "
                                   f"{host}; stop that process before resuming")
            now = _now()
            conn.execute("UPDATE sessions SET state = 'running', owner = ?, pid = ?, host = ?, ended_at = NULL, "
                         "updated_at = ?, message = ? WHERE id = ?",
                         (self.owner, os.getpid(), socket.gethostname(), now, f"resumed (was {state})", session_id))

        self._write(f"claiming session {session_id}", write)
        return self.session(session_id)

    def set_target(self, session_id: int, target_iterations: int) -> None:
        """Change how many measured iterations the session aims for."""
        self._write(f"updating session {session_id}", lambda conn: conn.execute(
            "UPDATE sessions SET target_iterations = ?, updated_at = ? WHERE id = ?",
            (int(target_iterations), _now(), session_id)))

    def finish_session(self, session_id: int, state: str, message: str) -> None:
        """Record how the session ended (``state`` one of :data:`SESSION_STATES`)."""
        if state not in SESSION_STATES:
            raise ValueError(f"session state {state!r}: allowed {', '.join(SESSION_STATES)}")
        now = _now()
        self._write(f"closing session {session_id}", lambda conn: conn.execute(
            "UPDATE sessions SET state = ?, message = ?, ended_at = ?, updated_at = ? WHERE id = ? AND owner = ?",
            (state, message, None if state == "running" else now, now, session_id, self.owner)))

    # ---------------------------------------------------------- reading
    def _position_mask(self, session_id: int) -> np.ndarray:
        if session_id not in self._position_masks:
            with self._guard(f"reading session {session_id}"):
                row = self._db.execute("SELECT m.error_units FROM sessions s JOIN maneuvers m ON m.id = "
                                       "s.maneuver_id WHERE s.id = ?", (session_id,)).fetchone()
            units = json.loads(row[0]) if row else []
            self._position_masks[session_id] = np.array([u == "m" for u in units], dtype=bool)
        return self._position_masks[session_id]

    def resolve_session(self, ref: int | str) -> int:
        """A session id from ``ref``: a positive id or ``"last"`` (the newest session)."""
        if isinstance(ref, str) and ref.strip().lower() == "last":
            with self._guard("listing sessions"):
                row = self._db.execute("SELECT max(id) FROM sessions").fetchone()
            if row is None or row[0] is None:
                raise SessionNotFound(f"{self.path}: holds no sessions yet")
            return int(row[0])
        try:
            session_id = int(ref)
        except (TypeError, ValueError):
            raise SessionNotFound(f"{self.path}: session {ref!r}: expected a session id or 'last'") from None
        if not 1 <= session_id < 2**63:
            raise SessionNotFound(f"{self.path}: no session {session_id} (see `aerobat sessions --db {self.path}`)")
        with self._guard("reading sessions"):
            found = self._db.execute("SELECT 1 FROM sessions WHERE id = ?", (session_id,)).fetchone()
        if not found:
            raise SessionNotFound(f"{self.path}: no session {session_id} (see `aerobat sessions --db {self.path}`)")
        return session_id

    _SUMMARY_COLUMNS = ("s.id, m.name, p.kind, s.seed, s.n_records, s.n_measured, s.target_iterations, "
                        "s.last_position_error_m, s.state, s.owner, s.started_at, s.updated_at")

    def list_sessions(self, *, limit: int | None = None, newest_first: bool = False) -> list[SessionSummary]:
        """Every session's summary row (no iteration is read)."""
        order = "DESC" if newest_first else "ASC"
        sql = (f"SELECT {self._SUMMARY_COLUMNS} FROM sessions s JOIN maneuvers m ON m.id = s.maneuver_id "
               f"JOIN plants p ON p.id = s.plant_id ORDER BY s.id {order}")
        args: tuple[Any, ...] = ()
        if limit is not None:
            sql += " LIMIT ?"
            args = (int(limit),)
        with self._guard("listing sessions"):
            rows = self._db.execute(sql, args).fetchall()
        alive: dict[str | None, bool | None] = {}
        out = []
        for r in rows:
            state, owner = r[8], r[9]
            display = state
            if state == "running":
                if owner not in alive:
                    alive[owner] = owner_alive(owner)
                if alive[owner] is False:
                    display = "killed"
            out.append(SessionSummary(id=r[0], maneuver_name=r[1], plant_kind=r[2], seed=r[3], n_records=r[4],
                                      n_measured=r[5], target_iterations=r[6], last_position_error_m=r[7],
                                      state=state, display_state=display, started_at=r[10], updated_at=r[11]))
        return out

    def session(self, session_id: int) -> SessionRecord:
        """The session and its summary."""
        with self._guard(f"reading session {session_id}"):
            r = self._db.execute(
                """SELECT s.id, s.maneuver_id, s.design_id, s.plant_id, s.seed, s.rule, s.target_iterations,
                          s.start_params, s.warm_start_from, s.state, s.message, s.started_at, s.updated_at,
                          s.ended_at, s.host, s.pid, s.owner, s.command, s.aerobat_version, s.n_records,
                          s.n_measured, s.last_index, s.last_correction, s.last_error, s.last_position_error_m,
                          s.current_params, m.name, p.kind
                   FROM sessions s JOIN maneuvers m ON m.id = s.maneuver_id JOIN plants p ON p.id = s.plant_id
                   WHERE s.id = ?""", (session_id,)).fetchone()
        if r is None:
            raise SessionNotFound(f"{self.path}: no session {session_id} (see `aerobat sessions --db {self.path}`)")
        state, owner = r[9], r[16]
        display = "killed" if state == "running" and owner_alive(owner) is False else state
        return SessionRecord(
            id=r[0], maneuver_id=r[1], design_id=r[2], plant_id=r[3], seed=r[4], rule=json.loads(r[5]),
            target_iterations=r[6], start_params=_from_f8(r[7]), warm_start_from=r[8], state=state,
            display_state=display, message=r[10], started_at=r[11], updated_at=r[12], ended_at=r[13], host=r[14],
            pid=r[15], owner=owner, command=tuple(json.loads(r[17] or "[]")), aerobat_version=r[18],
            n_records=r[19], n_measured=r[20], last_index=r[21], last_correction=r[22],
            last_error=None if r[23] is None else _from_f8(r[23]), last_position_error_m=r[24],
            current_params=_from_f8(r[25] if r[25] is not None else r[7]), maneuver_name=r[26], plant_kind=r[27])

    def maneuver(self, maneuver_id: int) -> ManeuverRecord:
        """A stored maneuver specification."""
        with self._guard("reading a maneuver"):
            r = self._db.execute("SELECT id, kind, name, spec, parameter_names, parameter_units, error_names, "
                                 "error_units, error_scales FROM maneuvers WHERE id = ?", (maneuver_id,)).fetchone()
        if r is None:
            raise StoreFormatError(f"{self.path}: damaged: maneuver {maneuver_id} is missing")
        return ManeuverRecord(id=r[0], kind=r[1], name=r[2], spec=json.loads(r[3]),
                              parameter_names=tuple(json.loads(r[4])), parameter_units=tuple(json.loads(r[5])),
                              error_names=tuple(json.loads(r[6])), error_units=tuple(json.loads(r[7])),
                              error_scales=tuple(float(v) for v in json.loads(r[8])))

    def design(self, design_id: int) -> DesignRecord:
        """A stored design, arrays bit for bit as computed."""
        with self._guard("reading a design"):
            r = self._db.execute(
                """SELECT id, maneuver_id, vehicle_id, n_par, n_err, p_guess, p_nominal, residual, residual_norm,
                          jacobian, correction, correction_kind, singular_values, condition_number, rank,
                          converged, status, message, duration_s, compute_s, evaluations, created_at
                   FROM designs WHERE id = ?""", (design_id,)).fetchone()
        if r is None:
            raise StoreFormatError(f"{self.path}: damaged: design {design_id} is missing")
        n_par, n_err = r[3], r[4]
        return DesignRecord(
            id=r[0], maneuver_id=r[1], vehicle_id=r[2], p_guess=_from_f8(r[5]), p_nominal=_from_f8(r[6]),
            residual=_from_f8(r[7]), residual_norm=_nan_if_none(r[8]), jacobian=_from_f8(r[9], (n_err, n_par)),
            correction=_from_f8(r[10], (n_par, n_err)), correction_kind=r[11], singular_values=_from_f8(r[12]),
            condition_number=_nan_if_none(r[13]), rank=r[14], converged=bool(r[15]), status=r[16], message=r[17],
            duration_s=_nan_if_none(r[18]), compute_s=_nan_if_none(r[19]), evaluations=r[20], created_at=r[21])

    def vehicle(self, vehicle_id: int) -> VehicleRecord:
        """A stored vehicle configuration."""
        with self._guard("reading a vehicle"):
            r = self._db.execute("SELECT id, name, config FROM vehicles WHERE id = ?", (vehicle_id,)).fetchone()
        if r is None:
            raise StoreFormatError(f"{self.path}: damaged: vehicle {vehicle_id} is missing")
        return VehicleRecord(id=r[0], name=r[1], config=json.loads(r[2]))

    def plant(self, plant_id: int) -> PlantRecord:
        """A stored plant configuration."""
        with self._guard("reading a plant"):
            r = self._db.execute("SELECT id, kind, vehicle_id, config FROM plants WHERE id = ?",
                                 (plant_id,)).fetchone()
        if r is None:
            raise StoreFormatError(f"{self.path}: damaged: plant {plant_id} is missing")
        return PlantRecord(id=r[0], kind=r[1], vehicle_id=r[2], config=json.loads(r[3]))

    _ITERATION_COLUMNS = ("session_id, idx, correction, status, params, next_params, error, gamma, scale, message, "
                          "final_state, start_state, traj_rows, recorded_at, info")

    def _iteration(self, r: Sequence[Any], extra: Sequence[Any], trajectories: bool,
                   plant_state: bool) -> IterationRecord:
        times = states = None
        k = 0
        if trajectories:
            blob, rows, cols, codec = extra[0], extra[1], extra[2], extra[3]
            k = 4
            if blob is not None and rows:
                if codec != TRAJECTORY_CODEC:
                    raise ValueError(f"iteration {r[1]}: unknown trajectory encoding {codec!r}")
                times, states = decode_trajectory(blob, rows, cols)
        pstate = json.loads(extra[k]) if plant_state and extra[k] else None
        return IterationRecord(
            session_id=r[0], index=r[1], correction=r[2], status=r[3], params=_from_f8(r[4]),
            next_params=_from_f8(r[5]), error=_from_f8(r[6]), gamma=r[7], scale=r[8], message=r[9],
            final_state=None if r[10] is None else _from_f8(r[10]),
            start_state=None if r[11] is None else _from_f8(r[11]), trajectory_rows=r[12], recorded_at=r[13],
            info=json.loads(r[14]) if r[14] else {}, times_s=times, states=states, plant_state=pstate)

    def iterations(self, session_id: int, *, trajectories: bool = False, plant_state: bool = False,
                   indices: Sequence[int] | None = None) -> list[IterationRecord]:
        """The session's iterations in order (optionally only ``indices``).

        Parameters
        ----------
        trajectories : also decode the measured trajectories.
        plant_state : also load the plant states.
        """
        columns = self._ITERATION_COLUMNS
        if trajectories:
            columns += ", trajectory, traj_rows, traj_cols, traj_codec"
        if plant_state:
            columns += ", plant_state"
        sql = f"SELECT {columns} FROM iterations WHERE session_id = ?"
        args: list[Any] = [session_id]
        if indices is not None:
            wanted = sorted({int(i) for i in indices})
            if not wanted:
                return []
            sql += f" AND idx IN ({', '.join('?' * len(wanted))})"
            args += wanted
        sql += " ORDER BY idx"
        with self._guard(f"reading iterations of session {session_id}"):
            rows = self._db.execute(sql, args).fetchall()
        n = 15
        try:
            return [self._iteration(r[:n], r[n:], trajectories, plant_state) for r in rows]
        except (ValueError, zlib.error) as exc:
            raise StoreFormatError(f"{self.path}: session {session_id}: damaged iteration data ({exc})") from None

    def last_iteration(self, session_id: int) -> IterationRecord | None:
        """The session's last stored iteration, with the plant state (None if it has none)."""
        with self._guard(f"reading iterations of session {session_id}"):
            r = self._db.execute(f"SELECT {self._ITERATION_COLUMNS}, plant_state FROM iterations WHERE "
                                 f"session_id = ? ORDER BY idx DESC LIMIT 1", (session_id,)).fetchone()
        return None if r is None else self._iteration(r[:15], r[15:], False, True)


    # -------------------------------------------------------------- studies (schema 3)

    def create_study(self, kind: str, spec: Mapping[str, Any]) -> int:
        """Record a new study; its id."""
        spec_json = _canonical(_json_ready(dict(spec)))

        def write(conn: sqlite3.Connection) -> int:
            cursor = conn.execute("INSERT INTO studies (kind, spec, created_at) VALUES (?, ?, ?)",
                                  (kind, spec_json, _now()))
            return int(cursor.lastrowid or 0)

        return int(self._write("creating a study", write))

    def resolve_study(self, ref: int | str) -> int:
        """A study id from ``ref`` (an id or ``last``); :class:`StoreError` if there is none."""
        with self._guard("reading studies"):
            if str(ref) == "last":
                row = self._db.execute("SELECT max(id) FROM studies").fetchone()
                if row is None or row[0] is None:
                    raise SessionNotFound(f"{self.path}: no studies yet")
                return int(row[0])
            try:
                study_id = int(ref)
            except (TypeError, ValueError):
                raise SessionNotFound(f"study {ref!r}: expected a study id or 'last'") from None
            if self._db.execute("SELECT 1 FROM studies WHERE id = ?", (study_id,)).fetchone() is None:
                raise SessionNotFound(f"{self.path}: no study {study_id}")
            return study_id

    def list_studies(self) -> list[tuple[int, str, str]]:
        """(id, kind, created_at) of every study, oldest first."""
        with self._guard("reading studies"):
            return [(int(r[0]), str(r[1]), str(r[2])) for r in
                    self._db.execute("SELECT id, kind, created_at FROM studies ORDER BY id")]

    def finished_study_jobs(self, study_id: int) -> set[str]:
        with self._guard("reading study jobs"):
            return {r[0] for r in self._db.execute("SELECT key FROM study_jobs WHERE study_id = ?", (study_id,))}

    def record_study_job(self, study_id: int, key: str, spec: Mapping[str, Any],
                         result: Mapping[str, Any]) -> None:
        """Store one finished job (committed before the next result is taken)."""
        spec_json = _canonical(_json_ready(dict(spec)))
        result_json = json.dumps(_json_ready(dict(result)), allow_nan=True)

        def write(conn: sqlite3.Connection) -> None:
            conn.execute("INSERT OR REPLACE INTO study_jobs (study_id, key, spec, result, recorded_at) "
                         "VALUES (?, ?, ?, ?, ?)", (study_id, key, spec_json, result_json, _now()))

        self._write("recording a study job", write)

    def study_results(self, study_id: int) -> dict[str, dict[str, Any]]:
        with self._guard("reading study jobs"):
            return {key: json.loads(result) for key, result in self._db.execute(
                "SELECT key, result FROM study_jobs WHERE study_id = ? ORDER BY key", (study_id,))}


def _nan_if_none(value: float | None) -> float:
    return math.nan if value is None else float(value)


def _rollback(conn: sqlite3.Connection) -> None:
    if conn.in_transaction:
        with contextlib.suppress(sqlite3.Error):
            conn.execute("ROLLBACK")


def _statements(script: str) -> list[str]:
    """Split a schema script into statements (no semicolons inside our DDL's strings)."""
    lines = [line.split("--", 1)[0] for line in script.splitlines()]
    return [s.strip() for s in "\n".join(lines).split(";") if s.strip()]
