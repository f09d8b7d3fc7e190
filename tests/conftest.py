"""Suite-wide guards."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(autouse=True, scope="session")
def _the_suite_leaves_the_users_store_alone():
    """No test may write the default store ``./aerobat.sqlite`` of the folder it runs in: give it ``--db``."""
    path = Path.cwd() / "aerobat.sqlite"

    def stamp():
        return path.stat().st_mtime_ns if path.exists() else None

    before = stamp()
    yield
    assert stamp() == before, f"a test wrote {path}: tests must pass --db (or run in a temporary folder)"
