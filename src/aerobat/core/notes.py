"""What learning noted about one trial beyond its status: parameters held or pinned at a bound.

An :class:`~aerobat.core.learning.Iteration` carries its notes as :class:`IterationNote`
values — a :class:`NoteKind`, the parameter concerned and the words — and its ``message``
says the same in one line for people (:func:`message_with_notes`), so nothing has to read
the notes back out of the text.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum

__all__ = ["IterationNote", "NoteKind", "message_with_notes"]

HELD_PREFIX = "; held at a bound: "
"""How a message lists the parameters held at a bound (after the plant's own message)."""
WARNING_PREFIX = "; warning: "
"""How a message adds each warning."""


class NoteKind(StrEnum):
    """What a note says about a trial's correction."""

    HELD_AT_BOUND = "held_at_bound"
    PINNED_AT_BOUND = "pinned_at_bound"

    @property
    def warning(self) -> bool:
        """The note asks a person to look (a maneuver poorly formulated or infeasible here)."""
        return self is NoteKind.PINNED_AT_BOUND


@dataclass(frozen=True)
class IterationNote:
    """One note on a trial's correction.

    Attributes
    ----------
    kind : :class:`NoteKind`.
    parameter : name of the parameter concerned.
    text : the note in words (a warning's whole sentence; ``held at a bound`` for a held parameter).
    """

    kind: NoteKind
    parameter: str
    text: str

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", NoteKind(self.kind))

    @classmethod
    def held(cls, parameter: str) -> IterationNote:
        """``parameter`` sat at a bound, pushed further out: held while the others were corrected."""
        return cls(NoteKind.HELD_AT_BOUND, parameter, "held at a bound")


def message_with_notes(message: str, notes: Sequence[IterationNote]) -> str:
    """``message`` followed by the notes in words: the held parameters in one clause, then each warning."""
    held = [note.parameter for note in notes if note.kind is NoteKind.HELD_AT_BOUND]
    text = message + (HELD_PREFIX + ", ".join(held) if held else "")
    return text + "".join(WARNING_PREFIX + note.text for note in notes if note.kind.warning)
