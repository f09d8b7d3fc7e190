"""A real full disk for tests and the fuzz campaign: a small tmpfs, mounted where root may mount one.

``tests/conftest.py``'s ``small_tmpfs`` fixture mounts one per call and unmounts it after the test
(skipping the test, with the reason, where no tmpfs can be mounted: not Linux, not root, a
container without the capability); ``scripts/fuzz_exports.py`` loads this file for its full-disk
cases. A process-wide file size limit (``RLIMIT_FSIZE``, what ``tests/store/test_durability.py``
uses for a ``learn`` subprocess) fails writes with ``EFBIG``; a tmpfs fails them with ``ENOSPC``
exactly as a full disk does, in this process, for every file on it.
"""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
import sys
from pathlib import Path

__all__ = ["fill_up", "mount_tmpfs", "unmount"]


def mount_tmpfs(folder: Path, size: str = "64k") -> str | None:
    """Mount a tmpfs of ``size`` bytes (``64k``, ``4m``) on the existing ``folder``; None, or why it cannot."""
    if sys.platform != "linux":
        return f"a tmpfs is Linux's ({sys.platform})"
    if os.geteuid() != 0:
        return "mounting a tmpfs needs root"
    if shutil.which("mount") is None:
        return "no mount command"
    result = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size},mode=0755", "tmpfs", str(folder)],
                            capture_output=True, text=True, timeout=30)
    if result.returncode != 0:
        return f"mount -t tmpfs failed: {result.stderr.strip() or result.returncode}"
    return None


def unmount(folder: Path) -> None:
    """Unmount a tmpfs :func:`mount_tmpfs` mounted (lazily if something still holds a file on it)."""
    result = subprocess.run(["umount", str(folder)], capture_output=True, text=True, timeout=30)
    if result.returncode != 0:
        subprocess.run(["umount", "-l", str(folder)], capture_output=True, text=True, timeout=30, check=True)


def fill_up(folder: Path, *, leave: int = 0, name: str = ".filler") -> int:
    """Fill the file system of ``folder`` until at most ``leave`` bytes are free; the bytes free then.

    tmpfs counts whole pages: what is left is ``leave`` rounded down to a page (and 0 for 0).
    """
    free = os.statvfs(folder)
    room = free.f_bavail * free.f_frsize - leave
    block = bytes(64 * 1024)
    with open(folder / name, "ab", buffering=0) as filler:
        while room > 0:
            try:
                written = filler.write(block[:min(len(block), room)])
            except OSError as exc:
                if exc.errno != errno.ENOSPC:
                    raise
                break
            room -= written or 0
    after = os.statvfs(folder)
    return after.f_bavail * after.f_frsize
