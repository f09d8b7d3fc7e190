"""Record checksums: every stored row carries a CRC-32 of its content, verified whenever it is read.

SQLite checks the structure of its pages (``quick_check``) but not what a record holds: a
bit flipped inside a stored number, text or array by a bad disk or memory goes unnoticed
and comes back as a different value. From schema 5 every row of every table has a
``checksum`` column: the CRC-32 of the table's name and of the row's values (its key
included), each with its type and length. A row whose values do not give its checksum — a
flip in a value, in the record's header, in its key or in the checksum itself — is refused
with :class:`~aerobat.errors.StoreFormatError` naming the table and the row. CRC-32 catches
every single-bit and every two-bit error, and every burst of up to 32 bits, in records up
to hundreds of megabytes; other damage escapes it with probability 2⁻³².

An iteration's measured trajectory (the largest value by far) has its own checksum,
``traj_checksum``, which the row's checksum covers: reading iterations without their
trajectories does not read the trajectories, and reading them verifies them.

Values are checksummed as SQLite gives them back: NaN (stored as NULL) as NULL, integral
numbers as integers whatever column they are in (a REAL column keeps 3.0 as the integer 3).
"""

from __future__ import annotations

import math
import sqlite3
import struct
import zlib
from collections.abc import Mapping, Sequence
from typing import Any

from aerobat.errors import StoreFormatError

__all__ = ["COVERED", "KEYS", "backfill", "blob_checksum", "insert", "record_checksum", "select_list", "update",
           "verify"]

COVERED: dict[str, tuple[str, ...]] = {
    "meta": ("key", "value"),
    "vehicles": ("id", "name", "config", "digest"),
    "plants": ("id", "kind", "vehicle_id", "config", "digest"),
    "maneuvers": ("id", "kind", "name", "spec", "parameter_names", "parameter_units", "error_names", "error_units",
                  "error_scales", "digest", "error_kinds"),
    "designs": ("id", "maneuver_id", "vehicle_id", "n_par", "n_err", "p_guess", "p_nominal", "residual",
                "residual_norm", "jacobian", "correction", "correction_kind", "singular_values", "condition_number",
                "rank", "converged", "status", "message", "duration_s", "compute_s", "evaluations", "created_at",
                "digest"),
    "sessions": ("id", "maneuver_id", "design_id", "plant_id", "seed", "rule", "target_iterations", "start_params",
                 "warm_start_from", "state", "message", "started_at", "updated_at", "ended_at", "host", "pid", "owner",
                 "command", "aerobat_version", "n_records", "n_measured", "last_index", "last_correction",
                 "last_error", "last_position_error_m", "current_params", "study_id", "tags", "notes"),
    "iterations": ("session_id", "idx", "correction", "status", "params", "next_params", "error", "gamma", "scale",
                   "message", "final_state", "start_state", "traj_rows", "traj_cols", "traj_codec", "info",
                   "recorded_at", "plant_state", "learner_state", "traj_checksum", "notes", "signal_names",
                   "signal_rows", "signal_codec", "signal_checksum"),
    "studies": ("id", "kind", "spec", "created_at", "command", "out_dir"),
    "study_jobs": ("study_id", "key", "spec", "result", "recorded_at", "status", "error", "attempts", "session_id"),
}
"""The columns each table's checksum covers, in order (every column but ``checksum``,
``iterations.trajectory``, which ``traj_checksum`` covers, and ``iterations.signals``, which
``signal_checksum`` covers; ``iterations.notes`` since schema 6, the ``signal_*`` columns since 7)."""

KEYS: dict[str, tuple[str, ...]] = {"meta": ("key",), "iterations": ("session_id", "idx"),
                                    "study_jobs": ("study_id", "key")}
"""Each table's key (``id`` where not listed)."""


def key_of(table: str) -> tuple[str, ...]:
    return KEYS.get(table, ("id",))


def _canon(value: Any) -> bytes:
    if value is None:
        return b"n"
    if isinstance(value, bool | int):
        return b"i" + str(int(value)).encode()
    if isinstance(value, float):
        if math.isnan(value):
            return b"n"  # SQLite stores NaN as NULL
        if value.is_integer() and abs(value) < 2.0**63:
            return b"i" + str(int(value)).encode()  # REAL columns keep integral values as integers
        return b"f" + struct.pack("<d", value)
    if isinstance(value, str):
        data = value.encode("utf-8", "surrogatepass")
        return b"s" + struct.pack("<Q", len(data)) + data
    if isinstance(value, bytes | bytearray | memoryview):
        data = bytes(value)
        return b"b" + struct.pack("<Q", len(data)) + data
    raise TypeError(f"cannot checksum a {type(value).__name__}")  # a bug: the store binds only these types


def record_checksum(table: str, values: Sequence[Any]) -> int:
    """CRC-32 of ``table`` and the row's covered values (in :data:`COVERED` order)."""
    crc = zlib.crc32(table.encode())
    for value in values:
        crc = zlib.crc32(_canon(value), crc)
    return crc


def blob_checksum(blob: bytes | None) -> int | None:
    """CRC-32 of a large value kept apart (a trajectory); None for none."""
    return None if blob is None else zlib.crc32(blob)


def select_list(table: str, alias: str = "") -> str:
    """``col, col, …, checksum`` for a SELECT that :func:`verify` can check."""
    prefix = f"{alias}." if alias else ""
    return ", ".join(f"{prefix}{c}" for c in (*COVERED[table], "checksum"))


def _describe(table: str, values: Mapping[str, Any]) -> str:
    key = ", ".join(f"{k} {values.get(k)!r}" for k in key_of(table))
    return f"{table} record ({key})"


def verify(path: Any, table: str, row: Sequence[Any]) -> dict[str, Any]:
    """The row (covered values then checksum, as :func:`select_list` selects) as a dict, if intact.

    Raises
    ------
    StoreFormatError
        Its values do not give its checksum, or it has none.
    """
    columns = COVERED[table]
    values = dict(zip(columns, row[: len(columns)], strict=True))
    stored = row[len(columns)]
    try:
        good = isinstance(stored, int) and stored == record_checksum(table, row[: len(columns)])
    except TypeError:
        good = False
    if not good:
        raise StoreFormatError(
            f"{path}: the {_describe(table, values)} fails its checksum: it changed on disk (a bad disk or memory, "
            f"or an edit outside aerobat), so it is not used — restore the store from a backup; other records "
            f"are still readable")
    return values


def verify_blob(path: Any, where: str, blob: bytes | None, stored: int | None, *,
                what: str = "measured trajectory") -> None:
    """Raise if a blob kept apart (a trajectory, a plant's signals) does not give the checksum its row holds."""
    if blob_checksum(blob) != stored:
        raise StoreFormatError(f"{path}: the {what} of {where} fails its checksum: it changed on disk, "
                               f"so it is not used — restore the store from a backup")


def insert(conn: sqlite3.Connection, table: str, row: Mapping[str, Any], *, extra: Mapping[str, Any] | None = None,
           verb: str = "INSERT") -> None:
    """Insert a row (every covered column given) with its checksum; ``extra``: columns not covered."""
    columns = COVERED[table]
    values = [row[c] for c in columns]
    names = [*columns, "checksum", *(extra or {})]
    marks = ", ".join("?" * len(names))
    conn.execute(f"{verb} INTO {table} ({', '.join(names)}) VALUES ({marks})",
                 (*values, record_checksum(table, values), *(extra or {}).values()))


def fetch(conn: sqlite3.Connection, path: Any, table: str, key: Mapping[str, Any]) -> dict[str, Any] | None:
    """One row by its key, verified (None if there is none)."""
    where = " AND ".join(f"{k} = ?" for k in key)
    row = conn.execute(f"SELECT {select_list(table)} FROM {table} WHERE {where}", tuple(key.values())).fetchone()
    return None if row is None else verify(path, table, row)


def update(conn: sqlite3.Connection, path: Any, table: str, key: Mapping[str, Any],
           changes: Mapping[str, Any], *, old: dict[str, Any] | None = None) -> dict[str, Any] | None:
    """Change some columns of a verified row and its checksum; the row as it was (None if missing).

    ``old``: the row as :func:`fetch` just read it in this transaction. A row that fails its
    checksum is not written to (:class:`StoreFormatError`).
    """
    old = old if old is not None else fetch(conn, path, table, key)
    if old is None:
        return None
    new = {**old, **changes}
    sets = ", ".join(f"{c} = ?" for c in (*changes, "checksum"))
    where = " AND ".join(f"{k} = ?" for k in key)
    conn.execute(f"UPDATE {table} SET {sets} WHERE {where}",
                 (*changes.values(), record_checksum(table, [new[c] for c in COVERED[table]]), *key.values()))
    return old


def backfill(conn: sqlite3.Connection, table: str, columns: Sequence[str] | None = None) -> None:
    """Give every row of ``table`` its checksum (the migration to schema 5; ``columns``: the covered
    columns at that version, default :data:`COVERED`'s)."""
    columns = tuple(COVERED[table] if columns is None else columns)
    keys = key_of(table)
    where = " AND ".join(f"{k} = ?" for k in keys)
    if table == "iterations":
        conn.executemany("UPDATE iterations SET traj_checksum = ? WHERE session_id = ? AND idx = ?",
                         [(blob_checksum(blob), sid, idx) for sid, idx, blob in
                          conn.execute("SELECT session_id, idx, trajectory FROM iterations").fetchall()])
    updates = []
    for r in conn.execute(f"SELECT {', '.join(columns)} FROM {table}").fetchall():
        values = dict(zip(columns, r, strict=True))
        updates.append((record_checksum(table, r), *(values[k] for k in keys)))
    conn.executemany(f"UPDATE {table} SET checksum = ? WHERE {where}", updates)
