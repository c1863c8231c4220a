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

Sessions: one file may hold several runs of the experiment by the same participant id (a restart, a second
visit, two files pasted together). A run is told apart by an explicit session column (``session``,
``session_id``, ``run_id``), by jsPsych's ``list`` and by its counter restarting — jsPsych's
``trial_index`` (and ``time_elapsed``) start again at 0, the long format's ``trial`` at 1 — so each row
belongs to one session and the rule of the other formats applies: unfinished sessions are excluded as
"unfinished", the first finished session (in file order) is imported and every later one is excluded as
"duplicate participant id". Runs whose rows are interleaved so that they cannot be told apart (two runs of
the same list, rows shuffled) exclude all of that participant's rows with that reason, never a merge.
"""

from __future__ import annotations

import json
import math

from collections import Counter
from dataclasses import dataclass, field

from analysis.responses.answers import Answer, Exclusion
from analysis.responses.read import RawFile, _participant_column
from analysis.responses.scoring import CHOICE, LEVEL


# Long-CSV columns the importer reads, or that restate the design (what ``simulate --format long`` writes).
LONG_COLUMNS = {"stimulus_id", "response", "button_pressed", "rt", "rt_ms", "repetition", "trial", "block",
                "block_label", "practice", "kind", "condition_id", "left", "right", "positions", "end",
                "shapemotion_protocol", "session", "session_id", "run_id"}

# Columns that name a run of the experiment (when they are not the participant column).
SESSION_COLUMNS = ("session", "session_id", "run_id")


# jsPsych data columns that carry no answer of their own: the core fields of every trial
# (jsPsych 7 and 8), the fields of the plugins a shapemotion experiment runs (preload, button
# responses, survey forms), and the bookkeeping the exported experiment adds to its trials
# (``response_label``, ``rating`` and ``chosen`` restate ``response``; ``rank_step`` numbers a ranking's
# picks). Any other column — e.g. a lab's own ``jsPsych.data.addProperties`` field — is listed as not
# imported, as in the other formats.
JSPSYCH_COLUMNS = {"trial_type", "trial_index", "time_elapsed", "internal_node_id", "plugin_version",
                   "timeline_variables", "stimulus", "success", "timeout", "failed_images", "failed_audio",
                   "failed_video", "view_history", "question_order", "list", "protocol", "clip_id",
                   "response_label", "rating", "chosen", "rank_step"}


# Columns that restate a stimulus's row of conditions.csv; checked against it like factor columns.
RESTATED = ("condition_id", "left", "right", "positions")


def trialwise_answers(raw: RawFile, between: list[str], within: list[str] = ()):
    """Answers and row exclusions of a jsPsych or long file (one row per answer).

    Levels of the ``within`` factors that a row states are kept in ``Answer.declared`` so that the
    importer can check them against the stimulus (a contradiction is an error, never ignored).
    """
    rows = raw.rows if raw.format == "jspsych-json" else [dict(zip(raw.columns, r)) for r in raw.rows]
    pid_col = _participant_column(raw.columns)
    jspsych = raw.format.startswith("jspsych")
    pids = [_text(record.get(pid_col)) if pid_col else raw.path.stem for record in rows]
    wellformed = [raw.format == "jspsych-json" or len(cells) == len(raw.columns) for cells in raw.rows]
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
        sid = _text(record.get("stimulus_id"))
        if not sid:
            kind = _text(record.get("trial_type")) or "?"
            exclusions.append(Exclusion(number, pid, "not a stimulus trial", f"trial_type = {kind}"))
            continue
        if not pid:
            exclusions.append(Exclusion(number, pid, "no participant id", f"column {pid_col!r} is empty"))
            continue
        stated = _text(record.get("repetition"))
        if stated and not _whole(stated):
            # Renumbering it would silently put the answer on another repetition.
            exclusions.append(Exclusion(number, pid, "malformed row",
                                        f"column 'repetition' is {stated!r}; expected a whole number ≥ 1"))
            continue
        answers.append(_answer(record, number, pid, sid, jspsych, between, within))
    return answers, exclusions + unread_columns(raw, [*between, *within])


def unread_columns(raw: RawFile, factors: list[str]) -> list[Exclusion]:
    """Column notes for the columns the importer does not read (e.g. a free-text comment).

    Listed like the Qualtrics columns that name no stimulus, so nothing a user gave disappears unmentioned.
    """
    jspsych = raw.format.startswith("jspsych")
    known = LONG_COLUMNS | set(factors) | {_participant_column(raw.columns)} | (JSPSYCH_COLUMNS if jspsych else set())
    fmt = "jsPsych data" if jspsych else "the long format"
    return [Exclusion(None, "", "column not imported", f"column {name!r} is not a column {fmt} reads "
                                                       f"(participant, stimulus_id, response, rt, repetition, trial, "
                                                       f"factor columns, …); column not imported", name)
            for name in raw.columns if name not in known]


@dataclass
class Session:
    """One run of the experiment by one participant id: its rows (indices into the file's records)."""

    participant: str
    rows: list[int] = field(default_factory=list)
    label: str = ""            # what tells it apart, for messages ("list 2", "session 'b'")
    finished: bool = True
    tangled: str = ""          # why its rows cannot be told apart from another run's (then not imported)


def session_exclusions(rows: list[dict], pids: list[str], wellformed: list[bool], raw: RawFile,
                       pid_col: str | None) -> dict[int, tuple[str, str]]:
    """Row index → (reason, detail) for the rows of sessions that are not imported: unfinished runs, runs after
    the participant's first finished one ("duplicate participant id"), and runs that cannot be told apart."""
    numbers = raw.row_numbers
    out: dict[int, tuple[str, str]] = {}
    by_participant: dict[str, list[Session]] = {}
    for session in find_sessions(rows, pids, wellformed, raw, pid_col):
        by_participant.setdefault(session.participant, []).append(session)
    for pid, sessions in by_participant.items():
        sessions.sort(key=lambda s: s.rows[0])
        tangled = [s.tangled for s in sessions if s.tangled]
        if tangled:
            detail = (f"participant {pid!r}: {tangled[0]}; the runs cannot be told apart, so none of this "
                      f"participant's {sum(len(s.rows) for s in sessions)} rows is imported")
            for s in sessions:
                out.update({i: ("duplicate participant id", detail) for i in s.rows})
            continue
        several = len(sessions) > 1
        kept = None
        for n, s in enumerate(sessions, 1):
            where = (f"session {n} of {len(sessions)} of participant {pid!r} ({s.label + ', ' if s.label else ''}"
                     f"{_span(s, numbers)})") if several else ""
            if not s.finished:
                detail = (f"{where}: no closing row with end = 1 in this session" if several else
                          "no closing row with end = 1 for this participant")
                out.update({i: ("unfinished", detail) for i in s.rows})
            elif kept is None:
                kept = (n, s)
            else:
                first_n, first = kept
                detail = (f"{where} is another run of the experiment; participant {pid!r} is already imported "
                          f"from session {first_n} ({first.label + ', ' if first.label else ''}{_span(first, numbers)})")
                out.update({i: ("duplicate participant id", detail) for i in s.rows})
    return out


def _span(session: Session, numbers: list[int]) -> str:
    rows = sorted(numbers[i] for i in session.rows)
    if len(rows) == 1:
        return f"row {rows[0]}"
    if rows[-1] - rows[0] + 1 == len(rows):
        return f"rows {rows[0]}–{rows[-1]}"
    return f"{len(rows)} rows between row {rows[0]} and row {rows[-1]}"


def find_sessions(rows: list[dict], pids: list[str], wellformed: list[bool], raw: RawFile,
                  pid_col: str | None) -> list[Session]:
    """Split each participant's rows into runs of the experiment (see the module docstring)."""
    jspsych = raw.format.startswith("jspsych")
    id_cols = [c for c in SESSION_COLUMNS if c in raw.columns and c != pid_col]
    if jspsych and "list" in raw.columns:
        id_cols.append("list")
    counter = "trial_index" if jspsych else "trial"
    clock = "time_elapsed" if jspsych else None
    has_end = "end" in raw.columns
    # a row without a session value belongs to its participant's only session value, if there is one
    values: dict[tuple[str, str], set[str]] = {}
    for i, record in enumerate(rows):
        for c in id_cols:
            if wellformed[i] and _text(record.get(c)):
                values.setdefault((pids[i], c), set()).add(_text(record.get(c)))

    def value(i: int, column: str) -> str:
        own = _text(rows[i].get(column))
        known = values.get((pids[i], column), set())
        return own or (next(iter(known)) if len(known) == 1 else "")

    parts: dict[tuple, list[int]] = {}
    for i in range(len(rows)):
        if wellformed[i]:
            parts.setdefault((pids[i], *(value(i, c) for c in id_cols)), []).append(i)
    sessions = []
    for key, indices in parts.items():
        label = ", ".join(f"{c} {v!r}" if c != "list" else f"list {v}" for c, v in zip(id_cols, key[1:]) if v)
        for run, tangled in _split_runs(rows, indices, counter, clock, jspsych):
            sessions.append(Session(key[0], run, label, tangled=tangled,
                                    finished=not has_end or any(_text(rows[i].get("end")).lower() in ("1", "true")
                                                                for i in run)))
    return sessions


def _split_runs(rows: list[dict], indices: list[int], counter: str, clock: str | None,
                jspsych: bool) -> list[tuple[list[int], str]]:
    """The runs within one participant's rows that share every session column: ``[(row indices, tangled)]``.

    One run when the counter never repeats; else the file-order segments at which it restarts, if there are as
    many as the counter's most repeated value (the runs were written one after the other); else the rows of
    several runs are interleaved: one entry, flagged as tangled."""
    values = [_number(rows[i].get(counter)) for i in indices]
    counts = Counter(v for v in values if v is not None)
    repeats = max(counts.values(), default=0)
    if repeats <= 1:
        return [(indices, "")]
    segments: list[list[int]] = [[]]
    last_count = last_clock = None
    for i, value in zip(indices, values):
        now = _number(rows[i].get(clock)) if clock else None
        restart = ((value is not None and last_count is not None and value <= last_count) or
                   (now is not None and last_clock is not None and now < last_clock))
        if restart and segments[-1]:
            segments.append([])
        segments[-1].append(i)
        last_count = value if value is not None else last_count
        last_clock = now if now is not None else last_clock
    if not jspsych and not _answers_overlap(rows, segments):
        return [(indices, "")]   # the long file numbers its trials per block, say: one run
    if len(segments) == repeats:
        return [(segment, "") for segment in segments]
    value = min(v for v, n in counts.items() if n == repeats)
    return [(indices, f"{counter} {value:g} appears {repeats} times, in {len(segments)} stretches of rows "
                      f"that do not each count up from the start (rows of {repeats} runs interleaved, e.g. sorted "
                      f"or shuffled)")]


def _answers_overlap(rows: list[dict], segments: list[list[int]]) -> bool:
    """Whether two stretches of a long file answer the same stimulus (and repetition): a second run, not the
    file's own trial numbering restarting per block."""
    seen: set = set()
    for segment in segments:
        here = {(_text(rows[i].get("stimulus_id")), _text(rows[i].get("repetition"))) for i in segment
                if _text(rows[i].get("stimulus_id"))}
        if seen & here:
            return True
        seen |= here
    return False


def _answer(record: dict, number: int, pid: str, sid: str, jspsych: bool, between: list[str],
            within: list[str] = ()) -> Answer:
    value, ranks = _response(record.get("response", record.get("button_pressed")), jspsych)
    # jsPsych answers are the buttons pressed (positions, position labels); the long format names the level
    reading = CHOICE if jspsych else LEVEL
    restated = {c: _text(record.get(c)) for c in ("chosen", "rating") if jspsych and _text(record.get(c))}
    rt = _number(record.get("rt"))
    if rt is not None and jspsych:
        rt = rt / 1000.0
    elif rt is None and _number(record.get("rt_ms")) is not None:
        rt = _number(record.get("rt_ms")) / 1000.0
    rep = _number(record.get("repetition"))
    trial = _number(record.get("trial"))  # jsPsych's trial_index counts every row; order is re-derived later
    groups = {n: _text(record.get(n)) for n in between if _text(record.get(n))}
    # The placement columns restate the design too: the score reads the design's, so a file whose
    # clips stood elsewhere on screen would be scored against the wrong alternative.
    declared = {n: _text(record.get(n)) for n in (*within, *RESTATED) if _text(record.get(n))}
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
    text = _text(raw)
    number = _number(text)
    if jspsych and number is not None and float(number).is_integer():
        return str(int(number) + 1), None  # jsPsych buttons and scales count from 0
    return text, None


def _text(value) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    return str(value).strip()


def _whole(text: str) -> bool:
    """A cell holding a whole number ≥ 1 (``2`` or ``2.0``)."""
    number = _number(text)
    return number is not None and number >= 1 and float(number).is_integer()


def _number(value) -> float | None:
    text = _text(value)
    try:
        number = float(text)
    except ValueError:
        return None
    return None if math.isnan(number) else number
