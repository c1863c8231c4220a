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

The exclusions table has one row per excluded row (``scope`` "row": a Qualtrics respondent, a jsPsych or
long-format answer), per answer excluded from a row that is otherwise imported (``scope`` "answer": one bad
cell of a Qualtrics export), per column not imported (``scope`` "column") and per file of a folder not read
(``scope`` "file"). Rows reconcile: ``rows = imported rows + excluded rows``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from analysis.errors import AnalysisError
from analysis.io_design import DesignInfo
from analysis.responses.answers import ANSWER, FILE, ROW, TagIndex
from analysis.responses.qualtrics import qualtrics_answers, qualtrics_attention
from analysis.responses.read import RawFile, folder_entries, read_response_file, response_files, shown
from analysis.responses.tidy import assemble
from analysis.responses.trialwise import records_and_ids, trialwise_answers
from analysis.responses.attention import answer_buttons, attention_report, exclude_inattentive

__all__ = ["ImportResult", "import_responses", "read_response_file"]

# exclusions.csv reason of a folder entry that is not read (hidden file, other file, subfolder); row is empty
FILE_NOT_READ = "file not read"


@dataclass
class ImportResult:
    """The tidy table, the exclusions and the counts that reconcile them with the file."""

    path: Path
    format: str
    data: pd.DataFrame
    exclusions: pd.DataFrame
    n_rows: int
    attention: pd.DataFrame | None = None   # attention checks per participant (attention.py), if any

    @property
    def n_imported_rows(self) -> int:
        return len(_row_keys(self.data))

    @property
    def excluded_rows(self) -> pd.DataFrame:
        """The exclusions of whole rows (not of single answers, columns or files)."""
        return self.exclusions[self.exclusions["scope"] == ROW].dropna(subset=["row"])

    @property
    def excluded_answers(self) -> pd.DataFrame:
        """The answers excluded one by one (Qualtrics: a bad cell), the rest of their row imported."""
        return self.exclusions[self.exclusions["scope"] == ANSWER]

    @property
    def n_excluded_rows(self) -> int:
        return len(_row_keys(self.excluded_rows))

    @property
    def reconciles(self) -> bool:
        """Every row of the file is imported or excluded, never both, and every answer excluded on its own
        belongs to a row of the file."""
        imported, excluded = _row_keys(self.data), _row_keys(self.excluded_rows)
        return (self.n_rows == len(imported) + len(excluded) and not imported & excluded
                and _row_keys(self.excluded_answers) <= imported | excluded)

    def summary(self) -> dict:
        """Counts for reports: rows, imported, excluded by reason, answers excluded one by one, participants."""
        rows, answers = self.excluded_rows, self.excluded_answers
        return {"file": str(self.path), "format": self.format, "rows": self.n_rows,
                "imported_rows": self.n_imported_rows, "excluded_rows": self.n_excluded_rows,
                "participants": int(self.data["participant"].nunique()),
                "answers": int((~self.data["practice"]).sum()),
                "excluded_by_reason": _counts(rows["reason"]),
                "excluded_answers": len(answers),
                "answers_excluded_by_reason": _counts(answers["reason"]),
                "columns_not_imported": self.exclusions.loc[self.exclusions["row"].isna()
                                                            & (self.exclusions["reason"] != FILE_NOT_READ),
                                                            "column"].tolist(),
                "files_not_read": [{"name": f, "reason": d} for f, d in
                                   self.exclusions.loc[self.exclusions["reason"] == FILE_NOT_READ,
                                                       ["file", "detail"]].itertuples(index=False)]
                if "file" in self.exclusions else []} | self._attention_summary()

    def _attention_summary(self) -> dict:
        """``attention_checks``: per participant with checks, how many were shown and failed (only when any)."""
        if self.attention is None or self.attention.empty:
            return {}
        return {"attention_checks": [{"participant": str(p), "checks": int(n), "failed": int(f)}
                                     for p, n, f in self.attention[["participant", "checks", "failed"]]
                                     .itertuples(index=False)]}


def _counts(reasons: pd.Series) -> dict:
    return {str(k): int(v) for k, v in reasons.value_counts().sort_index().items()}


def _row_keys(frame: pd.DataFrame) -> set:
    """Distinct file rows of a table: ``row``, or (``file``, ``row``) for a folder of files."""
    columns = ["file", "row"] if "file" in frame else ["row"]
    return set(frame[columns].itertuples(index=False, name=None))


def import_responses(path: str | Path, design: DesignInfo) -> ImportResult:
    """Read ``path`` (any supported format, or a folder of such files, e.g. one jsPsych CSV per participant),
    map answers to the design's stimuli, apply the exclusions."""
    if Path(path).is_dir():
        return import_folder(Path(path), design)
    raw = read_response_file(path)
    check_protocol(raw, design)
    tags = _tag_index(design)
    attention = None
    try:   # the readers and checks name row and column; the file is known here
        if raw.format.startswith("qualtrics"):
            answers, exclusions, columns = qualtrics_answers(raw, tags, design.between,
                                                             design.response_type == "ranking")
            checks = design.protocol.get("attention_checks")
            if checks:
                attention = qualtrics_attention(raw, str(checks.get("answer", "")), answer_buttons(design))
        else:
            (answers, exclusions), columns = trialwise_answers(raw, design.between, design.within), None
            if raw.format.startswith("jspsych"):
                attention = attention_report(*records_and_ids(raw))
        if attention is not None:
            rule = (design.protocol.get("attention_checks") or {}).get("exclude_if_failed")
            answers, inattentive = exclude_inattentive(answers, attention, rule)
            exclusions = exclusions + inattentive
        data, excluded = assemble(answers, exclusions, raw.row_numbers, design,
                                  trialwise=not raw.format.startswith("qualtrics"), stimulus_columns=columns)
    except AnalysisError as exc:
        raise AnalysisError(f"{path}: {exc}") from None
    return ImportResult(Path(path), raw.format, data, excluded, raw.n_rows, attention)


def protocol_columns(raw: RawFile) -> list[str]:
    """Columns in which the survey exports record the protocol's name: the Qualtrics embedded field
    ``shapemotion_protocol``; jsPsych's ``protocol`` data property."""
    names = ["shapemotion_protocol"] + (["protocol"] if raw.format.startswith("jspsych") else [])
    return [n for n in names if n in raw.columns]


def check_protocol(raw: RawFile, design: DesignInfo) -> None:
    """Refuse an export whose recorded protocol is not the design's: every answer would be excluded (or,
    worse, matched to the wrong stimuli) instead of naming the real cause."""
    expected = str(design.protocol.get("name") or "")
    if not expected:
        return
    for column in protocol_columns(raw):
        for number, record in zip(raw.row_numbers, raw.rows):
            value = record.get(column) if isinstance(record, dict) else \
                (record[raw.columns.index(column)] if raw.columns.index(column) < len(record) else "")
            value = str(value if value is not None else "").strip()
            if value and value != expected:
                raise AnalysisError(
                    f"{raw.path}: row {number}: column {column!r} says the responses are from protocol {shown(value)}, "
                    f"but the design {design.directory} is {expected!r}; analyse them against the design of "
                    f"{shown(value)}")


def _tag_index(design: DesignInfo) -> TagIndex:
    """Stimulus ids, plus any ``export_tag`` column the survey exporter or manifest recorded."""
    extra = {}
    for table in (design.conditions, design.manifest):
        if table is not None and "export_tag" in table:
            extra.update(dict(zip(table["export_tag"].astype(str), table["stimulus_id"].astype(str))))
    return TagIndex(design.conditions["stimulus_id"], extra)


def import_folder(folder: Path, design: DesignInfo) -> ImportResult:
    """Import every ``*.csv``/``*.json`` file of a folder; tables gain a ``file`` column.

    A participant found in several files is kept from the first file (in name order); the later files'
    rows of that participant are excluded as duplicates.
    """
    results = [import_responses(f, design) for f in response_files(folder)]
    data = pd.concat([r.data.assign(file=r.path.name) for r in results], ignore_index=True)
    exclusions = pd.concat([r.exclusions.assign(file=r.path.name) for r in results], ignore_index=True)
    owner = data.drop_duplicates("participant")[["participant", "file"]].set_index("participant")["file"]
    later = data["file"] != data["participant"].map(owner)
    moved = data[later].drop_duplicates(["file", "row"])
    extra = pd.DataFrame({"row": moved["row"], "participant": moved["participant"],
                          "reason": "duplicate participant id",
                          "detail": [f"{p!r} already imported from {owner[p]}" for p in moved["participant"]],
                          "column": "", "scope": ROW, "file": moved["file"]})
    # what the folder holds besides the response files: listed, as nothing is dropped silently
    skipped = pd.DataFrame([{"row": None, "participant": "", "reason": FILE_NOT_READ, "detail": s["reason"],
                             "column": "", "scope": FILE, "file": s["name"]} for s in folder_entries(folder)[1]],
                           columns=["row", "participant", "reason", "detail", "column", "scope", "file"])
    exclusions = pd.concat([exclusions, extra, skipped], ignore_index=True).astype({"row": "Int64"})
    formats = "+".join(sorted({r.format for r in results}))
    checks = [r.attention for r in results if r.attention is not None]
    return ImportResult(folder, formats, data[~later].reset_index(drop=True), exclusions,
                        sum(r.n_rows for r in results), pd.concat(checks, ignore_index=True) if checks else None)
