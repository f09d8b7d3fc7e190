"""Figures: every function returns a matplotlib figure (drawn on ``ax=`` where one is given).

The library never chooses a matplotlib backend and never uses pyplot; the command
line saves figures with :func:`save_figure`. Matplotlib is imported only when a
figure is drawn.
"""

from aerobat.plotting.files import new_figure, save_figure, write_text

__all__ = ["new_figure", "save_figure", "write_text"]
