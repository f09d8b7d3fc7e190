"""Figures as objects, files as the edge: new figures without pyplot, and saving with clear errors.

The library builds :class:`matplotlib.figure.Figure` objects directly, so it never
touches pyplot's global state and never chooses a backend; :func:`save_figure`
writes one to a file (the format from the extension).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["new_figure", "save_figure", "write_text"]


def new_figure(*, figsize: tuple[float, float] = (8.0, 5.0)) -> Any:
    """A figure with constrained layout, not registered with pyplot."""
    from matplotlib.figure import Figure

    return Figure(figsize=figsize, constrained_layout=True)


def save_figure(fig: Any, path: str | Path, *, dpi: int = 120) -> Path:
    """Write ``fig`` to ``path`` atomically, never over a store or through a link
    (:func:`aerobat.fileio.atomic_output`); :class:`~aerobat.errors.OutputError` (or ``DiskFull``) if that fails."""
    from aerobat.errors import OutputError
    from aerobat.fileio import atomic_output

    path = Path(path)
    kind = path.suffix.lower().lstrip(".")
    supported = fig.canvas.get_supported_filetypes()
    if kind and kind not in supported:  # matplotlib would raise a ValueError after the work is done
        raise OutputError(f"{path}: cannot write a figure as .{kind}; use one of "
                          f"{', '.join('.' + k for k in sorted(supported))}")
    with atomic_output(path) as handle:
        fig.savefig(handle, dpi=dpi, format=kind or "png")
    return path


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically, never over a store or through a link; :class:`~aerobat.errors.OutputError`
    (or ``DiskFull``) if that fails."""
    from aerobat.fileio import write_output

    return write_output(path, text)
