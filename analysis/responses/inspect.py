"""``shapemotion responses inspect``: what a response file is, before any design is involved.

>>> import tempfile, pathlib
>>> p = pathlib.Path(tempfile.mkdtemp()) / "long.csv"
>>> _ = p.write_text("participant,stimulus_id,response\\n1,s1,3\\n2,s1,4\\n")
>>> info = inspect_file(p)
>>> info["format"], info["responses"], info["participants"]
('long', 2, 2)
"""

from __future__ import annotations

from pathlib import Path

from analysis.responses.qualtrics import UNFINISHED, classify_columns
from analysis.responses.read import _participant_column, read_response_file


def inspect_file(path: str | Path) -> dict:
    """Format, number of responses (data rows), participants and every column with its question text."""
    raw = read_response_file(path)
    info = {"file": str(path), "format": raw.format, "rows": raw.n_rows}
    if raw.format.startswith("qualtrics"):
        cols = classify_columns(raw, tags=None)
        kinds = {i: "metadata" for i in cols.metadata} | {i: "display order" for i in cols.display_order}
        kinds |= {i: "timing" for i in cols.timing} | {i: "question" for i in cols.unknown}
        # the current export marks questions by QID ImportIds; the legacy one cannot tell them apart
        embedded = "embedded data" if raw.format == "qualtrics" else "embedded data or question"
        kinds |= {i: embedded for i in cols.embedded}
        finished = raw.columns.index("Finished") if "Finished" in raw.columns else None
        unfinished = sum(1 for r in raw.rows if finished is not None and finished < len(r)
                         and r[finished].strip().lower() in UNFINISHED)
        info |= {"responses": raw.n_rows, "participants": raw.n_rows, "unfinished": unfinished,
                 "columns": [{"name": c, "kind": kinds.get(i, "?"),
                              "question_text": raw.question_text[i] if i < len(raw.question_text) else "",
                              "import_id": raw.import_ids[i].get("ImportId", "") if raw.import_ids else ""}
                             for i, c in enumerate(raw.columns)]}
        return info
    rows = raw.rows if raw.format == "jspsych-json" else [dict(zip(raw.columns, r)) for r in raw.rows]
    answers = [r for r in rows if str(r.get("stimulus_id") or "").strip()]
    pid = _participant_column(raw.columns)
    # without a participant column the file is one participant's data (jsPsych saves one file each)
    people = len({str(r.get(pid)) for r in answers}) if pid else int(bool(answers))
    info |= {"responses": len(answers), "participants": people,
             "columns": [{"name": c, "kind": "column", "question_text": "", "import_id": ""} for c in raw.columns]}
    return info


def describe_text(info: dict) -> str:
    """The human-readable form of :func:`inspect_file`."""
    lines = [f"file: {info['file']}", f"format: {info['format']}", f"rows: {info['rows']}",
             f"responses: {info['responses']}", f"participants: {info['participants']}"]
    if "unfinished" in info:
        lines.append(f"unfinished (Finished = 0): {info['unfinished']}")
    lines.append("columns:")
    for c in info["columns"]:
        text = f" — {c['question_text'][:70]}" if c["question_text"] and c["question_text"] != c["name"] else ""
        lines.append(f"  {c['name']} [{c['kind']}]{text}")
    if "import" in info:
        imp = info["import"]
        reasons = ", ".join(f"{k}: {v}" for k, v in imp["excluded_by_reason"].items()) or "none"
        lines += [f"import against the design: {imp['imported_rows']} rows imported, {imp['excluded_rows']} excluded "
                  f"({reasons}); {imp['participants']} participants, {imp['answers']} test answers"]
        if imp["columns_not_imported"]:
            lines.append(f"columns not imported: {', '.join(imp['columns_not_imported'])}")
    return "\n".join(lines)
