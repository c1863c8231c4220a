"""Attention checks in jsPsych and Qualtrics data: who failed how many, and the exclusion the protocol asks for.

The jsPsych export (protocol ``attention_checks``) adds instructed-response rows marked
``attention_check = 1`` with the requested ``attention_answer`` and the button's ``response_label``.
The answer is judged here again from those two (ignoring case and spacing, as labels are matched
elsewhere), not from the page's own ``attention_passed``. A Qualtrics export's ``attention_check_<k>``
columns are turned into the same records (:func:`analysis.responses.qualtrics.qualtrics_attention`,
buttons from :func:`answer_buttons`) and judged here the same way. A participant who failed
``exclude_if_failed`` or more checks has every answer excluded with reason
:data:`FAILED_ATTENTION` (exclusions.csv says how many of how many were failed).

>>> rows = [{"participant": "1", "attention_check": "1", "attention_answer": "Neutral", "response_label": "neutral"},
...         {"participant": "2", "attention_check": "1", "attention_answer": "Neutral", "response_label": "Agree"},
...         {"participant": "2", "stimulus_id": "s1"}]
>>> attention_report(rows, ["1", "2", "2"]).to_dict("records")
[{'participant': '1', 'checks': 1, 'failed': 0}, {'participant': '2', 'checks': 1, 'failed': 1}]
"""

from __future__ import annotations

import pandas as pd

from analysis.responses.answers import Answer, Exclusion
from analysis.responses.read import cell_text

# exclusions.csv reason of an answer whose participant failed too many attention checks
FAILED_ATTENTION = "failed attention checks"
COLUMNS = ["participant", "checks", "failed"]


def _label(text: str) -> str:
    return " ".join(text.split()).casefold()


def answer_buttons(design) -> list[str]:
    """The buttons of a check (as of every answer): the Likert labels (``1``…``k`` without labels), else the
    screen positions' names — the design's ``position_labels``, else Left/Right for two, A, B, … for more
    (the survey export's rule, stimuli.protocol.position_labels_of).

    >>> from types import SimpleNamespace as D
    >>> answer_buttons(D(response_type="afc", labels=[], position_labels=[], k=2))
    ['Left', 'Right']
    """
    if design.response_type == "likert":
        return list(design.labels) or [str(i) for i in range(1, design.k + 1)]
    if design.position_labels:
        return list(design.position_labels)
    return ["Left", "Right"] if design.k == 2 else [chr(ord("A") + i) for i in range(design.k)]


def attention_report(records: list[dict], pids: list[str]) -> pd.DataFrame:
    """One row per participant with attention checks: ``checks`` shown and answered, ``failed``."""
    counts: dict[str, list[int]] = {}
    for record, pid in zip(records, pids):
        if cell_text(record.get("attention_check")) not in ("1", "true", "True"):
            continue
        asked, given = cell_text(record.get("attention_answer")), cell_text(record.get("response_label"))
        entry = counts.setdefault(pid, [0, 0])
        entry[0] += 1
        entry[1] += int(_label(given) != _label(asked))
    return pd.DataFrame([[pid, n, failed] for pid, (n, failed) in counts.items()], columns=COLUMNS)


def exclude_inattentive(answers: list[Answer], report: pd.DataFrame, limit: int | None
                        ) -> tuple[list[Answer], list[Exclusion]]:
    """Answers of participants below ``limit`` failed checks, and an exclusion for each answer of the others.

    >>> a = [Answer(5, "2", "s1", "3")]
    >>> kept, dropped = exclude_inattentive(a, pd.DataFrame([["2", 4, 1]], columns=COLUMNS), 1)
    >>> kept, dropped[0].reason, dropped[0].detail
    ([], 'failed attention checks', 'failed 1 of 4 attention checks; the protocol excludes a participant who fails 1 or more (attention_checks.exclude_if_failed)')
    """
    if not limit or report.empty:
        return answers, []
    failed = report.set_index("participant")
    out = {p: (int(r.failed), int(r.checks)) for p, r in failed.iterrows() if r.failed >= limit}
    kept = [a for a in answers if a.participant not in out]
    dropped = [Exclusion(a.row, a.participant, FAILED_ATTENTION,
                         f"failed {out[a.participant][0]} of {out[a.participant][1]} attention checks; the protocol "
                         f"excludes a participant who fails {limit} or more (attention_checks.exclude_if_failed)")
               for a in answers if a.participant in out]
    return kept, dropped
