"""The records every reader produces: one :class:`Answer` per question answered, one :class:`Exclusion` per row left out.

Readers turn their format into these; :mod:`analysis.responses.tidy` scores and checks them the same way
whatever the source, so every format gets the same exclusion rules.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field


@dataclass
class Answer:
    """One answer to one stimulus. ``value`` is the raw text; ``ranks`` the rank per screen position."""

    row: int                       # 1-based record number in the file (header rows included)
    participant: str
    stimulus_id: str
    value: str
    column: str = "response"
    repetition: int | None = None
    trial: int | None = None
    rt: float | None = None
    ranks: list[str] | None = None
    groups: dict[str, str] = field(default_factory=dict)   # between levels the file declares
    declared: dict[str, str] = field(default_factory=dict)  # other factor levels the file states (checked)
    numbered: bool = False         # repetition counted by the importer, not stated in the file


@dataclass
class Exclusion:
    """A row (or, with ``row`` None, a column) that is not imported, and why."""

    row: int | None
    participant: str
    reason: str
    detail: str = ""
    column: str = ""


def _key(text: str) -> str:
    """Tags compare case-insensitively with any punctuation as '_' (Qualtrics tags cannot hold every character)."""
    return re.sub(r"[^0-9a-z]+", "_", text.lower()).strip("_")


REPETITION_SUFFIX = re.compile(r"^(?P<base>.+?)(?:[_.#-]+(?:r|rep)?(?P<rep>\d+))$", re.IGNORECASE)


class TagIndex:
    """Map question export tags / stimulus columns to ``(stimulus_id, repetition)``.

    A tag is the stimulus id itself, optionally followed by a repetition suffix (``_r2``, ``_rep2``,
    ``_2``, ``#2``). Punctuation and case are ignored.

    >>> idx = TagIndex(["F-walk-Hi1-Lo2", "F-walk-Hi1-Lo1"])
    >>> idx.match("F-walk-Hi1-Lo2"), idx.match("F_walk_Hi1_Lo2_r2"), idx.match("Q99")
    (('F-walk-Hi1-Lo2', None), ('F-walk-Hi1-Lo2', 2), None)
    """

    def __init__(self, stimulus_ids, extra: dict[str, str] | None = None):
        self._index = {_key(s): s for s in stimulus_ids}
        for tag, sid in (extra or {}).items():
            self._index[_key(tag)] = sid

    def match(self, tag: str) -> tuple[str, int | None] | None:
        key = _key(tag)
        if key in self._index:
            return self._index[key], None
        m = REPETITION_SUFFIX.match(tag.strip())
        if m and _key(m["base"]) in self._index:
            return self._index[_key(m["base"])], int(m["rep"])
        return None
