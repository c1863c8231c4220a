"""``shapemotion responses inspect``: what a response file is, before any design is involved.

A file whose header names a column twice is described (``repeated_columns``), not refused: inspecting is how
one finds out what is wrong with it; the import refuses it.

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
from analysis.responses.read import _participant_column, folder_entries, read_response_file, response_files


def inspect_file(path: str | Path) -> dict:
    """Format, number of responses (data rows), participants and every column with its question text.

    A folder is read as ``analyze`` reads it (:func:`inspect_folder`)."""
    if Path(path).is_dir():
        return inspect_folder(Path(path))
    return _inspect_one(Path(path))[0]


def inspect_folder(folder: Path) -> dict:
    """Every response file of a folder: per-file counts (``files``), totals, and the columns of all files.

    Participants are counted once across files, as the import keeps a participant found in several files once.
    """
    parts = [_inspect_one(f) for f in response_files(folder)]
    skipped = folder_entries(folder)[1]
    infos = [info for info, _ in parts]
    info = {"file": str(folder), "format": "+".join(sorted({i["format"] for i in infos})),
            "rows": sum(i["rows"] for i in infos), "responses": sum(i["responses"] for i in infos),
            "participants": len(set().union(*(ids for _, ids in parts))),
            "files": [{k: v for k, v in i.items() if k != "columns"} | {"file": Path(i["file"]).name} for i in infos],
            "skipped": skipped}
    if any("unfinished" in i for i in infos):
        info["unfinished"] = sum(i.get("unfinished", 0) for i in infos)
    columns: dict[str, dict] = {}
    for i in infos:
        for c in i["columns"]:
            columns.setdefault(c["name"], c | {"files": 0})["files"] += 1
    return info | {"columns": list(columns.values())}


def _inspect_one(path: Path) -> tuple[dict, set]:
    """:func:`inspect_file` of one file, and its participants (ids, or the file's rows where ids are unknown)."""
    raw = read_response_file(path, refuse_repeated=False)
    info = {"file": str(path), "format": raw.format, "rows": raw.n_rows}
    if raw.repeated:
        info["repeated_columns"] = raw.repeated
    if raw.format.startswith("qualtrics"):
        cols = classify_columns(raw, tags=None)
        kinds = {i: "metadata" for i in cols.metadata} | {i: "display order" for i in cols.display_order}
        kinds |= {i: "timing" for i in cols.timing} | {i: "question" for i in cols.unknown}
        kinds |= {i: "attention check" for i in cols.attention}
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
        return info, {(str(path), n) for n in raw.row_numbers}   # one respondent per row
    rows = raw.rows if raw.format == "jspsych-json" else [dict(zip(raw.columns, r)) for r in raw.rows]
    answers = [r for r in rows if str(r.get("stimulus_id") or "").strip()]
    pid = _participant_column(raw.columns)
    # without a participant column the file is one participant's data (jsPsych saves one file each)
    people = {str(r.get(pid)) for r in answers} if pid else ({str(path)} if answers else set())
    info |= {"responses": len(answers), "participants": len(people),
             "columns": [{"name": c, "kind": "column", "question_text": "", "import_id": ""} for c in raw.columns]}
    return info, people


def describe_text(info: dict) -> str:
    """The human-readable form of :func:`inspect_file`."""
    lines = [f"{'folder' if 'files' in info else 'file'}: {info['file']}"]
    if "files" in info:
        lines.append(f"files: {len(info['files'])}")
        lines += [f"  {f['file']}: {f['format']}; rows {f['rows']}, responses {f['responses']}, "
                  f"participants {f['participants']}" for f in info["files"]]
        if info.get("skipped"):
            lines.append(f"skipped (not read): {len(info['skipped'])}")
            lines += [f"  {s['name']}: {s['reason']}" for s in info["skipped"]]
        lines.append("total:")
    lines += [f"format: {info['format']}", f"rows: {info['rows']}", f"responses: {info['responses']}",
              f"participants: {info['participants']}"]
    repeated = info.get("repeated_columns") or [f"{f['file']}: {r}" for f in info.get("files", [])
                                                for r in f.get("repeated_columns", [])]
    if repeated:
        lines.append("repeated column names (the import refuses this file):")
        lines += [f"  {r}" for r in repeated]
    if "unfinished" in info:
        lines.append(f"unfinished (Finished = 0): {info['unfinished']}")
    lines.append("columns:")
    for c in info["columns"]:
        text = f" — {c['question_text'][:70]}" if c["question_text"] and c["question_text"] != c["name"] else ""
        only = f" (in {c['files']} of {len(info['files'])} files)" if c.get("files", 0) < len(info.get("files", [])) \
            else ""
        lines.append(f"  {c['name']} [{c['kind']}]{text}{only}")
    if "import" in info:
        imp = info["import"]
        reasons = ", ".join(f"{k}: {v}" for k, v in imp["excluded_by_reason"].items()) or "none"
        lines += [f"import against the design: {imp['imported_rows']} rows imported, {imp['excluded_rows']} excluded "
                  f"({reasons}); {imp['participants']} participants, {imp['answers']} test answers"]
        if imp.get("excluded_answers"):
            answers = ", ".join(f"{k}: {v}" for k, v in imp["answers_excluded_by_reason"].items())
            lines.append(f"answers excluded one by one (the rest of their row imported): {imp['excluded_answers']} "
                         f"({answers})")
        if imp["columns_not_imported"]:
            lines.append(f"columns not imported: {', '.join(imp['columns_not_imported'])}")
    return "\n".join(lines)
