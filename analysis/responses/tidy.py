"""Score answers, apply the exclusion rules, and build the tidy long table.

Rules, in order (each excluded row is listed once, with the first reason that applies):
1. the reader's own (malformed row, unfinished, preview/test, not a stimulus trial, duplicate participant id);
2. answers to stimuli the design does not know (long formats: that row);
3. duplicate answers (same participant, stimulus and repetition) and repetitions outside the design's 1…n;
4. answers outside the response scale;
5. participants whose answers span several between-subject groups;
6. participants with missing cells (a design cell without any valid answer): all their rows.
Rules 2–4 are faults of one answer: in a one-answer-per-row format (jsPsych, long) that row is excluded; in a
Qualtrics export (one respondent per row) only that answer is (``scope`` "answer"), the respondent's other
answers are imported — unless rule 6 then applies. A Qualtrics column whose tag states a repetition the design
lacks is a fault of the column, not of its answers: it is listed once and not imported (like a tag that names no
stimulus). Rows with no answer at all are listed as "no answers",
rows whose every answer was excluded one by one as "no valid answers".
``imported rows + excluded rows = rows in the file``; in an imported row, each answer is imported or listed.
A factor level a row states that contradicts its stimulus's level in conditions.csv is an error, not an
exclusion: the file and the design disagree about what was shown.
"""

from __future__ import annotations

from collections import Counter, defaultdict

import pandas as pd

from analysis.errors import AnalysisError
from analysis.io_design import DesignInfo
from analysis.responses.answers import ANSWER, COLUMN, ROW, Answer, Exclusion
from analysis.responses.read import shown
from analysis.responses.scoring import OutsideScale, score_choice, score_likert, score_ranking

EXCLUSION_COLUMNS = ["row", "participant", "reason", "detail", "column", "scope"]


def assemble(answers: list[Answer], exclusions: list[Exclusion], rows: list[int], design: DesignInfo,
             trialwise: bool, stimulus_columns: dict[str, list[str]] | None = None
             ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(tidy table, exclusions table) from a reader's answers and exclusions.

    ``trialwise``: one answer per row (jsPsych, long), so a fault of the answer excludes its row; otherwise
    (Qualtrics) it excludes that answer alone. ``stimulus_columns`` (stimulus id → the columns answering it)
    lets a missing-cell exclusion name the columns where the cell's answers would be.
    """
    excluded: dict[int, Exclusion] = {e.row: e for e in exclusions if e.row is not None}
    column_notes = [e for e in exclusions if e.row is None]
    answer_drops: dict[int, tuple[Answer, Exclusion]] = {}   # id(answer) → (answer, why it alone is left out)
    stimuli = design.stimulus_table()

    def drop(answer: Answer, reason: str, detail: str, column: str | None = None) -> None:
        """Exclude the answer's whole row (in a Qualtrics export: the respondent)."""
        excluded.setdefault(answer.row, Exclusion(answer.row, answer.participant, reason, detail,
                                                  answer.column if column is None else column))

    def drop_answer(answer: Answer, reason: str, detail: str) -> None:
        """Exclude one answer: its row where the row is that answer, else the answer alone."""
        if trialwise:
            drop(answer, reason, detail)
        else:
            answer_drops.setdefault(id(answer), (answer, Exclusion(answer.row, answer.participant, reason, detail,
                                                                   answer.column, ANSWER)))

    def live(pairs: list) -> list:
        return [(a, s) for a, s in pairs if a.row not in excluded and id(a) not in answer_drops]

    kept = []
    for a in answers:
        if a.stimulus_id not in stimuli.index:
            drop_answer(a, "unknown stimulus", f"stimulus_id {shown(a.stimulus_id)} is not in conditions.csv")
        else:
            kept.append(a)
    check_declared_levels(kept, stimuli)
    kept = _number_repetitions(kept, trialwise)
    if not trialwise:
        kept, notes = _columns_outside(kept, design.repetitions, stimuli)
        column_notes += notes
    kept = _drop_duplicates(kept, drop_answer, design.repetitions, stimuli)
    scored = []
    for a in kept:
        try:
            scored.append((a, _score(a, design)))
        except OutsideScale as exc:
            drop_answer(a, "answer outside the scale", str(exc))
    scored = live(scored)
    scored = live(_check_groups(scored, design, stimuli, drop))
    scored = live(_check_cells(scored, design, stimuli, drop, list(answer_drops.values()), stimulus_columns))
    imported = {a.row for a, _ in scored}
    for row in rows:
        if row not in imported and row not in excluded:
            excluded[row] = _unanswered(row, [e for a, e in answer_drops.values() if a.row == row])
    table = _table(scored, design, stimuli)
    listed = sorted([*excluded.values(), *(e for _, e in answer_drops.values())],
                    key=lambda e: (e.row, e.scope != ROW)) + column_notes
    frame = pd.DataFrame([[e.row, e.participant, e.reason, e.detail, e.column,
                           e.scope if e.row is not None else COLUMN] for e in listed],
                         columns=EXCLUSION_COLUMNS).astype({"row": "Int64"})
    return table, frame


def _unanswered(row: int, dropped: list[Exclusion]) -> Exclusion:
    """The exclusion of a row none of whose answers is imported and which no rule excluded as a whole."""
    if not dropped:
        return Exclusion(row, "", "no answers", "the row answers no stimulus of the design")
    reasons = ", ".join(sorted({e.reason for e in dropped}))
    return Exclusion(row, dropped[0].participant, "no valid answers",
                     f"all {len(dropped)} answers of the row are excluded ({reasons}; each is listed with scope "
                     f"'answer')")


def check_declared_levels(answers: list[Answer], stimuli: pd.DataFrame) -> None:
    """A factor column of the file must agree with the stimulus's level (case and spacing aside)."""
    for a in answers:
        for factor, value in a.declared.items():
            level = str(stimuli.loc[a.stimulus_id].get(factor, ""))
            if level and value.strip().casefold() != level.casefold():
                raise AnalysisError(f"row {a.row}: column {factor!r} is {shown(value)}, but stimulus {a.stimulus_id} "
                                    f"has "
                                    f"{factor} = {level!r} in conditions.csv; the file and the design disagree")


def rows_text(rows) -> str:
    """``row 5`` / ``rows 2, 3, 9`` / ``rows 2, 3, 4, 5, 6 … (72 rows)`` for messages."""
    rows = sorted(set(rows))
    shown = ", ".join(str(r) for r in rows[:5]) + (f" … ({len(rows)} rows)" if len(rows) > 5 else "")
    return f"row{'s' if len(rows) > 1 else ''} {shown}"


def _number_repetitions(answers: list[Answer], trialwise: bool) -> list[Answer]:
    """Repetitions the file does not state are numbered by presentation (or row) order."""
    counter: Counter = Counter()
    for a in sorted(answers, key=lambda a: (a.participant, a.trial if a.trial is not None else 0, a.row)):
        if a.repetition is None:
            counter[(a.participant, a.stimulus_id)] += 1
            a.repetition = counter[(a.participant, a.stimulus_id)]
            a.numbered = True
    if trialwise:  # presentation order within a participant = row order when no trial number is given
        order: Counter = Counter()
        for a in sorted(answers, key=lambda a: a.row):
            order[a.participant] += 1
            a.trial = a.trial if a.trial is not None else order[a.participant]
    return answers


def _drop_duplicates(answers: list[Answer], drop, repetitions: int, stimuli: pd.DataFrame) -> list[Answer]:
    """Same participant, stimulus and repetition twice, more showings of a test clip than the design has, or
    a repetition the file states outside the design's 1…n."""
    stated = defaultdict(list)   # row → its answers whose stated repetition the design does not have
    for a in answers:
        if not a.numbered and _outside(a, repetitions, stimuli):
            stated[a.row].append(a)
    first: dict[tuple, int] = {}
    out = []
    for a in sorted(answers, key=lambda a: a.row):
        if a.numbered and _outside(a, repetitions, stimuli):
            drop(a, "duplicate answer", f"participant {a.participant!r} answered {a.stimulus_id} {a.repetition} "
                                        f"times; the design shows it {repetitions} time(s)")
            continue
        if any(a is b for b in stated.get(a.row, ())):
            drop(a, "repetition outside the design", _outside_detail(stated[a.row], repetitions))
            continue
        key = (a.participant, a.stimulus_id, a.repetition)
        if key in first and first[key] != a.row:
            drop(a, "duplicate answer", f"participant {a.participant!r} already answered {a.stimulus_id} "
                                        f"repetition {a.repetition} in row {first[key]}")
            continue
        first.setdefault(key, a.row)
        out.append(a)
    return out


def _columns_outside(answers: list[Answer], repetitions: int, stimuli: pd.DataFrame
                     ) -> tuple[list[Answer], list[Exclusion]]:
    """(the answers of the other columns, one note per column) for the columns of a wide export whose tag states
    a repetition the design does not have: the column does not fit the design, whoever answered it."""
    outside: dict[str, Answer] = {}
    for a in answers:
        if not a.numbered and _outside(a, repetitions, stimuli):
            outside.setdefault(a.column, a)
    notes = [Exclusion(None, "", "repetition outside the design",
                       f"{_outside_detail([a], repetitions)}; column not imported", column, COLUMN)
             for column, a in outside.items()]
    return [a for a in answers if a.column not in outside], notes


def _outside(a: Answer, repetitions: int, stimuli: pd.DataFrame) -> bool:
    """A test answer whose repetition is not one of the design's 1…n (practice clips may repeat freely)."""
    return not (1 <= a.repetition <= repetitions) and not stimuli.loc[a.stimulus_id, "practice"]


def _outside_detail(answers: list[Answer], repetitions: int) -> str:
    """Name the column(s) that state a repetition the design does not have (Qualtrics: the export tags)."""
    if answers[0].column == "response":   # one-row-per-answer formats state it in the ``repetition`` column
        a = answers[0]
        return (f"column 'repetition' is {a.repetition} for {a.stimulus_id}; the design shows each stimulus "
                f"{repetitions} time(s) (repetition 1…{repetitions})")
    columns = ", ".join(f"{a.column!r} (repetition {a.repetition} of {a.stimulus_id})" for a in answers)
    return (f"column{'s' if len(answers) > 1 else ''} {columns}: the design shows each stimulus {repetitions} "
            f"time(s) (repetition 1…{repetitions}); is the export from another design?")


def _score(a: Answer, design: DesignInfo) -> dict:
    """The answer's score; what a choice value means is fixed by its source (``a.reading``), not guessed."""
    if design.response_type == "likert":
        score = {"rating": score_likert(a.value, design.labels, design.k, a.reading)}
    elif design.response_type == "afc":
        arrangement = design.arrangement(a.stimulus_id)
        chosen, position = score_choice(a.value, arrangement, design.position_labels, a.reading)
        score = {"chosen": chosen, "position": position}
    else:
        arrangement = design.arrangement(a.stimulus_id)
        return {"ranking": ">".join(score_ranking(a.ranks, a.value, arrangement, design.position_labels,
                                                  a.reading))}
    check_restated(a, score, design)
    return score


def check_restated(a: Answer, score: dict, design: DesignInfo) -> None:
    """jsPsych's ``chosen`` / ``rating`` columns restate the answer; a row where they disagree with the score of
    its ``response`` is an error (the file and the design disagree about what was shown where)."""
    for column, value in a.restated.items():
        if column not in score:
            continue
        if str(score[column]).strip().casefold() != value.strip().casefold():
            where = (f" (positions {'|'.join(design.arrangement(a.stimulus_id))} in conditions.csv)"
                     if column == "chosen" else "")
            raise AnalysisError(f"row {a.row}: column {column!r} is {shown(value)}, but the answer {a.column} = "
                                f"{shown(a.value)} "
                                f"of participant {shown(a.participant)} to stimulus {a.stimulus_id} is {column} "
                                f"{score[column]!r}{where}; the file and the design disagree")


def _check_groups(scored, design: DesignInfo, stimuli: pd.DataFrame, drop):
    """Every participant belongs to one between-subject group (from the stimuli answered and the file)."""
    if not design.between:
        return scored
    groups = defaultdict(set)
    evidence = defaultdict(list)   # participant → (row, group of the stimulus, group the file states)
    for a, _ in scored:
        row = stimuli.loc[a.stimulus_id]
        shown = tuple(str(row.get(b, "")) for b in design.between)
        stated = tuple(a.groups.get(b, shown[i]) for i, b in enumerate(design.between)) if a.groups else shown
        groups[a.participant] |= {shown, stated}
        evidence[a.participant].append((a.row, shown, stated))
    details = {p: _groups_detail(evidence[p], design.between) for p, g in groups.items() if len(g) > 1}
    stated = {a.participant: ", ".join(b for b in design.between if b in a.groups) for a, _ in scored}
    for a, _ in scored:
        if a.participant in details:
            # the column is the file's group column where it has one; the detail names the stimuli's rows
            drop(a, "several between-subject groups", details[a.participant], stated[a.participant])
    return scored


def _groups_detail(evidence: list[tuple], between: list[str]) -> str:
    """Which rows put one participant in which between group: stimuli of several groups, or a group
    column that contradicts the stimuli answered."""
    def name(group: tuple) -> str:
        return ", ".join(f"{b}={v}" for b, v in zip(between, group))

    found = sorted({"/".join(g) for _, shown, stated in evidence for g in (shown, stated)})
    parts = []
    by_shown = defaultdict(list)
    for row, shown, _ in evidence:
        by_shown[shown].append(row)
    if len(by_shown) > 1:
        parts.append("stimuli of " + " and ".join(f"{name(g)} ({rows_text(r)})" for g, r in sorted(by_shown.items())))
    conflicts = defaultdict(list)
    for row, shown, stated in evidence:
        if stated != shown:
            conflicts[(stated, shown)].append(row)
    for (stated, shown), rows in sorted(conflicts.items()):
        parts.append(f"the file's {'/'.join(between)} column says {name(stated)} for a stimulus of {name(shown)} "
                     f"({rows_text(rows)})")
    return f"{'×'.join(between)} levels {found} in one participant's answers: {'; '.join(parts)}"


def _cell_key(row: pd.Series, factors: list[str]) -> tuple:
    return tuple(str(row[f]) for f in factors)


def _check_cells(scored, design: DesignInfo, stimuli: pd.DataFrame, drop,
                 dropped: list[tuple[Answer, Exclusion]] = (), stimulus_columns: dict[str, list[str]] | None = None):
    """A participant must have at least one valid answer in each design cell of their group.

    The exclusion names the first missing cell, the columns where its answers would be (``stimulus_columns``;
    one-answer-per-row formats: ``stimulus_id``) and the participant's answers there that were excluded one by
    one (``dropped``), which is how a cell that was answered goes missing.
    """
    tests = design.test_conditions
    cells_of_group = defaultdict(set)
    stimuli_of_cell = defaultdict(list)
    for _, row in tests.iterrows():
        cells_of_group[_cell_key(row, design.between)].add(_cell_key(row, design.cell_factors))
        stimuli_of_cell[(_cell_key(row, design.between), _cell_key(row, design.cell_factors))].append(
            row["stimulus_id"])
    seen = defaultdict(set)
    group_of = {}
    for a, _ in scored:
        row = stimuli.loc[a.stimulus_id]
        if row["practice"]:
            continue
        group_of[a.participant] = _cell_key(row, design.between)
        seen[a.participant].add(_cell_key(row, design.cell_factors))
    for a, _ in scored:
        if a.participant not in group_of:
            drop(a, "missing cells", "no answer to any test stimulus (practice only)")
            continue
        group = group_of[a.participant]
        expected = cells_of_group.get(group, set())
        missing = sorted(expected - seen[a.participant])
        if missing:
            example = ", ".join(f"{f}={v}" for f, v in zip(design.cell_factors, missing[0]))
            cell_stimuli = stimuli_of_cell[(group, missing[0])]
            columns = ("stimulus_id" if stimulus_columns is None else
                       ", ".join(c for sid in cell_stimuli for c in stimulus_columns.get(sid, [])))
            gone = [e.reason for b, e in dropped if b.participant == a.participant and b.stimulus_id in cell_stimuli]
            note = (f"; {len(gone)} answer{'s' if len(gone) > 1 else ''} there excluded "
                    f"({', '.join(sorted(set(gone)))})" if gone else "")
            drop(a, "missing cells", f"{len(missing)} of {len(expected)} design cells have no valid answer "
                                     f"(e.g. {example}{note})", columns)
    return scored


def _table(scored, design: DesignInfo, stimuli: pd.DataFrame) -> pd.DataFrame:
    factor_cols = [f.name for f in design.factors if f.role != "alternatives"]
    records = []
    for a, score in scored:
        row = stimuli.loc[a.stimulus_id]
        records.append({"participant": a.participant, **{f: str(row.get(f, "")) for f in factor_cols},
                        "stimulus_id": a.stimulus_id, "repetition": a.repetition, "trial": a.trial, **score,
                        "rt": a.rt, "practice": bool(row["practice"]), "row": a.row})
    score_cols = {"likert": ["rating"], "afc": ["chosen", "position"], "ranking": ["ranking"]}[design.response_type]
    columns = ["participant", *factor_cols, "stimulus_id", "repetition", "trial", *score_cols, "rt", "practice", "row"]
    table = pd.DataFrame.from_records(records, columns=columns)
    # explicit dtypes, so that an empty table (everyone excluded) still behaves like a full one
    table = table.astype({"repetition": "Int64", "trial": "Int64", "row": "Int64", "practice": bool, "rt": float})
    if design.response_type in ("likert",):
        table["rating"] = table["rating"].astype("Int64")
    if design.response_type == "afc":
        table["position"] = table["position"].astype("Int64")
    table["_order"] = participant_order(table["participant"])
    table = table.sort_values(["_order", "practice", "trial", "row", "stimulus_id", "repetition"], kind="stable")
    return table.drop(columns="_order").reset_index(drop=True)


def participant_order(participants: pd.Series) -> pd.Series:
    """Sort key: numeric ids as numbers (2 before 10), then the others alphabetically."""
    ids = sorted(set(participants), key=lambda x: (0, int(x), "") if str(x).isdigit() else (1, 0, str(x)))
    rank = {p: i for i, p in enumerate(ids)}
    return participants.map(rank)
