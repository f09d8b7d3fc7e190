"""The experiment store's file: opening, checking, migrating and transactions (one SQLite file).

A :class:`Database` opens a file only after a read-only look has shown that it is
an aerobat store of a version this aerobat reads (foreign, newer and damaged files
are refused and never modified), creates or migrates its schema in one transaction,
and runs every write as one short ``BEGIN IMMEDIATE`` transaction, retried while
another process holds the lock. SQLite errors become :mod:`aerobat.errors` store
errors that name the file and what went wrong.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import sqlite3
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Literal, Self
from urllib.parse import quote

from aerobat.config import as_path, check_range, short_repr
from aerobat.errors import (
    ConfigError,
    SessionNotFound,
    StoreAccessError,
    StoreBusyError,
    StoreError,
    StoreFormatError,
    StoreVersionError,
    StoreWriteError,
)
from aerobat.fileio import default_store_path, store_sibling_suffix
from aerobat.store import checksums
from aerobat.store.codec import utc_now
from aerobat.store.migrations import (
    APPLICATION_ID,
    SCHEMA,
    SCHEMA_VERSION,
    TABLES,
    TABLES_SINCE,
    migrate,
    sql_statements,
)
from aerobat.store.owners import owner_token

__all__ = ["DEFAULT_PATH", "Database", "default_path", "next_id", "rollback", "sql_statements"]

DEFAULT_PATH = "aerobat.sqlite"
"""Default database file, relative to the working directory (``AEROBAT_DB`` overrides it)."""

_SQLITE_MAGIC = b"SQLite format 3\x00"


def default_path() -> str:
    """The database used when ``--db`` is not given: ``$AEROBAT_DB`` or ``./aerobat.sqlite``."""
    return default_store_path()


class Database:
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
    on_wait : called with a message when a write has waited a while for another process's lock.

    Opening is careful: ``path`` is always a filesystem path (never an SQLite URI, even if it
    starts with ``file:``); a store opened to write (``create=True``) must pass SQLite's
    ``quick_check`` and carry aerobat's identity (``application_id`` and ``meta.application``),
    and its file and folder must be writable — checked before anything is written. A store
    opened to read only is opened read-only (``immutable`` in a read-only folder), and a failed
    check is reported in :attr:`problems` instead of refusing it. Each write first checks that
    the file is still the one that was opened (not deleted or replaced).

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
                 synchronous: Literal["normal", "full"] = "normal", busy_timeout_s: float = 60.0,
                 on_wait: Any = None) -> None:
        if not isinstance(synchronous, str) or synchronous not in ("normal", "full"):
            raise ConfigError(f"synchronous = {short_repr(synchronous)}: allowed 'normal' or 'full'")
        if not isinstance(create, bool):
            raise ConfigError(f"create = {short_repr(create)}: allowed True or False")
        if on_wait is not None and not callable(on_wait):
            raise ConfigError(f"on_wait = {short_repr(on_wait)}: allowed a callable or None")
        if not isinstance(path, str | os.PathLike):
            raise StoreAccessError(f"--db: expected a database file path, got {type(path).__name__} "
                                   f"{short_repr(path)}")
        if not str(path).strip():
            raise StoreAccessError("--db: empty database path")
        suffix = store_sibling_suffix(path)
        if suffix is not None:  # issue 31 D6: the next `--db X` would take this file for X's own and delete it
            raise StoreAccessError(f"--db {os.fspath(path)}: named like the {suffix} file SQLite keeps next to a "
                                   f"store {os.fspath(path)[:-len(suffix)]}; choose a name that does not end in "
                                   f"-wal, -shm or -journal")
        check_range("busy_timeout_s", busy_timeout_s, low=0.0, unit="s")
        self.path = as_path(path, "--db")
        self.busy_timeout_s = float(busy_timeout_s)
        self.owner = owner_token()
        self.migrated_from: list[int] = []
        self.problems: list[str] = []
        self.writing = create
        self.on_wait = on_wait
        self._conn: sqlite3.Connection | None = None
        self._identity: tuple[int, int] | None = None
        try:
            fresh = self._check_file(create)
            if fresh and create and not self.path.exists() and self._create_file():
                fresh = self._check_file(create)  # now a complete store (ours, or another process's)
            read_only = not create and not os.access(self.path.parent if str(self.path.parent) else ".", os.W_OK)
            uri = f"file:{quote(os.fsencode(self.path.resolve()))}" + ("?mode=ro&immutable=1" if read_only else
                                                               "" if create else "?mode=ro")
        except OSError as exc:  # a name too long for the file system, a loop of links, an I/O error…
            raise StoreAccessError(f"{self.path}: cannot open the database: {exc.strerror or exc}") from None
        if read_only:
            self.problems.append(f"{self.path}: its folder is read-only: opened as an unchanging snapshot")
        try:
            self._conn = sqlite3.connect(uri, uri=True, timeout=min(self.busy_timeout_s, 1.0), isolation_level=None,
                                         check_same_thread=False)
        except sqlite3.Error as exc:
            raise self._translate(exc, "opening the database") from None
        # text that is not UTF-8 (a flipped bit can turn a blob into text) is read as it is and then
        # fails its record's checksum, instead of failing the query
        self._conn.text_factory = lambda data: data.decode("utf-8", "surrogateescape")
        try:
            with self._guard("opening the database"):
                self._conn.execute("PRAGMA foreign_keys = ON")
                self._conn.execute(f"PRAGMA synchronous = {synchronous.upper()}")
                if fresh:
                    self._initialize()
                elif create:
                    self._upgrade_if_needed()
            self._identity = self._file_identity()
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
            if not parent.is_dir():  # a new store's folders are made, as an output's are
                try:
                    parent.mkdir(parents=True, exist_ok=True)
                except OSError as exc:
                    raise StoreAccessError(f"{path}: cannot create the database: cannot make the directory "
                                           f"{parent} ({exc.strerror or exc})") from None
            if not os.access(parent, os.W_OK):
                raise StoreAccessError(f"{path}: cannot create the database: directory {parent} is read-only")
            return True
        if not path.is_file():
            raise StoreAccessError(f"{path}: not a regular file, expected a database file (--db PATH)")
        if create and not os.access(path, os.W_OK):
            raise StoreAccessError(f"{path}: the database is read-only; nothing can be stored in it (commands that "
                                   f"only read it, like `aerobat sessions`, still work)")
        folder = path.parent if str(path.parent) else Path(".")
        if create and not os.access(folder, os.W_OK):
            raise StoreAccessError(f"{path}: its folder {folder} is read-only: SQLite needs to create its journal "
                                   f"files there to write (commands that only read the store still work)")
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
        uri = f"file:{quote(os.fsencode(path.resolve()))}?mode=ro"
        with path.open("rb") as handle:
            wal_format = handle.read(20)[18:20] == b"\x02\x02"
        side_files = any(Path(f"{path}{suffix}").exists() for suffix in ("-wal", "-shm"))
        if wal_format and not side_files:
            # nobody has it open and its WAL is empty: read the file alone, so that refusing
            # it leaves no -wal/-shm files behind
            uri += "&immutable=1"
        deadline = time.monotonic() + self.busy_timeout_s
        told = False
        while True:
            try:
                app_id, version, tables, tagged, damage = self._probe_read(uri)
                break
            except StoreBusyError:
                # In WAL mode nothing but an exclusive lock keeps a reader out (another program's
                # PRAGMA locking_mode = EXCLUSIVE, or an aerobat recovering a crashed WAL): say so at once
                if time.monotonic() >= deadline:
                    raise StoreBusyError(
                        f"{path}: another process kept the database locked for {self.busy_timeout_s:g} s (an "
                        f"exclusive lock, e.g. a program holding it with PRAGMA locking_mode = EXCLUSIVE); "
                        f"nothing was read or written — close that program and try again") from None
                if not told and self.on_wait is not None:
                    self.on_wait(f"{path}: another process holds the database with an exclusive lock (e.g. PRAGMA "
                                 f"locking_mode = EXCLUSIVE); waiting up to {self.busy_timeout_s:g} s for it")
                    told = True
                time.sleep(0.05)
        ours = app_id == APPLICATION_ID or tagged
        if ours and damage != ["ok"]:
            lines = [line.strip() for entry in damage for line in str(entry).splitlines()
                     if line.strip() and not line.startswith("***")]
            detail = "; ".join(lines[:3]) + (" …" if len(lines) > 3 else "")
            if self.writing:
                raise StoreFormatError(f"{path}: the database is damaged (SQLite's quick_check: {detail}); nothing "
                                       f"was written to it — restore it from a backup, or read what is left with "
                                       f"`aerobat sessions` / `show` / `export`")
            self.problems.append(f"{path}: the database is damaged (quick_check: {detail}); what it shows may be "
                                 f"incomplete")
        if ours and not (app_id == APPLICATION_ID and tagged) and tables:
            changed = "its application_id" if app_id != APPLICATION_ID else "its meta.application entry"
            if self.writing:
                raise StoreFormatError(f"{path}: {changed} was changed: it no longer identifies as an aerobat store, "
                                       f"so nothing is written to it (reading it still works)")
            self.problems.append(f"{path}: {changed} was changed: it no longer identifies as an aerobat store")
        if not ours:
            if not tables and app_id == 0:
                if not self.writing:
                    # An SQLite file without tables: nothing to read. It is also what a store looks like
                    # for an instant while another process creates it (its header written, its schema
                    # not yet committed); a reader must not try to create the schema through its
                    # read-only connection ("attempt to write a readonly database").
                    raise StoreAccessError(f"{path}: an empty SQLite file, no aerobat database yet; "
                                           f"`aerobat learn` creates one")
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

    def _create_file(self) -> bool:
        """Create a missing store atomically; False where the file system cannot (then it is created in place).

        The schema is written into a private file next to it, which is then hard-linked to the
        store's name: other processes see no file or a complete store, never one half created
        (a reader that found the bare SQLite header of a store being created used to take it for
        an empty database). If another process links its file first, that one is used.
        """
        path = self.path
        tmp = path.with_name(f".{path.name}.creating-{os.getpid()}-{secrets.token_hex(4)}")
        try:
            conn = sqlite3.connect(f"file:{quote(os.fsencode(tmp.resolve()))}", uri=True, isolation_level=None)
            try:
                self._initialize(conn)
            finally:
                conn.close()
            try:
                os.link(tmp, path)
            except FileExistsError:
                pass  # another process created it meanwhile: use that one
            except OSError:
                return False  # no hard links here (some network or FAT file systems)
            return True
        except sqlite3.Error as exc:
            raise self._translate(exc, "creating the database") from None
        finally:
            for suffix in ("", "-wal", "-shm", "-journal"):
                with contextlib.suppress(OSError):
                    os.unlink(f"{tmp}{suffix}")

    def _probe_read(self, uri: str) -> tuple[int, int, list[str], bool, list[str]]:
        """application_id, user_version, tables, meta tag and quick_check, in one read transaction."""
        try:
            probe = sqlite3.connect(uri, uri=True, timeout=0.25, isolation_level=None)
        except sqlite3.Error as exc:
            raise StoreAccessError(f"{self.path}: cannot open the database for reading: {exc}") from None
        try:
            probe.execute("BEGIN")  # one read transaction: every answer below describes the same moment
            app_id = probe.execute("PRAGMA application_id").fetchone()[0]
            version = probe.execute("PRAGMA user_version").fetchone()[0]
            tables = [r[0] for r in probe.execute(
                "SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE 'sqlite_%' ORDER BY name")]
            tagged = False
            if "meta" in tables:
                with contextlib.suppress(sqlite3.Error):
                    row = probe.execute("SELECT value FROM meta WHERE key = 'application'").fetchone()
                    tagged = bool(row and row[0] == "aerobat")
            damage = [r[0] for r in probe.execute("PRAGMA quick_check(20)")] if tables else ["ok"]
        except sqlite3.DatabaseError as exc:
            kind = getattr(exc, "sqlite_errorname", "")
            if kind.startswith(("SQLITE_BUSY", "SQLITE_LOCKED")):
                raise StoreBusyError(f"{self.path}: the database is locked by another process") from None
            raise StoreFormatError(f"{self.path}: not a usable aerobat database ({exc}); the file was not modified "
                                   f"— restore it from a backup or choose another --db path") from None
        finally:
            probe.close()
        return app_id, version, tables, tagged, damage

    def _initialize(self, conn: sqlite3.Connection | None = None) -> None:
        own = conn is None
        conn = self._db if conn is None else conn
        conn.execute("PRAGMA journal_mode = WAL")
        conn.execute("BEGIN IMMEDIATE")
        try:
            existing = conn.execute("SELECT count(*) FROM sqlite_master WHERE name NOT LIKE 'sqlite_%'").fetchone()[0]
            if existing == 0:  # another process may have created it meanwhile
                for statement in sql_statements(SCHEMA):
                    conn.execute(statement)
                conn.execute(f"PRAGMA application_id = {APPLICATION_ID}")
                conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
                from aerobat import __version__

                for key, value in (("application", "aerobat"), ("created_by", __version__),
                                   ("created_at", utc_now())):
                    checksums.insert(conn, "meta", {"key": key, "value": value})
            conn.execute("COMMIT")
        except BaseException:
            rollback(conn)
            raise
        if existing and own:
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
                    checksums.insert(conn, "meta", {"key": f"migrated_from_{version}", "value": utc_now()},
                                     verb="INSERT OR REPLACE")
                conn.execute("COMMIT")
            except BaseException:
                rollback(conn)
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

    def __enter__(self) -> Self:
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
        except OverflowError as exc:  # an id beyond SQLite's 64-bit integers: no such row can exist
            raise SessionNotFound(f"{self.path}: {action}: {exc}") from None

    def _file_identity(self) -> tuple[int, int] | None:
        try:
            stat = os.stat(self.path)
        except OSError:
            return None
        return stat.st_dev, stat.st_ino

    def _check_still_there(self, action: str) -> None:
        if self._identity is not None and self._file_identity() != self._identity:
            raise StoreWriteError(f"{self.path}: {action} failed: the database file was deleted or replaced while "
                                  f"in use; nothing more is written (what was stored is in the file that was removed)")

    def _write(self, action: str, fn: Any) -> Any:
        """Run ``fn(conn)`` in one ``BEGIN IMMEDIATE`` transaction, waiting up to ``busy_timeout_s`` for a lock."""
        conn = self._db
        if not self.writing:
            raise StoreAccessError(f"{self.path}: {action}: the store was opened for reading only")
        self._check_still_there(action)
        waited = 0.0
        told = False
        while True:
            try:
                with self._guard(action):
                    conn.execute("BEGIN IMMEDIATE")
                    try:
                        result = fn(conn)
                        conn.execute("COMMIT")
                    except BaseException:
                        rollback(conn)
                        raise
                return result
            except StoreBusyError:
                waited += 1.0  # the connection's own busy timeout
                if waited >= self.busy_timeout_s:
                    raise
                if not told and self.on_wait is not None:
                    self.on_wait(f"{self.path}: waiting for another process's lock to {action} (up to "
                                 f"{self.busy_timeout_s:g} s)")
                    told = True
                time.sleep(0.05)

    def integrity_check(self) -> list[str]:
        """``PRAGMA integrity_check`` and ``foreign_key_check``: an empty list if the file is sound."""
        with self._guard("checking integrity"):
            rows = [r[0] for r in self._db.execute("PRAGMA integrity_check")]
            problems = [] if rows == ["ok"] else rows
            problems += [f"foreign key: {r}" for r in self._db.execute("PRAGMA foreign_key_check")]
        return problems



def next_id(conn: sqlite3.Connection, table: str) -> int:
    """The id a new row of ``table`` gets (inside the caller's write transaction; its checksum covers it)."""
    return int(conn.execute(f"SELECT coalesce(max(id), 0) + 1 FROM {table}").fetchone()[0])


def rollback(conn: sqlite3.Connection) -> None:
    if conn.in_transaction:
        with contextlib.suppress(sqlite3.Error):
            conn.execute("ROLLBACK")
