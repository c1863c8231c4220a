"""Response import: any supported export → one tidy long table plus an explicit exclusions table.

>>> from analysis.io_design import load_design                       # doctest: +SKIP
>>> from analysis.responses import import_responses                   # doctest: +SKIP
>>> result = import_responses("responses.csv", load_design("design")) # doctest: +SKIP
>>> result.n_rows == result.n_imported_rows + result.n_excluded_rows  # doctest: +SKIP
True

The tidy table has one row per answer: ``participant``, the factor columns, ``stimulus_id``,
``repetition``, ``trial`` (presentation order when known), the score (``rating`` for Likert;
``chosen`` and ``position`` for k-AFC; ``ranking`` = levels best first, ``a>b>c``, for rankings),
``rt`` (seconds, when known), ``practice`` and ``row`` (the record number in the file).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from analysis.io_design import DesignInfo
from analysis.responses.answers import TagIndex
from analysis.responses.qualtrics import qualtrics_answers
from analysis.responses.read import RawFile, read_response_file
from analysis.responses.tidy import assemble
from analysis.responses.trialwise import trialwise_answers

__all__ = ["ImportResult", "import_responses", "read_response_file"]


@dataclass
class ImportResult:
    """The tidy table, the exclusions and the counts that reconcile them with the file."""

    path: Path
    format: str
    data: pd.DataFrame
    exclusions: pd.DataFrame
    n_rows: int

    @property
    def n_imported_rows(self) -> int:
        return int(self.data["row"].nunique())

    @property
    def n_excluded_rows(self) -> int:
        return int(self.exclusions["row"].dropna().nunique())

    @property
    def reconciles(self) -> bool:
        return self.n_rows == self.n_imported_rows + self.n_excluded_rows

    def summary(self) -> dict:
        """Counts for reports: rows, imported, excluded by reason, participants kept."""
        rows = self.exclusions.dropna(subset=["row"])
        return {"file": str(self.path), "format": self.format, "rows": self.n_rows,
                "imported_rows": self.n_imported_rows, "excluded_rows": self.n_excluded_rows,
                "participants": int(self.data["participant"].nunique()),
                "answers": int((~self.data["practice"]).sum()),
                "excluded_by_reason": {str(k): int(v) for k, v in rows["reason"].value_counts().sort_index().items()},
                "columns_not_imported": self.exclusions.loc[self.exclusions["row"].isna(), "column"].tolist()}


def import_responses(path: str | Path, design: DesignInfo) -> ImportResult:
    """Read ``path`` (any supported format), map answers to the design's stimuli, apply the exclusions."""
    raw = read_response_file(path)
    tags = _tag_index(design)
    if raw.format.startswith("qualtrics"):
        answers, exclusions = qualtrics_answers(raw, tags, design.between, design.response_type == "ranking")
    else:
        answers, exclusions = trialwise_answers(raw, design.between)
    data, excluded = assemble(answers, exclusions, raw.row_numbers, design, trialwise=not raw.format.startswith("qualtrics"))
    return ImportResult(Path(path), raw.format, data, excluded, raw.n_rows)


def _tag_index(design: DesignInfo) -> TagIndex:
    """Stimulus ids, plus any ``export_tag`` column the survey exporter or manifest recorded."""
    extra = {}
    for table in (design.conditions, design.manifest):
        if table is not None and "export_tag" in table:
            extra.update(dict(zip(table["export_tag"].astype(str), table["stimulus_id"].astype(str))))
    return TagIndex(design.conditions["stimulus_id"], extra)
