"""Qualtrics CSV exports (current 3-header-row form and the legacy 2-row form) → answers + row exclusions.

One data row is one respondent. Columns are classified as metadata (StartDate … UserLanguage),
display-order ``*_DO`` columns (they give each participant's presentation order), timing columns,
questions (their export tag names a stimulus, optionally with a repetition suffix; rank-order questions
add ``_1`` … ``_k`` per screen position) and embedded data (anything else, e.g. ``PROLIFIC_PID``).
A question whose tag names no stimulus is listed as a column exclusion; two columns whose tags name the same
stimulus and repetition (``F-walk-Hi1_r1`` and ``f_walk_hi1_r1``) are refused, as one would replace the other.

One bad cell excludes that answer, not the respondent (``scope`` ``answer`` in the exclusions): the row's
other answers are imported unless the respondent then lacks a design cell (see :mod:`analysis.responses.tidy`).

Attention-check questions (export tags ``attention_check_1``, … that the QSF/TXT export writes) are not
answers: :func:`qualtrics_attention` reads them into the same per-participant report as jsPsych's checks
(:mod:`analysis.responses.attention`).

A forced-choice value is an answer option of the survey (``scoring.CHOICE``): a number is the option's 1-based
screen position (the numeric export's recode), text the option's label (a position label, ``Left``/``Right``) —
never a level name that happens to look like a number (see :mod:`analysis.responses.scoring`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from analysis.errors import AnalysisError
from analysis.responses.answers import Answer, Exclusion, TagIndex
from analysis.responses.attention import attention_report
from analysis.responses.read import QUALTRICS_METADATA, RawFile, _participant_column, shown
from analysis.responses.scoring import CHOICE, LABEL

TIMING = re.compile(r"_(First Click|Last Click|Page Submit|Click Count)$", re.IGNORECASE)
RANK_POSITION = re.compile(r"^(?P<base>.+)_(?P<pos>\d+)$")
# export tag of an attention-check question (stimuli/survey/checks.py CHECK_TAG)
ATTENTION_TAG = re.compile(r"^attention_check_\d+$", re.IGNORECASE)
UNFINISHED = {"0", "false", "no"}
# Qualtrics Status codes that are not real respondents (numeric export / choice-text export).
NOT_REAL = {"1", "2", "8", "9", "12", "17", "survey preview", "survey test", "spam", "preview spam",
            "imported spam", "offline survey preview"}


@dataclass
class QualtricsColumns:
    """Which column is what, with the stimulus a question column answers."""

    questions: dict[int, tuple[str, int | None, int | None]] = field(default_factory=dict)  # i → (sid, rep, pos)
    display_order: list[int] = field(default_factory=list)
    metadata: list[int] = field(default_factory=list)
    embedded: list[int] = field(default_factory=list)
    timing: list[int] = field(default_factory=list)
    unknown: list[int] = field(default_factory=list)
    attention: list[int] = field(default_factory=list)


def classify_columns(raw: RawFile, tags: TagIndex | None, ranking: bool = False) -> QualtricsColumns:
    """Sort the export's columns; ``tags`` None only classifies (for ``responses inspect``)."""
    out = QualtricsColumns()
    for i, name in enumerate(raw.columns):
        import_id = str(raw.import_ids[i].get("ImportId", "")) if i < len(raw.import_ids) else ""
        if name in QUALTRICS_METADATA or (import_id and import_id[0].islower() and import_id != name):
            out.metadata.append(i)
        elif name.endswith("_DO"):
            out.display_order.append(i)
        elif TIMING.search(name):
            out.timing.append(i)
        elif ATTENTION_TAG.match(name):
            out.attention.append(i)
        elif tags is not None and (hit := _match(name, tags, ranking)):
            out.questions[i] = hit
        elif import_id.startswith("QID") or (raw.format == "qualtrics-legacy" and re.match(r"^Q\d", name)):
            out.unknown.append(i)
        else:
            out.embedded.append(i)
    return out


def _match(name: str, tags: TagIndex, ranking: bool) -> tuple[str, int | None, int | None] | None:
    try:
        return _match_tag(name, tags, ranking)
    except AnalysisError as exc:   # several stimuli fit the tag
        raise AnalysisError(f"column {shown(name)}: {exc}") from None


def _match_tag(name: str, tags: TagIndex, ranking: bool) -> tuple[str, int | None, int | None] | None:
    if ranking:
        m = RANK_POSITION.match(name)
        hit = tags.match(m["base"]) if m else None
        return (hit[0], hit[1], int(m["pos"])) if hit else None
    hit = tags.match(name)
    return (hit[0], hit[1], None) if hit else None


def check_one_column_per_answer(raw: RawFile, cols: QualtricsColumns) -> None:
    """Refuse two question columns that state the same stimulus and repetition (and rank position): the
    answers of one would silently stand for the other's."""
    first: dict[tuple, int] = {}
    for i, (sid, rep, pos) in cols.questions.items():
        if rep is None and pos is None:
            continue   # unnumbered showings of one stimulus are numbered in presentation order
        other = first.setdefault((sid, rep, pos), i)
        if other != i:
            what = f"repetition {rep} of stimulus {sid!r}" if rep is not None else f"stimulus {sid!r}"
            where = f" at rank position {pos}" if pos is not None else ""
            names = f"{shown(raw.columns[other])} and {shown(raw.columns[i])}"
            raise AnalysisError(f"columns {other + 1} and {i + 1} ({names}) "
                                f"both answer {what}{where} (their tags differ only in case or punctuation); "
                                f"rename or remove one of them")


def stimulus_columns(raw: RawFile, cols: QualtricsColumns) -> dict[str, list[str]]:
    """Stimulus id → the question columns that answer it (rank-order columns by their question's tag), so that
    an exclusion for a missing design cell can name where its answers would be."""
    out: dict[str, list[str]] = {}
    for i, (sid, _, pos) in cols.questions.items():
        name = raw.columns[i].rsplit("_", 1)[0] if pos is not None else raw.columns[i]
        if name not in out.setdefault(sid, []):
            out[sid].append(name)
    return out


def qualtrics_answers(raw: RawFile, tags: TagIndex, between: list[str], ranking: bool = False):
    """Answers, row exclusions and :func:`stimulus_columns` of a Qualtrics export (one row per respondent)."""
    cols = classify_columns(raw, tags, ranking)
    check_one_column_per_answer(raw, cols)
    exclusions = [Exclusion(None, "", "unknown export tag",
                            f"question {shown(raw.columns[i])} ({_text(raw, i)}) names no stimulus of the design; "
                            f"column not imported", raw.columns[i]) for i in cols.unknown]
    exclusions += [Exclusion(None, "", "attention check", f"question {shown(raw.columns[i])} is an attention check: "
                             f"scored in the attention report, not imported as an answer", raw.columns[i])
                   for i in cols.attention]
    group_cols = {name: _find(raw.columns, name) for name in between}
    reading = _reading(raw)
    answers: list[Answer] = []
    for row, record, pid, reason in _respondents(raw):
        if reason:
            exclusions.append(Exclusion(row, pid, *reason))
            continue
        groups = {n: record[i].strip() for n, i in group_cols.items() if i is not None and record[i].strip()}
        answers += _row_answers(raw, record, row, pid, cols, groups, reading)
    return answers, exclusions, stimulus_columns(raw, cols)


def _respondents(raw: RawFile):
    """(row number, record, participant id, why the row is excluded or None) for every data row."""
    pid_col = _id_column(raw)
    finished = _find(raw.columns, "Finished")
    status = _find(raw.columns, "Status")
    seen: dict[str, int] = {}
    for row, record in zip(raw.row_numbers, raw.rows):
        pid = record[pid_col].strip() if pid_col is not None and pid_col < len(record) else ""
        pid = pid or f"row{row}"
        reason = _row_problem(raw, record, finished, status)
        if reason is None and pid in seen:
            reason = ("duplicate participant id", f"{pid!r} already imported from row {seen[pid]}")
        if reason is None:
            seen[pid] = row
        yield row, record, pid, reason


def _reading(raw: RawFile) -> str:
    """LABEL for a choice-text export, CHOICE for a numeric one (see :func:`_choice_text`)."""
    return LABEL if _choice_text(raw, _find(raw.columns, "Finished"), _find(raw.columns, "Status")) else CHOICE


def qualtrics_attention(raw: RawFile, asked: str, labels: list[str]):
    """The attention report (:func:`analysis.responses.attention.attention_report`) of the export's
    ``attention_check_<k>`` columns, or None when it has none. ``asked``: the protocol's
    ``attention_checks.answer``; ``labels``: the answer buttons, which a numeric export's value (the
    choice's recode, 1…k) indexes. Only the respondents the import keeps are counted; a blank cell is
    a check the respondent was not shown (another group's, another rotation's).

    >>> from analysis.responses.read import RawFile
    >>> raw = RawFile("x.csv", "qualtrics", ["ResponseId", "Finished", "attention_check_1"],
    ...               rows=[["R_1", "1", "2"], ["R_2", "1", "3"]], row_numbers=[4, 5])
    >>> qualtrics_attention(raw, "Medium", ["Light", "Medium", "Heavy"]).to_dict("records")
    [{'participant': 'R_1', 'checks': 1, 'failed': 0}, {'participant': 'R_2', 'checks': 1, 'failed': 1}]
    """
    columns = [i for i, name in enumerate(raw.columns) if ATTENTION_TAG.match(name)]
    if not columns:
        return None
    numeric = _reading(raw) == CHOICE
    records, pids = [], []
    for _, record, pid, reason in _respondents(raw):
        for value in (record[i].strip() for i in columns if not reason and i < len(record)):
            if value:
                records.append({"attention_check": "1", "attention_answer": asked,
                                "response_label": _button(value, labels, numeric)})
                pids.append(pid)
    return attention_report(records, pids)


def _button(value: str, labels: list[str], numeric: bool) -> str:
    """The label of the button a check's cell names: a numeric export's recode 1…k indexes ``labels``;
    a choice-text export (or a number outside 1…k, which then matches no button) is the text itself."""
    if numeric and value.isdigit() and 1 <= int(value) <= len(labels):
        return labels[int(value) - 1]
    return value


def _choice_text(raw: RawFile, finished: int | None, status: int | None) -> bool:
    """Whether the export holds choice text rather than numeric values: Qualtrics writes ``Finished`` as
    True/False and ``Status`` as "IP Address"… in a choice-text export, as 1/0 and codes in a numeric one."""
    for record in raw.rows:
        for i, text_values in ((finished, ("true", "false")), (status, None)):
            cell = record[i].strip().lower() if i is not None and i < len(record) else ""
            if cell and (cell in text_values if text_values else not cell.isdigit()):
                return True
    return False


def _row_problem(raw: RawFile, record: list[str], finished: int | None, status: int | None):
    if len(record) != len(raw.columns):
        return "malformed row", f"{len(record)} fields, the header has {len(raw.columns)} (corrupted export?)"
    if status is not None and record[status].strip().lower() in NOT_REAL:
        return "survey preview or test", f"Status = {record[status]!r}"
    if finished is not None and record[finished].strip().lower() in UNFINISHED:
        progress = _find(raw.columns, "Progress")
        extra = f", Progress = {record[progress]}%" if progress is not None else ""
        return "unfinished", f"Finished = {record[finished]}{extra}"
    return None


def _row_answers(raw, record, row, pid, cols: QualtricsColumns, groups, reading: str) -> list[Answer]:
    order = _display_order(raw, record, cols)
    answers: dict[tuple[str, int | None], Answer] = {}
    for i, (sid, rep, pos) in cols.questions.items():
        value = record[i].strip()
        if not value:
            continue
        names = (raw.columns[i], str(raw.import_ids[i].get("ImportId", "")))
        if pos is not None:   # a rank-order column (<tag>_<k>, QID_<k>): the _DO list names the question
            names = tuple(name.rsplit("_", 1)[0] for name in names)
        trial = order.get(names[0].lower()) or order.get(names[1].lower())
        if pos is None:
            answers[(raw.columns[i], None)] = Answer(row, pid, sid, value, raw.columns[i], rep, trial, groups=groups,
                                                     reading=reading)
            continue
        base = raw.columns[i].rsplit("_", 1)[0]
        answer = answers.setdefault((base, rep), Answer(row, pid, sid, "", base, rep, trial, ranks=[], groups=groups,
                                                        reading=reading))
        answer.ranks.extend([""] * (pos - len(answer.ranks)))
        answer.ranks[pos - 1] = value
    return list(answers.values())


def _display_order(raw: RawFile, record: list[str], cols: QualtricsColumns) -> dict[str, int]:
    """Tag (or QID) → 1-based position in the participant's presentation order, from the ``*_DO`` columns.

    Block-level ``FL_*_DO`` columns list blocks; question-level ``<block>_DO`` columns list questions.
    Blocks are taken in the order the flow shows them, so trial numbers run across blocks.
    """
    lists = {raw.columns[i][:-3]: [x.strip() for x in record[i].split("|") if x.strip()]
             for i in cols.display_order if i < len(record)}
    flow = [name for key, items in lists.items() if key.startswith("FL_") for name in items]
    blocks = [b for b in flow if b in lists] + [b for b in lists if b not in flow and not b.startswith("FL_")]
    order: dict[str, int] = {}
    for block in blocks:
        for item in lists[block]:
            order.setdefault(item.lower(), len(order) + 1)
    return order


def _id_column(raw: RawFile) -> int | None:
    name = _participant_column(raw.columns) or next((c for c in ("ResponseId", "ResponseID") if c in raw.columns),
                                                    None)
    return raw.columns.index(name) if name else None


def _find(columns: list[str], name: str) -> int | None:
    return columns.index(name) if name in columns else None


def _text(raw: RawFile, i: int) -> str:
    text = raw.question_text[i] if i < len(raw.question_text) else ""
    return repr(text[:60]) if text else "no question text"
