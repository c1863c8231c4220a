"""One-row-per-answer formats → answers: jsPsych data (CSV or JSON) and the plain long CSV.

jsPsych rows are trials of any plugin; those with a ``stimulus_id`` (the survey exporter adds it to each
video trial's ``data``) are answers, every other row (instructions, consent, fullscreen, …) is listed as
excluded with reason "not a stimulus trial" so that counts reconcile with the file. Button responses
are 0-based in jsPsych and become 1-based here; ``rt`` is in milliseconds in jsPsych and seconds in the
tidy table.

What a forced-choice value means is fixed by the format (``scoring.CHOICE`` / ``scoring.LEVEL``): jsPsych's
``response`` is the button pressed, i.e. a screen position (or, for rankings, the position labels picked);
the long format's ``response`` names the chosen level. jsPsych's own ``chosen``/``rating`` columns restate
the answer and are checked against it.

Sessions (several runs by one participant id in one file) are told apart in :mod:`analysis.responses.sessions`.
A jsPsych file without a participant column is one participant's (the file name is the id); if it holds
several runs, it is refused rather than read as one participant who ran the experiment many times.

A response time that is not a number ≥ 0 (``fast``, ``-5``; empty or ``null`` is no time, which is fine) makes
the row "malformed": the time is not analysed, but a cell that cannot be a time shows the row was damaged
(shifted fields, a hand edit), so its answer is not trusted either — the row is excluded and listed, the file
and the other answers are kept, as for a ``repetition`` that is no whole number.
"""

from __future__ import annotations

import json

import math

from analysis.errors import AnalysisError
from analysis.responses.answers import Answer, Exclusion
from analysis.responses.read import PARTICIPANT_COLUMNS, RawFile, _participant_column, cell_number, cell_text, shown
from analysis.responses.scoring import CHOICE, LEVEL
from analysis.responses.sessions import find_sessions, session_exclusions


# Long-CSV columns the importer reads, or that restate the design (what ``simulate --format long`` writes).
LONG_COLUMNS = {"stimulus_id", "response", "button_pressed", "rt", "rt_ms", "repetition", "trial", "block",
                "block_label", "practice", "kind", "condition_id", "left", "right", "positions", "end",
                "shapemotion_protocol", "session", "session_id", "run_id", "shapemotion_simulated"}


# jsPsych data columns that carry no answer of their own: the core fields of every trial
# (jsPsych 7 and 8), the fields of the plugins a shapemotion experiment runs (preload, button
# responses, survey forms), and the bookkeeping the exported experiment adds to its trials
# (``response_label``, ``rating`` and ``chosen`` restate ``response``; ``rank_step`` numbers a ranking's
# picks). Any other column — e.g. a lab's own ``jsPsych.data.addProperties`` field — is listed as not
# imported, as in the other formats.
JSPSYCH_COLUMNS = {"trial_type", "trial_index", "time_elapsed", "internal_node_id", "plugin_version",
                   "timeline_variables", "stimulus", "success", "timeout", "failed_images", "failed_audio",
                   "failed_video", "view_history", "question_order", "list", "protocol", "clip_id",
                   "response_label", "rating", "chosen", "rank_step",
                   "attention_check", "attention_answer", "attention_passed"}   # attention checks (attention.py)


# Columns that restate a stimulus's row of conditions.csv; checked against it like factor columns.
RESTATED = ("condition_id", "left", "right", "positions")


def trialwise_answers(raw: RawFile, between: list[str], within: list[str] = ()):
    """Answers and row exclusions of a jsPsych or long file (one row per answer).

    Levels of the ``within`` factors that a row states are kept in ``Answer.declared`` so that the
    importer can check them against the stimulus (a contradiction is an error, never ignored).
    """
    rows, pids = records_and_ids(raw)
    pid_col = _participant_column(raw.columns)
    jspsych = raw.format.startswith("jspsych")
    wellformed = [raw.format == "jspsych-json" or len(cells) == len(raw.columns) for cells in raw.rows]
    if pid_col is None:
        check_one_participant(rows, pids, wellformed, raw)
    session_problem = session_exclusions(rows, pids, wellformed, raw, pid_col)
    answers, exclusions = [], []
    for i, (number, record, cells) in enumerate(zip(raw.row_numbers, rows, raw.rows)):
        pid = pids[i]
        if not wellformed[i]:
            exclusions.append(Exclusion(number, pid, "malformed row",
                                        f"{len(cells)} fields, the header has {len(raw.columns)}"))
            continue
        if i in session_problem:
            exclusions.append(Exclusion(number, pid, *session_problem[i]))
            continue
        sid = cell_text(record.get("stimulus_id"))
        if not sid:
            kind = cell_text(record.get("trial_type")) or "?"
            exclusions.append(Exclusion(number, pid, "not a stimulus trial", f"trial_type = {kind}"))
            continue
        if not pid:
            exclusions.append(Exclusion(number, pid, "no participant id", f"column {pid_col!r} is empty"))
            continue
        stated = cell_text(record.get("repetition"))
        if stated and not _whole(stated):
            # Renumbering it would silently put the answer on another repetition.
            exclusions.append(Exclusion(number, pid, "malformed row",
                                        f"column 'repetition' is {shown(stated)}; expected a whole number ≥ 1",
                                        "repetition"))
            continue
        bad_time = _bad_time(record, jspsych)
        if bad_time:
            exclusions.append(Exclusion(number, pid, "malformed row", bad_time[1], bad_time[0]))
            continue
        answers.append(_answer(record, number, pid, sid, jspsych, between, within))
    return answers, exclusions + unread_columns(raw, [*between, *within])


def records_and_ids(raw: RawFile) -> tuple[list[dict], list[str]]:
    """Each row as a dict of its columns, and its participant id (the file name without a participant column)."""
    rows = raw.rows if raw.format == "jspsych-json" else [dict(zip(raw.columns, r)) for r in raw.rows]
    pid_col = _participant_column(raw.columns)
    return rows, [cell_text(record.get(pid_col)) if pid_col else raw.path.stem for record in rows]


def check_one_participant(rows: list[dict], pids: list[str], wellformed: list[bool], raw: RawFile) -> None:
    """A file without a participant column is read as one participant's: refuse it when it holds several runs
    of the experiment (a file of many participants whose id column was lost would otherwise be one participant
    who ran it many times, and the analysis would say the responses hold a single group)."""
    sessions = find_sessions(rows, pids, wellformed, raw, None)
    runs = len(sessions) if not any(s.tangled for s in sessions) else None
    if runs is not None and runs <= 1:
        return
    found = (f"{runs} runs of the experiment (starting in rows "
             f"{', '.join(str(raw.row_numbers[s.rows[0]]) for s in sessions[:5])}{' …' if runs > 5 else ''})"
             if runs is not None else f"several runs of the experiment ({sessions[0].tangled})")
    raise AnalysisError(f"no participant column (one of {', '.join(PARTICIPANT_COLUMNS)}), but the file holds "
                        f"{found}; without one the whole file would be read as the single participant "
                        f"{pids[0]!r} (the file name) — add the participant column, or save one file per "
                        f"participant")


def _bad_time(record: dict, jspsych: bool) -> tuple[str, str] | None:
    """(column, detail) for a response time that is not a number ≥ 0: jsPsych ``rt`` (ms), long ``rt`` (s) or
    ``rt_ms``. Empty or ``null`` is no time (jsPsych writes null when no response was timed)."""
    for column, unit in (("rt", "milliseconds" if jspsych else "seconds"), ("rt_ms", "milliseconds")):
        text = cell_text(record.get(column))
        if not text or text.lower() == "null":
            continue
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value >= 0):
            return column, f"column {column!r} is {shown(text)}; expected a response time in {unit} (a number ≥ 0, " \
                           f"or empty), so the row is damaged"
    return None


def unread_columns(raw: RawFile, factors: list[str]) -> list[Exclusion]:
    """Column notes for the columns the importer does not read (e.g. a free-text comment).

    Listed like the Qualtrics columns that name no stimulus, so nothing a user gave disappears unmentioned.
    """
    jspsych = raw.format.startswith("jspsych")
    known = LONG_COLUMNS | set(factors) | {_participant_column(raw.columns)} | (JSPSYCH_COLUMNS if jspsych else set())
    fmt = "jsPsych data" if jspsych else "the long format"
    return [Exclusion(None, "", "column not imported", f"column {shown(name)} is not a column {fmt} reads "
                                                       f"(participant, stimulus_id, response, rt, repetition, trial, "
                                                       f"factor columns, …); column not imported", name)
            for name in raw.columns if name not in known]


def _answer(record: dict, number: int, pid: str, sid: str, jspsych: bool, between: list[str],
            within: list[str] = ()) -> Answer:
    value, ranks = _response(record.get("response", record.get("button_pressed")), jspsych)
    # jsPsych answers are the buttons pressed (positions, position labels); the long format names the level
    reading = CHOICE if jspsych else LEVEL
    restated = {c: cell_text(record.get(c)) for c in ("chosen", "rating") if jspsych and cell_text(record.get(c))}
    rt = cell_number(record.get("rt"))
    if rt is not None and jspsych:
        rt = rt / 1000.0
    elif rt is None and cell_number(record.get("rt_ms")) is not None:
        rt = cell_number(record.get("rt_ms")) / 1000.0
    rep = cell_number(record.get("repetition"))
    trial = cell_number(record.get("trial"))  # jsPsych's trial_index counts every row; order is re-derived later
    groups = {n: cell_text(record.get(n)) for n in between if cell_text(record.get(n))}
    # The placement columns restate the design too: the score reads the design's, so a file whose
    # clips stood elsewhere on screen would be scored against the wrong alternative.
    declared = {n: cell_text(record.get(n)) for n in (*within, *RESTATED) if cell_text(record.get(n))}
    return Answer(number, pid, sid, value, "response", int(rep) if rep is not None else None,
                  int(trial) if trial is not None else None, rt, ranks, groups, declared, reading=reading,
                  restated=restated)


def _response(raw, jspsych: bool) -> tuple[str, list[str] | None]:
    """Text value (1-based when numeric) or a ranking order ``a>b>c`` from any jsPsych response shape."""
    if isinstance(raw, str) and raw.strip()[:1] in "[{":
        try:
            raw = json.loads(raw)
        except json.JSONDecodeError:
            pass
    if isinstance(raw, dict):  # survey plugins: {"Q0": 2}
        raw = next(iter(raw.values()), "")
    if isinstance(raw, list):
        return ">".join(str(x) for x in raw), None
    text = cell_text(raw)
    number = cell_number(text)
    if jspsych and number is not None and float(number).is_integer():
        return str(int(number) + 1), None  # jsPsych buttons and scales count from 0
    return text, None


def _whole(text: str) -> bool:
    """A cell holding a whole number ≥ 1 (``2`` or ``2.0``)."""
    number = cell_number(text)
    return number is not None and number >= 1 and float(number).is_integer()
