"""The records every reader produces: one :class:`Answer` per question answered, one :class:`Exclusion` per row
(or, in a Qualtrics export, answer) left out.

Readers turn their format into these; :mod:`analysis.responses.tidy` scores and checks them the same way
whatever the source, so every format gets the same exclusion rules.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from analysis.errors import AnalysisError
from analysis.responses.read import shown
from analysis.responses.scoring import CHOICE


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
    reading: str = CHOICE          # what a choice value means (scoring.CHOICE: survey option; LEVEL: level name)
    restated: dict[str, str] = field(default_factory=dict)  # the file's own restatement of the score (checked)


# What an exclusion leaves out (the ``scope`` column of exclusions.csv).
ROW = "row"          # the whole record of the file (a Qualtrics respondent; one jsPsych/long answer)
ANSWER = "answer"    # one answer (cell) of a record whose other answers are imported (Qualtrics)
COLUMN = "column"    # a column that is not imported (``row`` empty)
FILE = "file"        # a file of a folder that is not read (``row`` empty)


@dataclass
class Exclusion:
    """A row, an answer of a row (``scope`` ANSWER) or, with ``row`` None, a column that is not imported, and why."""

    row: int | None
    participant: str
    reason: str
    detail: str = ""
    column: str = ""
    scope: str = ROW


def _key(text: str) -> str:
    """Tags compare case-insensitively with any punctuation as '_' (Qualtrics tags cannot hold every character)."""
    return re.sub(r"[^0-9a-z]+", "_", text.lower()).strip("_")


def _safe(text: str) -> str:
    """The survey exporter's form of a stimulus id as a Qualtrics export tag (characters other than letters,
    digits, ``_``, ``-`` and ``.`` become ``_``)."""
    return "".join(c if c.isalnum() or c in "_-." else "_" for c in text)


REPETITION_SUFFIX = re.compile(r"^(?P<base>.+?)(?:[_.#-]+(?:r|rep)?(?P<rep>\d+))$", re.IGNORECASE)


class TagIndex:
    """Map question export tags / stimulus columns to ``(stimulus_id, repetition)``.

    A tag is the stimulus id itself (or its export-tag form), optionally followed by a repetition suffix
    (``_r2``, ``_rep2``, ``_2``, ``#2``). A tag that is exactly a stimulus id (or an ``export_tag`` of the
    manifest) names that stimulus; otherwise punctuation and case are ignored — as long as that leaves one
    stimulus: a tag that then fits several (``X_Y-Z`` and ``X-Y_Z`` are both ``x_y_z``) is an error naming
    them, never a silent pick.

    >>> idx = TagIndex(["F-walk-Hi1-Lo2", "F-walk-Hi1-Lo1"])
    >>> idx.match("F-walk-Hi1-Lo2"), idx.match("F_walk_Hi1_Lo2_r2"), idx.match("Q99")
    (('F-walk-Hi1-Lo2', None), ('F-walk-Hi1-Lo2', 2), None)
    >>> TagIndex(["X_Y-Z", "X-Y_Z"]).match("X-Y_Z")
    ('X-Y_Z', None)
    """

    def __init__(self, stimulus_ids, extra: dict[str, str] | None = None):
        self._exact: dict[str, set[str]] = {}   # tag as written (the id, its export form, a manifest tag) → ids
        self._loose: dict[str, set[str]] = {}   # case and punctuation ignored → ids
        pairs = [(str(s), str(s)) for s in stimulus_ids] + [(str(t), str(s)) for t, s in (extra or {}).items()]
        for tag, sid in pairs:
            for form in {tag, _safe(tag)}:
                self._exact.setdefault(form, set()).add(sid)
            self._loose.setdefault(_key(tag), set()).add(sid)

    def _lookup(self, tag: str, exact: bool) -> str | None:
        index, key, how = ((self._exact, tag, "exactly") if exact else
                           (self._loose, _key(tag), "when case and punctuation are ignored"))
        found = index.get(key, set())
        if len(found) > 1:
            raise AnalysisError(
                f"export tag {shown(tag)} names {len(found)} stimuli of the design {how}: "
                f"{' and '.join(repr(s) for s in sorted(found))}; their ids differ only in case or punctuation, so "
                f"the column cannot be matched to one of them — rename the question to the exact stimulus id, or "
                f"give the stimuli ids that differ in letters or digits (or an export_tag column in manifest.csv)")
        return next(iter(found), None)

    def match(self, tag: str) -> tuple[str, int | None] | None:
        hit = self._lookup(tag, exact=True)
        if hit is not None:
            return hit, None
        m = REPETITION_SUFFIX.match(tag.strip())
        base = None
        if m:
            base = self._lookup(m["base"], exact=True) or self._lookup(m["base"], exact=False)
        loose = self._lookup(tag, exact=False)
        if loose is not None and base is not None and loose != base:
            raise AnalysisError(
                f"export tag {shown(tag)} could be stimulus {loose!r} (case and punctuation ignored) or repetition "
                f"{m['rep']} of stimulus {base!r}; rename the question to the exact stimulus id (repetitions: "
                f"<stimulus id>_r<k>)")
        if loose is not None:
            return loose, None
        return (base, int(m["rep"])) if base is not None else None
