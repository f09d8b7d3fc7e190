"""The experiment store: every design, learning session, trial and study in one SQLite file.

:class:`Store` is the interface; see ``docs/store.md`` for the schema, the
guarantees and how each is tested. The store imports only the method's types and
the error hierarchy: it knows nothing about quadrocopters.
"""

from aerobat.errors import (
    SessionInUse,
    SessionNotFound,
    StoreAccessError,
    StoreBusyError,
    StoreError,
    StoreFormatError,
    StoreVersionError,
    StoreWriteError,
)
from aerobat.store.browse import SHOWN_STATES, SessionComparison
from aerobat.store.codec import decode_trajectory, encode_trajectory
from aerobat.store.database import DEFAULT_PATH, default_path
from aerobat.store.owners import owner_alive
from aerobat.store.query import SessionPage, SessionQuery, SortKey
from aerobat.store.records import (
    DesignRecord,
    IterationRecord,
    ManeuverRecord,
    PlantRecord,
    SessionRecord,
    SessionSummary,
    StudyJobRecord,
    StudyKind,
    StudyRecord,
    VehicleRecord,
)
from aerobat.store.store import SESSION_STATES, Store

__all__ = [
    "DEFAULT_PATH",
    "SESSION_STATES",
    "SHOWN_STATES",
    "SessionPage",
    "SessionQuery",
    "SortKey",
    "SessionComparison",
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
    "StudyJobRecord",
    "StudyKind",
    "StudyRecord",
    "VehicleRecord",
    "decode_trajectory",
    "default_path",
    "encode_trajectory",
    "owner_alive",
]
