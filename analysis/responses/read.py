"""Read a response file and tell which kind it is: Qualtrics (3-row or legacy 2-row), jsPsych CSV/JSON, long CSV.

Reading never guesses silently: a file that is binary, not UTF-8, empty or without a recognisable header,
that is no regular file (a FIFO, ``/dev/zero``) or is over the size limit (``io_files.MAX_INPUT_BYTES``), or
whose header names a column twice (a merge or a hand edit: one column's answers would replace the other's)
raises :class:`~analysis.errors.AnalysisError` naming the file and what was expected.

>>> import tempfile, pathlib
>>> p = pathlib.Path(tempfile.mkdtemp()) / "long.csv"
>>> _ = p.write_text("participant,stimulus_id,response\\n1,s1,3\\n")
>>> read_response_file(p).format
'long'
"""

from __future__ import annotations

import math

import csv
import io
import json
from dataclasses import dataclass, field
from pathlib import Path

from analysis.errors import AnalysisError
from analysis.io_files import read_input_bytes

# Columns Qualtrics writes before the questions (current names and the legacy V1…V10 names).
QUALTRICS_METADATA = {
    "StartDate", "EndDate", "Status", "IPAddress", "Progress", "Duration (in seconds)", "Finished",
    "RecordedDate", "ResponseId", "RecipientLastName", "RecipientFirstName", "RecipientEmail",
    "ExternalReference", "LocationLatitude", "LocationLongitude", "DistributionChannel", "UserLanguage",
    "ResponseID", "ResponseSet", "Name", "ExternalDataReference", "EmailAddress", "Q_TotalDuration",
    "Q_RecaptchaScore", "Q_RelevantIDDuplicate", "Q_RelevantIDDuplicateScore", "Q_RelevantIDFraudScore",
    "Q_RelevantIDLastStartDate", "Q_BallotBoxStuffing",
}
JSPSYCH_MARKERS = {"trial_type", "trial_index", "internal_node_id", "time_elapsed"}
PARTICIPANT_COLUMNS = ["participant", "participant_id", "PROLIFIC_PID", "workerId", "subject", "subject_id",
                       "run_id"]


@dataclass
class RawFile:
    """A response file split into its header and data records (lists of strings, or dicts for JSON).

    ``rows[i]`` carries its 1-based record number in the file (``row_numbers[i]``) so that every
    exclusion can name the row a spreadsheet shows.
    """

    path: Path
    format: str                   # qualtrics | qualtrics-legacy | jspsych-csv | jspsych-json | long
    columns: list[str]
    question_text: list[str] = field(default_factory=list)
    import_ids: list[dict] = field(default_factory=list)
    rows: list[list[str]] | list[dict] = field(default_factory=list)
    row_numbers: list[int] = field(default_factory=list)
    repeated: list[str] = field(default_factory=list)   # columns (JSON: keys) named twice, as messages

    @property
    def n_rows(self) -> int:
        return len(self.rows)


RESPONSE_SUFFIXES = (".csv", ".json")


def folder_entries(folder: Path) -> tuple[list[Path], list[dict]]:
    """The response files directly in ``folder`` (``*.csv``, ``*.json``, any case; by name) and everything else
    there, which is not read: ``[{"name": …, "reason": …}]`` — hidden files (``.DS_Store``), other files
    (``README.txt``) and subfolders, which are not searched (an ``analyze`` report folder inside would
    otherwise be read as responses). Callers list the skipped entries, so that nothing is dropped silently."""
    files, skipped = [], []
    for path in sorted(folder.iterdir(), key=lambda p: p.name):
        if path.name.startswith("."):
            skipped.append({"name": path.name + ("/" if path.is_dir() else ""), "reason": "hidden file"})
        elif path.is_dir():
            inside = sum(1 for q in path.rglob("*") if q.is_file() and q.suffix.lower() in RESPONSE_SUFFIXES)
            held = f"; it holds {inside} .csv/.json file{'s' if inside != 1 else ''}" if inside else ""
            skipped.append({"name": path.name + "/", "reason": f"subfolder: subfolders are not searched{held}"})
        elif path.is_file() and path.suffix.lower() in RESPONSE_SUFFIXES:
            files.append(path)
        else:
            skipped.append({"name": path.name, "reason": "not a .csv or .json file"
                            if path.is_file() else "not a regular file"})
    return files, skipped


def skipped_text(skipped: list[dict]) -> str:
    """``README.txt (not a .csv or .json file); sub/ (subfolder: …)``."""
    return "; ".join(f"{s['name']} ({s['reason']})" for s in skipped)


def response_files(folder: Path) -> list[Path]:
    """The response files of a folder (``*.csv``, ``*.json``; e.g. one jsPsych file per participant), by name.

    See :func:`folder_entries` for what is not read."""
    files, skipped = folder_entries(folder)
    if not files:
        also = f" (not read: {skipped_text(skipped)})" if skipped else ""
        hint = ("; move the files into the folder itself, or pass the subfolder that holds them"
                if any(s["name"].endswith("/") and "holds" in s["reason"] for s in skipped) else "")
        raise AnalysisError(f"{folder}: the folder holds no .csv or .json response file directly inside "
                            f"it{also}{hint}")
    return files


def read_response_file(path: str | Path, refuse_repeated: bool = True) -> RawFile:
    """Detect the format of ``path`` and split it into header and records.

    A column named twice is refused (``refuse_repeated``); ``responses inspect`` reads such a file to describe
    it and lists ``RawFile.repeated`` instead.
    """
    path = Path(path)
    text = _decode(path)
    stripped = text.lstrip()
    if not stripped:
        raise AnalysisError(f"{path}: the file is empty (expected a response export with a header row)")
    raw = _read_json(path, stripped) if stripped[0] in "[{" else _read_csv(path, text)
    if refuse_repeated and raw.repeated:
        more = f"; and {len(raw.repeated) - 3} more" if len(raw.repeated) > 3 else ""
        raise AnalysisError(f"{path}: {'; '.join(raw.repeated[:3])}{more}; a column named twice would have one "
                            f"column's answers replace the other's (a merge or a hand edit?): rename or remove one of "
                            f"them")
    return raw


def repeated_columns(columns: list[str]) -> list[str]:
    """Messages for the names that several columns share (1-based positions, as a spreadsheet counts), and for
    participant columns that differ only in case (the importer finds those case-insensitively).

    >>> for message in repeated_columns(["participant", "Q3_1", "rt", "Q3_1", "PARTICIPANT"]):
    ...     print(message)
    columns 2 and 4 are both named 'Q3_1'
    columns 1 and 5 ('participant' and 'PARTICIPANT') both name the participant
    """
    positions: dict[str, list[int]] = {}
    for i, name in enumerate(columns, 1):
        if name:   # a blank header names nothing the importer reads
            positions.setdefault(name, []).append(i)
    out = [f"columns {_and(where)} are {'both' if len(where) == 2 else 'all'} named {shown(name)}"
           for name, where in positions.items() if len(where) > 1]
    wanted = {c.lower() for c in PARTICIPANT_COLUMNS}
    by_case: dict[str, list[str]] = {}
    for name in positions:
        if name.lower() in wanted:
            by_case.setdefault(name.lower(), []).append(name)
    for names in by_case.values():
        if len(names) > 1:
            where = [positions[n][0] for n in names]
            out.append(f"columns {_and(where)} ({_and([shown(n) for n in names])}) both name the participant")
    return out


def _and(items: list) -> str:
    items = [str(i) for i in items]
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} and {items[-1]}"


def _decode(path: Path) -> str:
    data = read_input_bytes(path, "response file")
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise AnalysisError(f"{path}: the file is UTF-16 (Qualtrics' TSV export?); export the responses as CSV "
                            f"(UTF-8) instead")
    if data[:4] == b"PK\x03\x04" or b"\x00" in data[:4096]:
        raise AnalysisError(f"{path}: not a text file (a ZIP/XLSX or binary file?); expected a CSV or JSON export")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise AnalysisError(f"{path}: line {line}: not UTF-8 text (byte 0x{data[exc.start]:02x}); "
                            f"re-export the responses as UTF-8 CSV") from None


class _Object(dict):
    """A JSON object that remembers the keys it holds twice (``json.loads`` keeps the last value silently)."""

    repeated: list[str] = []


def _object(pairs: list[tuple]) -> dict:
    obj = _Object(pairs)
    if len(obj) < len(pairs):
        keys = [k for k, _ in pairs]
        obj.repeated = list(dict.fromkeys(k for k in keys if keys.count(k) > 1))
    return obj


def _repeated_keys(trial, number: int) -> list[str]:
    """Messages for the keys a trial object (or an object inside it, e.g. a survey ``response``) holds twice."""
    out = [f"trial {number} has the key {key!r} twice" for key in getattr(trial, "repeated", [])]
    values = trial.values() if isinstance(trial, dict) else trial if isinstance(trial, list) else []
    for value in values:
        if isinstance(value, (dict, list)):
            out += _repeated_keys(value, number)
    return out


def _read_json(path: Path, text: str) -> RawFile:
    try:
        data = json.loads(text, object_pairs_hook=_object)
    except json.JSONDecodeError as exc:
        raise AnalysisError(f"{path}: line {exc.lineno}: not valid JSON ({exc.msg})") from None
    except RecursionError:
        raise AnalysisError(f"{path}: JSON nested too deeply to be jsPsych data") from None
    if isinstance(data, dict):  # jsPsych's {"trials": [...]} or a single trial object
        data = data.get("trials", [data])
    if not isinstance(data, list) or not all(isinstance(x, dict) for x in data):
        raise AnalysisError(f"{path}: expected jsPsych JSON data: a list of trial objects")
    if not data:
        raise AnalysisError(f"{path}: the file holds no responses (an empty list of trials)")
    # every jsPsych trial carries trial_type, trial_index, … ; without them this is some other JSON file
    if not any(JSPSYCH_MARKERS & trial.keys() or "stimulus_id" in trial for trial in data):
        keys = list(dict.fromkeys(k for trial in data for k in trial))[:6]
        raise AnalysisError(f"{path}: not a jsPsych export: no trial has {sorted(JSPSYCH_MARKERS)} or stimulus_id "
                            f"(found keys {keys})")
    columns = list(dict.fromkeys(k for trial in data for k in trial))
    repeated = [m for number, trial in enumerate(data, 1) for m in _repeated_keys(trial, number)]
    return RawFile(path, "jspsych-json", columns, rows=data, row_numbers=list(range(1, len(data) + 1)),
                   repeated=repeated)


def _read_csv(path: Path, text: str) -> RawFile:
    try:
        records = list(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as exc:
        raise AnalysisError(f"{path}: not a readable CSV file ({exc})") from None
    header = [c.strip() for c in records[0]]
    names = set(header)
    if _is_qualtrics(header):
        raw = _qualtrics(path, header, records)
        raw.repeated = repeated_columns(raw.columns)
        return raw
    data = records[1:]
    numbers = list(range(2, len(records) + 1))
    repeated = repeated_columns(header)
    if names & JSPSYCH_MARKERS and ("response" in names or "button_pressed" in names):
        return RawFile(path, "jspsych-csv", header, rows=data, row_numbers=numbers, repeated=repeated)
    if {"stimulus_id", "response"} <= names and _participant_column(header):
        return RawFile(path, "long", header, rows=data, row_numbers=numbers, repeated=repeated)
    raise AnalysisError(
        f"{path}: no recognisable header row; expected a Qualtrics export (ResponseId, Finished, … then the "
        f"questions' export tags), jsPsych data (trial_type, response, stimulus_id, …) or a long CSV with "
        f"columns participant, stimulus_id, response; the first row is [{', '.join(shown(h) for h in header[:6])}]")


def _is_qualtrics(header: list[str]) -> bool:
    names = set(header)
    current = bool({"ResponseId", "ResponseID"} & names) or {"StartDate", "Finished"} <= names
    legacy = len(header) > 1 and header[0] == "V1" and header[1] == "V2"
    return current or legacy


def _qualtrics(path: Path, header: list[str], records: list[list[str]]) -> RawFile:
    if len(records) < 2:
        raise AnalysisError(f"{path}: a Qualtrics export needs at least its 2 header rows; found 1")
    second = records[1] + [""] * (len(header) - len(records[1]))
    third = records[2] if len(records) > 2 else []
    is_current = bool(third) and all(c.strip().startswith("{") for c in third if c.strip()) and any(third)
    if is_current:
        import_ids = [_import_id(path, c) for c in third] + [{}] * (len(header) - len(third))
        start, fmt = 3, "qualtrics"
    else:
        import_ids, start, fmt = [{} for _ in header], 2, "qualtrics-legacy"
    # Legacy exports name their metadata V1…V10 in row 1 and the real names in row 2.
    columns = [second[i].strip() if _is_v_name(h) and second[i].strip() else h for i, h in enumerate(header)]
    return RawFile(path, fmt, columns, question_text=[c.strip() for c in second[:len(header)]], import_ids=import_ids,
                   rows=records[start:], row_numbers=list(range(start + 1, len(records) + 1)))


def _is_v_name(name: str) -> bool:
    return len(name) > 1 and name[0] == "V" and name[1:].isdigit()


def _import_id(path: Path, cell: str) -> dict:
    if not cell.strip():
        return {}
    try:
        value = json.loads(cell)
    except json.JSONDecodeError:
        raise AnalysisError(f"{path}: row 3: {shown(cell)} is not the ImportId JSON Qualtrics writes "
                            f"(e.g. {{\"ImportId\":\"QID1\"}})") from None
    return value if isinstance(value, dict) else {}


def _participant_column(columns: list[str]) -> str | None:
    """The first column that names participants (``participant``, ``PROLIFIC_PID``, …)."""
    lower = {c.lower(): c for c in columns}
    return next((lower[c.lower()] for c in PARTICIPANT_COLUMNS if c.lower() in lower), None)


def shown(value, limit: int = 60) -> str:
    """A cell or header quoted for a message, cut to ``limit`` characters: a damaged cell may hold megabytes.

    >>> shown("Q3_1"), shown("x" * 100_000, 5)
    ("'Q3_1'", "'xxxxx…' (100,000 characters)")
    """
    text = str(value)
    return repr(text) if len(text) <= limit else f"{text[:limit] + '…'!r} ({len(text):,} characters)"


def cell_text(value) -> str:
    """A cell as stripped text: "" for missing/NaN, whole floats without ".0"."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    return str(value).strip()


def cell_number(value) -> float | None:
    """A cell as a finite number (None when it is not one: ``1e309`` is no trial number or repetition).

    >>> cell_number("2.0"), cell_number("fast"), cell_number("1e309"), cell_number(float("nan"))
    (2.0, None, None, None)
    """
    text = cell_text(value)
    try:
        number = float(text)
    except ValueError:
        return None
    return number if math.isfinite(number) else None
