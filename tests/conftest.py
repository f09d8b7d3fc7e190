"""Suite-wide guards."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest_plugins = ["real_time_lock"]  # one wall-clock flight at a time, whatever the scheduler does


@pytest.fixture(autouse=True, scope="session")
def _the_suite_leaves_the_users_store_alone():
    """No test may write the default store ``./aerobat.sqlite`` of the folder it runs in: give it ``--db``."""
    path = Path.cwd() / "aerobat.sqlite"

    def stamp():
        return path.stat().st_mtime_ns if path.exists() else None

    before = stamp()
    yield
    assert stamp() == before, f"a test wrote {path}: tests must pass --db (or run in a temporary folder)"


@pytest.fixture(autouse=True, scope="session")
def _ctrl_c_raises_keyboard_interrupt():
    """The Ctrl-C tests need SIGINT to raise KeyboardInterrupt, however the suite was started.

    A shell without job control starts a background command (``make test &``, ``nohup … &``)
    with SIGINT ignored, and Python then leaves it ignored: a Ctrl-C test would see nothing. The
    suite restores Python's default handler (its subprocesses then start with the default too).
    """
    import signal

    previous = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    if previous is not None:  # None: a handler not installed from Python, which cannot be put back
        signal.signal(signal.SIGINT, previous)


@pytest.fixture
def small_tmpfs(tmp_path):
    """``small_tmpfs(size="64k")``: a folder with a tmpfs of that size mounted on it (a disk that fills up).

    Every tmpfs is unmounted after the test; the test is skipped, with the reason, where none can be
    mounted (``tests/full_disk.py``). Fill one up with ``full_disk.fill_up``.
    """
    from full_disk import mount_tmpfs, unmount

    mounted: list[Path] = []

    def mount(size: str = "64k") -> Path:
        folder = tmp_path / f"tmpfs-{len(mounted)}"
        folder.mkdir()
        reason = mount_tmpfs(folder, size)
        if reason is not None:
            pytest.skip(f"no full disk to test on: {reason}")
        mounted.append(folder)
        return folder

    yield mount
    for folder in reversed(mounted):
        unmount(folder)
