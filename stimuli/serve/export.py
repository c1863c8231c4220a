"""``shapemotion serve export``: the answers in the database as the CSV ``analyze`` reads.

The rows have the columns the static jsPsych runtime writes for a trial (``participant``, ``list``,
the between groups, ``stimulus_id``, ``response``, ``rating``/``chosen`` …, plus ``session``), one row
per answered trial, so ``shapemotion analyze`` imports them as a jsPsych CSV. The sessions — status,
list, browser, clips that failed to load or play — go to ``<out>_sessions.csv`` beside it.

>>> from stimuli.serve.export import column_order
>>> column_order([{"b": 1, "rt": 2}, {"c": 3}])
['rt', 'b', 'c']
"""

from __future__ import annotations

import csv
import datetime
import io
import json
from pathlib import Path

from stimuli.fileio import atomic_write_text
from stimuli.serve.db import Database

FIRST = ["rt", "trial_type", "trial_index", "participant", "session", "list"]
# The fields of an answer row that belong to its trial (what a closing row leaves out).
TRIAL_KEYS = {"rt", "trial_type", "trial_index", "stimulus_id", "clip_id", "kind", "practice", "block", "block_label",
              "trial", "repetition", "left", "right", "positions", "response", "response_label", "rating", "chosen",
              "attention_check", "attention_answer", "attention_passed"}
SESSION_FIELDS = ["session", "participant", "list", "status", "answers", "started", "finished", "browser",
                  "failed_clips", "params"]


def column_order(rows: list[dict]) -> list[str]:
    """The export's columns: the jsPsych core fields first, then every other key in order of appearance."""
    seen = dict.fromkeys(c for c in FIRST if any(c in r for r in rows))
    for row in rows:
        seen.update(dict.fromkeys(row))
    return list(seen)


def export_csv(db: Database) -> str:
    """Every stored answer, one row each (quoted like jsPsych's own CSV); a finished session ends with
    the closing row (``end`` = 1) the static runtime writes, so ``analyze`` excludes unfinished ones."""
    finished = {s["id"] for s in db.sessions() if s["finished"] is not None}
    rows: list[dict] = []
    answers = db.answer_rows()
    for i, (sid, row) in enumerate(answers):
        rows.append(row)
        if sid in finished and (i + 1 == len(answers) or answers[i + 1][0] != sid):
            rows.append(closing_row(row))
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=column_order(rows), quoting=csv.QUOTE_ALL, lineterminator="\n",
                            restval="")
    writer.writeheader()
    writer.writerows(rows)
    return out.getvalue()


def closing_row(last: dict) -> dict:
    """The end screen's row after a session's last answer: its participant, list and groups, ``end`` = 1.

    >>> closing_row({"participant": "p1", "list": 2, "SEX": "F", "trial_index": 3, "stimulus_id": "x", "rt": 5})
    {'participant': 'p1', 'list': 2, 'SEX': 'F', 'trial_type': 'html-button-response', 'trial_index': 4, 'end': 1}
    """
    row = {k: v for k, v in last.items() if k not in TRIAL_KEYS}
    return row | {"trial_type": "html-button-response", "trial_index": last["trial_index"] + 1, "end": 1}


def sessions_csv(db: Database) -> str:
    """One row per session: its status, answers stored, browser and clips that failed."""
    counts = db.count_answers()
    failures: dict[str, list[str]] = {}
    for e in db.events():
        detail = json.loads(e["detail"])
        failures.setdefault(e["session"], []).append(f"{e['kind']}:{detail['clip']}")
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=SESSION_FIELDS, lineterminator="\n")
    writer.writeheader()
    for s in db.sessions():
        writer.writerow({"session": s["id"], "participant": s["participant"], "list": s["list"],
                         "status": "finished" if s["finished"] is not None else "not finished",
                         "answers": counts.get(s["id"], 0), "started": _iso(s["started"]),
                         "finished": _iso(s["finished"]), "browser": s["user_agent"],
                         "failed_clips": "|".join(failures.get(s["id"], [])), "params": s["params"]})
    return out.getvalue()


def sessions_path(out: Path) -> Path:
    """Where the sessions table goes: ``responses.csv`` → ``responses_sessions.csv``."""
    return out.with_name(f"{out.stem}_sessions{out.suffix or '.csv'}")


def write_export(db: Database, out: str | Path) -> tuple[Path, Path]:
    """Write the answers CSV and the sessions CSV (each written whole, then moved into place)."""
    out = Path(out)
    answers, sessions = export_csv(db), sessions_csv(db)
    atomic_write_text(out, answers)
    atomic_write_text(sessions_path(out), sessions)
    return out, sessions_path(out)


def _iso(t: float | None) -> str:
    if t is None:
        return ""
    return datetime.datetime.fromtimestamp(t, datetime.timezone.utc).isoformat(timespec="seconds")
