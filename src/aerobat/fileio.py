"""Files in and out, checked in one place: what aerobat reads, what it writes, and what it never touches.

Inputs (:func:`read_input`) are regular files only, read up to a size cap: a FIFO would block
forever and ``/dev/zero`` would grow memory until the process is killed.

Outputs are checked before any work is done (:func:`check_output`) and written atomically
(:func:`write_output`, :func:`atomic_output`): the new content goes to a temporary file in the
same folder that then replaces the name. Writing therefore never goes *through* a symbolic or a
hard link — a link named like an output is replaced, the file it points to is untouched —
and a write that fails half way leaves the old file whole. Character devices (``/dev/null``)
are written directly. Nothing is ever written over an experiment store: the store a command
opens, the default one (``$AEROBAT_DB`` or ``./aerobat.sqlite``), their ``-wal``, ``-shm`` and
``-journal`` files (found by device and inode, so links and other names are recognised), and
any file that starts like an SQLite database.

Folders a command writes by default are unique per store and per session or study
(:func:`default_folder`), and carry an owner marker (:data:`OWNER_FILE`) so that a folder of
another store, or of another session, is never written into by default.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import stat
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO, Any

from aerobat.errors import ConfigError, DiskFull, OutputError

__all__ = [
    "MAX_INPUT_BYTES",
    "OWNER_FILE",
    "STORE_SIBLINGS",
    "atomic_output",
    "check_output",
    "check_output_folder",
    "claim_folder",
    "default_folder",
    "default_store_path",
    "folder_owner",
    "make_output_folder",
    "read_input",
    "read_input_text",
    "store_sibling_suffix",
    "write_output",
]

MAX_INPUT_BYTES = 16 * 2**20
"""The largest program, maneuver, vehicle or settings file aerobat reads (16 MiB)."""
STORE_SIBLINGS = ("-wal", "-shm", "-journal")
"""The files SQLite keeps next to a database ``X``: ``X-wal``, ``X-shm``, ``X-journal``."""
OWNER_FILE = ".aerobat-owner"
"""The marker in an output folder naming the store and the session or study it belongs to."""

_SQLITE_MAGIC = b"SQLite format 3\x00"
_WAL_MAGIC = (b"\x37\x7f\x06\x82", b"\x37\x7f\x06\x83")
_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)
_KIND = {stat.S_IFIFO: "a FIFO", stat.S_IFSOCK: "a socket", stat.S_IFBLK: "a block device",
         stat.S_IFCHR: "a character device", stat.S_IFDIR: "a folder"}


def _named(path: Path, option: str | None) -> str:
    return f"{option} {path}" if option else str(path)


def _as_path(value: Any, option: str | None) -> Path:
    name = option or "path"
    if not isinstance(value, str | os.PathLike):
        raise ConfigError(f"{name}: expected a file path (str or pathlib.Path), got {type(value).__name__}")
    try:
        text = os.fspath(value)
    except TypeError as exc:
        raise ConfigError(f"{name}: expected a file path ({exc})") from None
    if not isinstance(text, str):
        raise ConfigError(f"{name}: expected a file path given as text, got {type(text).__name__}")
    if not text.strip():
        raise ConfigError(f"{name}: empty file name")
    if "\x00" in text:
        raise ConfigError(f"{name} {text!r}: a file path cannot contain a NUL character")
    return Path(text)


def _kind(mode: int) -> str:
    return _KIND.get(stat.S_IFMT(mode), "not a regular file")


# ------------------------------------------------------------------ inputs


def read_input(path: Any, option: str | None = None, *, limit: int = MAX_INPUT_BYTES, what: str = "file") -> bytes:
    """The bytes of the regular file ``path``; :class:`ConfigError` naming ``option`` and the file otherwise.

    A FIFO, a device, a socket or a folder is refused without being read (the file is opened
    non-blocking and checked with ``fstat``, so a FIFO cannot block even if it replaced the file
    after a first look); a file larger than ``limit`` bytes is refused after reading ``limit + 1``.
    """
    path = _as_path(path, option)
    name = _named(path, option)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise ConfigError(f"{name}: file not found") from None
    except IsADirectoryError:
        raise ConfigError(f"{name}: is a directory, expected a {what}") from None
    except PermissionError:
        raise ConfigError(f"{name}: permission denied") from None
    except OSError as exc:  # a name too long, a loop of links, a path through a file, ENXIO (a socket)…
        raise ConfigError(f"{name}: cannot read: {exc.strerror or exc}") from None
    try:
        info = os.fstat(fd)
        if stat.S_ISDIR(info.st_mode):
            raise ConfigError(f"{name}: is a directory, expected a {what}")
        if not stat.S_ISREG(info.st_mode):
            raise ConfigError(f"{name}: {_kind(info.st_mode)}, not a regular file; expected a {what}")
        if info.st_size > limit:
            raise ConfigError(f"{name}: {info.st_size} bytes, larger than the {limit} bytes a {what} may have")
        os.set_blocking(fd, True)
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(fd, min(1 << 20, limit + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as exc:
        raise ConfigError(f"{name}: cannot read: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if size > limit:
        raise ConfigError(f"{name}: larger than the {limit} bytes a {what} may have")
    return b"".join(chunks)


def read_input_text(path: Any, option: str | None = None, *, limit: int = MAX_INPUT_BYTES,
                    what: str = "text file") -> str:
    """:func:`read_input` decoded as UTF-8; :class:`ConfigError` for bytes that are not UTF-8."""
    data = read_input(path, option, limit=limit, what=what)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{_named(Path(path), option)}: not a UTF-8 text file ({exc.reason})") from None


# ------------------------------------------------------------------ the stores


def default_store_path() -> str:
    """The store a command uses without ``--db``: ``$AEROBAT_DB`` or ``./aerobat.sqlite``."""
    return os.environ.get("AEROBAT_DB") or "aerobat.sqlite"


def store_sibling_suffix(path: Any) -> str | None:
    """``"-wal"``, ``"-shm"`` or ``"-journal"`` when ``path`` is named like one of SQLite's files next to a store."""
    text = os.fspath(path) if isinstance(path, str | os.PathLike) else ""
    return next((s for s in STORE_SIBLINGS if str(text).endswith(s)), None)


def _identities(stores: Iterable[Any]) -> dict[tuple[int, int], str]:
    """(device, inode) → name, of every existing store file and its siblings (the default store always)."""
    found: dict[tuple[int, int], str] = {}
    for store in (*stores, default_store_path()):
        if store is None:
            continue
        for suffix in ("", *STORE_SIBLINGS):
            name = f"{os.fspath(store)}{suffix}"
            with contextlib.suppress(OSError, ValueError):
                info = os.stat(name)
                found.setdefault((info.st_dev, info.st_ino), name)
    return found


def _looks_like_store(path: Path) -> bool:
    try:
        with open(path, "rb", buffering=0) as handle:
            head = handle.read(16)
    except OSError:
        return False
    return head.startswith(_SQLITE_MAGIC) or head[:4] in _WAL_MAGIC


# ------------------------------------------------------------------ outputs


def check_output(path: Any, *, option: str | None = None, force: bool = False, stores: Iterable[Any] = (),
                 devices: bool = True, can_force: bool = True) -> Path:
    """Refuse, before any work, an output ``path`` that cannot or must not be written; returns it as a Path.

    Refused always (:class:`ConfigError`, exit 2): the store (any name or link of it, its
    ``-wal``/``-shm``/``-journal``), a name ending in one of those suffixes, a file that starts
    like an SQLite database, a folder, a FIFO, a socket or a block device, a dangling symbolic
    link, an empty name, a folder where nothing can be created. Refused without ``force``: an
    existing file. Character devices (``/dev/null``) are accepted when ``devices``. ``can_force``:
    whether the command has a ``--force`` to suggest.
    """
    path = _as_path(path, option)
    name = _named(path, option)
    try:
        return _check_output(path, name, force=force, stores=stores, devices=devices, can_force=can_force)
    except OSError as exc:  # a name too long for the file system, a path through a file, a loop of links…
        raise ConfigError(f"{name}: {exc.strerror or exc}") from None


def _check_output(path: Path, name: str, *, force: bool, stores: Iterable[Any], devices: bool,
                  can_force: bool) -> Path:
    if store_sibling_suffix(path) is not None:
        raise ConfigError(f"{name}: named like an SQLite journal file ({store_sibling_suffix(path)}) of a store; "
                          f"choose another name")
    try:
        link = os.lstat(path)
    except FileNotFoundError:
        _check_can_create(path, name)
        return path
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise ConfigError(f"{name}: a symbolic link to {os.readlink(path)}, which does not exist; remove the link "
                          f"or choose another name") from None
    store = _identities(stores).get((info.st_dev, info.st_ino))
    if store is not None:
        how = " (through a link)" if stat.S_ISLNK(link.st_mode) or info.st_nlink > 1 else ""
        raise ConfigError(f"{name}: that is the experiment store {store}{how}; choose another file")
    if stat.S_ISDIR(info.st_mode):
        raise ConfigError(f"{name}: is a folder, expected a file")
    if stat.S_ISCHR(info.st_mode) and devices:
        return path
    if not stat.S_ISREG(info.st_mode):
        raise ConfigError(f"{name}: {_kind(info.st_mode)}, not a regular file; choose a file name")
    if _looks_like_store(path):
        raise ConfigError(f"{name}: an SQLite database (an experiment store?); aerobat never writes over one")
    if not force:
        raise ConfigError(f"{name}: the file exists; choose another name" + (
            " or pass --force to replace it" if can_force else " or remove it first"))
    folder = path.parent
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ConfigError(f"{name}: cannot replace it: its folder {folder} is not writable")
    return path


def _check_can_create(path: Path, name: str) -> None:
    """A missing output: its folder is made if missing (as ``--out DIR`` is) and must take a new file (probed with a
    create, then removed)."""
    folder = path.parent
    if not folder.is_dir():
        if os.path.lexists(folder):
            raise ConfigError(f"{name}: {folder} is not a folder")
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ConfigError(f"{name}: cannot make the folder {folder}: {exc.strerror or exc}") from None
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o600)
    except FileExistsError:  # created meanwhile: the write checks it again
        return
    except OSError as exc:
        raise ConfigError(f"{name}: cannot create the file: {exc.strerror or exc}") from None
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(path)


def _write_error(path: Path, option: str | None, exc: OSError) -> Exception:
    reason = exc.strerror or str(exc)
    if exc.errno in _FULL:
        return DiskFull(f"{_named(path, option)}: cannot write: the disk is full or a file size limit was reached "
                        f"({reason})")
    return OutputError(f"{_named(path, option)}: cannot write: {reason}")


@contextlib.contextmanager
def atomic_output(path: Any, *, option: str | None = None, stores: Iterable[Any] = ()) -> Iterator[IO[bytes]]:
    """A binary file to write ``path``'s new content into; it replaces ``path`` when the block ends without error.

    The target is checked again just before (:func:`check_output` with ``force``): the store
    is never written, whatever links appeared meanwhile. A character device is written directly.
    """
    path = check_output(path, option=option, force=True, stores=stores)
    try:
        if path.exists() and stat.S_ISCHR(os.stat(path).st_mode):
            with open(path, "wb") as device:
                yield device
            return
        temporary = path.with_name(f".{path.name[:200]}.{os.getpid()}.tmp")
        fd = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_CLOEXEC", 0), 0o666)
    except OSError as exc:
        raise _write_error(path, option, exc) from None
    try:
        with os.fdopen(fd, "wb") as handle:
            yield handle
            handle.flush()
        os.replace(temporary, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        raise _write_error(path, option, exc) from None
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        raise


def write_output(path: Any, data: str | bytes, *, option: str | None = None, stores: Iterable[Any] = ()) -> Path:
    """Write ``data`` (text as UTF-8) to ``path`` atomically, never over a store; returns the path."""
    with atomic_output(path, option=option, stores=stores) as handle:
        handle.write(data.encode("utf-8") if isinstance(data, str) else data)
    return Path(path)


# ------------------------------------------------------------------ output folders


def check_output_folder(path: Any, *, option: str | None = None) -> Path:
    """Refuse, before any work, a folder a command will create and write files into; returns it as a Path.

    For the folders a command makes *inside* the folder the user named (``--export DIR``'s
    ``session-3/``): refused (:class:`ConfigError`) when it is a symbolic link — its files would
    land wherever the link points, outside the folder the user named — or exists and is not a
    folder. A missing folder is fine (:func:`make_output_folder` creates it).
    """
    path = _as_path(path, option)
    name = _named(path, option)
    try:
        info = os.lstat(path)
    except FileNotFoundError:
        return path
    except OSError as exc:
        raise ConfigError(f"{name}: {exc.strerror or exc}") from None
    if stat.S_ISLNK(info.st_mode):
        raise ConfigError(f"{name}: a symbolic link (to {os.readlink(path)}); a folder of its own is written "
                          f"there: remove the link or choose another folder")
    if not stat.S_ISDIR(info.st_mode):
        raise ConfigError(f"{name}: exists and is not a folder ({_kind(info.st_mode)}); a folder is written there")
    return path


def make_output_folder(path: Any, *, option: str | None = None) -> Path:
    """Create the folder ``path`` (and its parents) after :func:`check_output_folder`; returns it.

    :class:`DiskFull` when there is no room for it, :class:`OutputError` when it cannot be made.
    """
    path = check_output_folder(path, option=option)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:  # a file, or a dangling link, appeared meanwhile
        raise ConfigError(f"{_named(path, option)}: exists and is not a folder") from None
    except OSError as exc:
        raise _write_error(path, option, exc) from None
    return path


def folder_owner(store: Any, kind: str, number: int, started: str = "") -> str:
    """The owner marker's text: the store's absolute path, ``session 3`` or ``study 2``, and when it started."""
    # a name with bytes that are not UTF-8 is written with them escaped (the marker is UTF-8 text)
    where = os.fsencode(Path(os.fspath(store)).resolve()).decode("utf-8", "backslashreplace")
    return f"{where}\n{kind} {number}\n{started}\n"


def _marker(folder: Path) -> str | None:
    try:
        return read_input_text(folder / OWNER_FILE, limit=64 * 1024)
    except ConfigError:
        return None


def default_folder(store: Any, kind: str, number: int, started: str = "", *, root: str | Path = "out") -> Path:
    """``out/<store stem>-<hash of its absolute path>/<kind>-<number>``, unique per store and session or study.

    The first of ``…/session-3``, ``…/session-3-2``, … that does not exist or whose owner marker
    names this very session (same store, number and start time): a folder left by an earlier
    store at the same path, or by anything else, is never written into.
    """
    absolute = Path(os.fspath(store)).resolve()
    digest = hashlib.sha256(os.fsencode(absolute)).hexdigest()[:8]
    # the folder's name is UTF-8 text (the store records it): bytes that are not become "_", the digest keeps it unique
    stem = os.fsencode(absolute.stem[:40]).decode("utf-8", "replace").replace("\ufffd", "_")
    base = Path(root) / f"{stem}-{digest}" / f"{kind}-{number}"
    owner = folder_owner(store, kind, number, started)
    for k in range(1, 1000):
        candidate = base if k == 1 else base.with_name(f"{base.name}-{k}")
        if not os.path.lexists(candidate) or (candidate.is_dir() and _marker(candidate) == owner):
            return candidate
    raise OutputError(f"{base}: 999 folders of that name exist; remove some or give --out")


def claim_folder(folder: Any, owner: str, *, option: str = "--out", force: bool = False,
                 can_force: bool = False) -> Path:
    """Create ``folder`` (if needed) and mark it as ``owner``'s; refuse a folder another session or study owns.

    A folder marked for someone else is refused unless ``force``; a folder with no marker is
    taken (an ``--out`` the user chose) and marked.
    """
    path = _as_path(folder, option)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise ConfigError(f"{option} {path}: exists and is not a folder") from None
    except OSError as exc:
        raise OutputError(f"{option} {path}: cannot create the folder: {exc.strerror or exc}") from None
    current = _marker(path)
    if current is not None and current != owner and not force:
        who = " ".join(current.split("\n")[:2]) if current.count("\n") >= 2 else current.strip()[:200]
        raise ConfigError(f"{option} {path}: holds the output of {who}; choose another folder"
                          + (" or pass --force to write into it anyway" if can_force else ""))
    if current != owner:
        try:
            write_output(path / OWNER_FILE, owner)
        except ConfigError as exc:
            raise ConfigError(f"{option} {path}: cannot mark the folder: {exc}") from None
    return path
