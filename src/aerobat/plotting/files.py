"""Figures as objects, files as the edge: new figures without pyplot, and saving with clear errors.

The library builds :class:`matplotlib.figure.Figure` objects directly, so it never
touches pyplot's global state and never chooses a backend; :func:`save_figure`
writes one to a file (the format from the extension).
"""

from __future__ import annotations

import errno
from pathlib import Path
from typing import Any

__all__ = ["new_figure", "save_figure", "write_text"]

_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


def new_figure(*, figsize: tuple[float, float] = (8.0, 5.0)) -> Any:
    """A figure with constrained layout, not registered with pyplot."""
    from matplotlib.figure import Figure

    return Figure(figsize=figsize, constrained_layout=True)


def _output_error(path: Path, exc: OSError) -> Exception:
    from aerobat.errors import DiskFull, OutputError

    reason = exc.strerror or str(exc)
    if exc.errno in _FULL:
        return DiskFull(f"{path}: cannot write: the disk is full or a file size limit was reached ({reason})")
    return OutputError(f"{path}: cannot write: {reason}")


def save_figure(fig: Any, path: str | Path, *, dpi: int = 120) -> Path:
    """Write ``fig`` to ``path``; :class:`~aerobat.errors.OutputError` (or ``DiskFull``) if that fails."""
    from aerobat.errors import OutputError

    path = Path(path)
    kind = path.suffix.lower().lstrip(".")
    supported = fig.canvas.get_supported_filetypes()
    if kind and kind not in supported:  # matplotlib would raise a ValueError after the work is done
        raise OutputError(f"{path}: cannot write a figure as .{kind}; use one of "
                          f"{', '.join('.' + k for k in sorted(supported))}")
    try:
        fig.savefig(path, dpi=dpi)
    except OSError as exc:
        raise _output_error(path, exc) from None
    return path


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path``; :class:`~aerobat.errors.OutputError` (or ``DiskFull``) if that fails."""
    path = Path(path)
    try:
        path.write_text(text)
    except OSError as exc:
        raise _output_error(path, exc) from None
    return path
