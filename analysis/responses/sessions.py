"""Runs of the experiment in one jsPsych or long file.

One file may hold several runs of the experiment by the same participant id (a restart, a second
visit, two files pasted together). A run is told apart by an explicit session column (``session``,
``session_id``, ``run_id``), by jsPsych's ``list`` and by its counter restarting — jsPsych's
``trial_index`` (and ``time_elapsed``) start again at 0, the long format's ``trial`` at 1 — so each row
belongs to one session and the rule of the other formats applies: unfinished sessions are excluded as
"unfinished", the first finished session (in file order) is imported and every later one is excluded as
"duplicate participant id". Runs whose rows are interleaved so that they cannot be told apart (two runs of
the same list, rows shuffled) exclude all of that participant's rows with that reason, never a merge.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

from analysis.responses.read import RawFile, cell_number, cell_text

# Columns that name a run of the experiment (when they are not the participant column).
SESSION_COLUMNS = ("session", "session_id", "run_id")


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
    filled = {c: _filled(rows, pids, wellformed, c) for c in id_cols}
    parts: dict[tuple, list[int]] = {}
    for i in range(len(rows)):
        if wellformed[i]:
            parts.setdefault((pids[i], *(filled[c][i] for c in id_cols)), []).append(i)
    sessions = []
    for key, indices in parts.items():
        label = ", ".join(f"{c} {v!r}" if c != "list" else f"list {v}" for c, v in zip(id_cols, key[1:]) if v)
        for run, tangled in _split_runs(rows, indices, counter, clock, jspsych):
            sessions.append(Session(key[0], run, label, tangled=tangled,
                                    finished=not has_end or any(cell_text(rows[i].get("end")).lower() in ("1", "true")
                                                                for i in run)))
    return sessions


def _filled(rows: list[dict], pids: list[str], wellformed: list[bool], column: str) -> dict[int, str]:
    """Row index → the session value of ``column``; a blank cell takes the value of its participant's row
    before it (at the start of the participant's rows: the first value after it). A blank cell inside a
    run used to make a run of its own, with no closing row, and the whole run was then lost as unfinished."""
    out: dict[int, str] = {}
    last: dict[str, str] = {}
    waiting: dict[str, list[int]] = {}
    for i, record in enumerate(rows):
        if not wellformed[i]:
            continue
        value, pid = cell_text(record.get(column)), pids[i]
        if value:
            last[pid] = value
            out.update({j: value for j in waiting.pop(pid, [])})
        elif pid in last:
            value = last[pid]
        else:
            waiting.setdefault(pid, []).append(i)
        out[i] = value
    return out


def _split_runs(rows: list[dict], indices: list[int], counter: str, clock: str | None,
                jspsych: bool) -> list[tuple[list[int], str]]:
    """The runs within one participant's rows that share every session column: ``[(row indices, tangled)]``.

    One run when the counter never repeats; else the file-order segments at which it restarts, if there are as
    many as the counter's most repeated value (the runs were written one after the other); else the rows of
    several runs are interleaved: one entry, flagged as tangled."""
    values = [cell_number(rows[i].get(counter)) for i in indices]
    counts = Counter(v for v in values if v is not None)
    repeats = max(counts.values(), default=0)
    if repeats <= 1:
        return [(indices, "")]
    segments: list[list[int]] = [[]]
    last_count = last_clock = None
    for i, value in zip(indices, values):
        now = cell_number(rows[i].get(clock)) if clock else None
        restart = ((value is not None and last_count is not None and value <= last_count) or
                   (now is not None and last_clock is not None and now < last_clock))
        if restart and segments[-1]:
            segments.append([])
        segments[-1].append(i)
        last_count = value if value is not None else last_count
        last_clock = now if now is not None else last_clock
    if not jspsych:   # a long file may number its trials per block: a restart alone is no new run
        segments = _join_blocks(rows, segments)
        repeats = max(Counter(_answer_key(rows[i]) for i in indices if _answer_key(rows[i])[0]).values(), default=1)
        if len(segments) == 1:
            return [(indices, "")]
    if len(segments) == repeats:
        return [(segment, "") for segment in segments]
    value = min(v for v, n in counts.items() if n == max(counts.values()))
    return [(indices, f"{counter} {value:g} appears {max(counts.values())} times, in {len(segments)} stretches of "
                      f"rows that do not each count up from the start (rows of several runs interleaved, e.g. "
                      f"sorted or shuffled)")]


def _answer_key(row: dict) -> tuple[str, str]:
    return cell_text(row.get("stimulus_id")), cell_text(row.get("repetition"))


def _join_blocks(rows: list[dict], segments: list[list[int]]) -> list[list[int]]:
    """Consecutive stretches of a long file joined into runs until one answers a stimulus (and repetition)
    the run already answered: per-block trial numbers restart without a new run; a repeated answer is one."""
    runs: list[list[int]] = []
    seen: set = set()
    for segment in segments:
        here = {_answer_key(rows[i]) for i in segment if _answer_key(rows[i])[0]}
        if runs and not seen & here:
            runs[-1] += segment
            seen |= here
        else:
            runs.append(list(segment))
            seen = here
    return runs
