"""Property-based test of the response import: corrupted exports either stop with AnalysisError (the exit-2 path)
or import cleanly with every row and answer accounted for — never another exception.

The valid exports are built once per module: the tool's own simulated exports of the two mini designs in every
format (Qualtrics choice text, numeric, legacy; jsPsych CSV and JSON; long) and the hand-written files of
tests/data/responses/. Each example damages one of them in memory (repeated headers, bad cells, truncated or
extended rows, other encodings, shuffled, extra or dropped columns, blank lines, huge values, a cut file) and
imports it from a temporary file. 400 + 100 examples run in well under 30 s.
"""

from __future__ import annotations

import csv
import io
import json
import random
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from analysis.errors import AnalysisError
from analysis.io_design import load_design
from analysis.io_writers import export_text
from analysis.model_spec import load_model
from analysis.responses import import_responses
from analysis.responses.read import read_response_file
from analysis.simulate import simulate_responses

DATA = Path(__file__).parent / "data" / "responses"
HAND_WRITTEN = {"qualtrics_likert_text.csv": "mini_likert", "qualtrics_likert_numeric.csv": "mini_likert",
                "qualtrics_legacy.csv": "mini_likert", "qualtrics_corrupt.csv": "mini_likert",
                "jspsych_likert.csv": "mini_likert", "qualtrics_afc_text.csv": "mini_afc", "long_afc.csv": "mini_afc"}
CSV_FORMATS = ["qualtrics", "qualtrics-numeric", "qualtrics-legacy", "jspsych", "long"]

# cell values a damaged export holds: outside the scale, not numbers, no times, empty, JSON fragments, huge
BAD_VALUES = ["6", "0", "-1", "99", "", " ", "fast", "-5", "1e309", "NaN", "inf", "3.5", "True", "null",
              "Left", "C", "[1, 2", '{"Q0": 99}', "１", "Sehr stimmig", "a" * 5000, "9" * 400, "\u202e5"]
COLUMN_NAMES = ["comment", "Q_new", "response", "participant", "Participant", "rt", "stimulus_id", "", "SEX",
                "trial_index", "Finished", "F-walk-Hi1_r1", "walk-Hi1-NoCOM_COM"]
CSV_DAMAGE = ["cell", "cell", "cell", "truncate_row", "extend_row", "drop_row", "duplicate_row", "repeat_header",
              "extra_column", "drop_column", "shuffle_columns", "rename_column", "blank_lines", "huge_cell"]
TEXT_DAMAGE = ["none", "none", "none", "latin1", "utf16", "cp1252", "bad_byte", "cut", "nul", "crlf", "bom"]


@pytest.fixture(scope="module")
def designs():
    return {name: load_design(DATA / name) for name in ("mini_likert", "mini_afc")}


@pytest.fixture(scope="module")
def exports(designs):
    """(name, design name, text) of every valid export the damage starts from."""
    out = []
    for name, design in designs.items():
        sim = simulate_responses(design, load_model(None, design), participants=4, seed=5)
        out += [(f"{name}-{fmt}.csv", name, export_text(sim, design, fmt, seed=5)) for fmt in CSV_FORMATS]
        out.append((f"{name}-jspsych.json", name, export_text(sim, design, "jspsych", path_suffix=".json", seed=5)))
    out += [(file, design, (DATA / file).read_text(encoding="utf-8-sig")) for file, design in HAND_WRITTEN.items()]
    return out


def _damage_rows(rows: list[list[str]], edits, rng: random.Random) -> list[list[str]]:
    """Apply the CSV-level damage; ``edits`` are (kind, a, b) with a, b arbitrary non-negative integers."""
    rows = [list(r) for r in rows]
    for kind, a, b in edits:
        width = max(len(rows[0]), 1)
        body = range(1, len(rows)) if len(rows) > 1 else range(0, 1)
        i, j = body[a % len(body)], b % width
        if kind in ("cell", "huge_cell"):
            if j < len(rows[i]):
                rows[i][j] = rng.choice(BAD_VALUES) if kind == "cell" else "x" * 200_000
        elif kind == "truncate_row":
            rows[i] = rows[i][:j]
        elif kind == "extend_row":
            rows[i] = rows[i] + [rng.choice(BAD_VALUES)] * (1 + b % 3)
        elif kind == "drop_row" and len(rows) > 2:
            rows.pop(i)
        elif kind == "duplicate_row":
            rows.insert(i, list(rows[i]))
        elif kind == "repeat_header":   # a merge: a copy of column j appended, with other answers
            rows = [r + [(r[j] if n == 0 or rng.random() < .5 else rng.choice(BAD_VALUES)) if j < len(r) else ""]
                    for n, r in enumerate(rows)]
        elif kind == "extra_column":
            name = rng.choice(COLUMN_NAMES)
            rows = [r[:j] + [name if n == 0 else rng.choice(BAD_VALUES)] + r[j:] for n, r in enumerate(rows)]
        elif kind == "drop_column":
            rows = [r[:j] + r[j + 1:] for r in rows]
        elif kind == "shuffle_columns":
            order = list(range(width))
            rng.shuffle(order)
            rows = [[r[k] for k in order if k < len(r)] for r in rows]
        elif kind == "rename_column" and j < len(rows[0]):
            rows[0][j] = rng.choice(COLUMN_NAMES)
        elif kind == "blank_lines":
            rows.insert(i, [])
    return rows


def _to_bytes(text: str, kind: str, position: int) -> bytes:
    """Encode the file as a damaged export might be: another encoding, a bad byte, cut short, a NUL."""
    if kind == "latin1":
        return text.encode("latin-1", errors="replace")
    if kind == "utf16":
        return text.encode("utf-16")
    if kind == "cp1252":
        return text.encode("cp1252", errors="replace")
    data = text.encode("utf-8")
    at = position % max(len(data), 1)
    if kind == "bad_byte":
        return data[:at] + b"\xff" + data[at + 1:]
    if kind == "cut":
        return data[:at]
    if kind == "nul":
        return data[:at] + b"\x00" + data[at:]
    if kind == "crlf":
        return data.replace(b"\n", b"\r\n")
    if kind == "bom":
        return b"\xef\xbb\xbf" + data
    return data


def _question_columns(result, raw, design) -> list[int]:
    """Indices of a Qualtrics export's columns that hold answers (those matched to stimuli, less the columns
    listed as not imported)."""
    from analysis.responses import _tag_index
    from analysis.responses.qualtrics import classify_columns
    noted = set(result.exclusions.loc[result.exclusions["scope"] == "column", "column"])
    cols = classify_columns(raw, _tag_index(design))
    return [i for i in cols.questions if raw.columns[i] not in noted]


def check_import(path: Path, design) -> None:
    """Import ``path``: an AnalysisError is fine (exit 2, nothing written); a result must account for every row
    and answer; anything else fails the test."""
    try:
        result = import_responses(path, design)
    except AnalysisError as exc:
        assert str(exc).strip() and len(str(exc)) < 2_000, "an error message should be short and name the file"
        assert path.name in str(exc)
        return
    assert result.reconciles, result.summary()
    rows = result.excluded_rows["row"].astype(int)
    assert rows.is_unique and not set(rows) & set(result.data["row"].astype(int))
    answers = result.excluded_answers
    assert set(answers["row"].astype(int)) <= set(result.data["row"].astype(int)) | set(rows)
    raw = read_response_file(path)
    if not raw.format.startswith("qualtrics"):
        assert answers.empty and result.data["row"].is_unique   # one answer per row
        return
    questions = _question_columns(result, raw, design)
    imported = result.data["row"].value_counts()
    listed = answers["row"].value_counts()
    for number, record in zip(raw.row_numbers, raw.rows):
        if number in imported.index:   # an imported respondent: each answered cell imported or listed
            given = sum(1 for i in questions if record[i].strip())
            assert given == imported[number] + listed.get(number, 0), (number, given)


def _repeated(rows: list[list[str]]) -> bool:
    names = [c.strip() for c in rows[0] if c.strip()] if rows else []
    return len(names) != len(set(names))


@settings(max_examples=400, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(which=st.integers(0, 10_000), seed=st.integers(0, 2**16),
       edits=st.lists(st.tuples(st.sampled_from(CSV_DAMAGE), st.integers(0, 10_000), st.integers(0, 10_000)),
                      min_size=1, max_size=4),
       text_damage=st.sampled_from(TEXT_DAMAGE), position=st.integers(0, 10**6))
def test_damaged_csv_exports_are_refused_or_reconcile(designs, exports, tmp_path_factory, which, seed, edits,
                                                      text_damage, position):
    csv_exports = [e for e in exports if e[0].endswith(".csv")]
    name, design_name, text = csv_exports[which % len(csv_exports)]
    rows = _damage_rows(list(csv.reader(io.StringIO(text, newline=""))), edits, random.Random(seed))
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="\n").writerows(rows)
    path = tmp_path_factory.mktemp("fuzz") / name
    path.write_bytes(_to_bytes(buffer.getvalue(), text_damage, position))
    legacy = "legacy" in name
    if _repeated(rows) and not legacy and text_damage in ("none", "crlf", "bom"):
        # a column named twice is never imported, whatever else the file has
        with pytest.raises(AnalysisError):
            import_responses(path, designs[design_name])
        return
    check_import(path, designs[design_name])


JSON_VALUES = [None, "", "fast", -5, 1e308, "99", 99, [1, 2], {"Q0": 99}, True, "x" * 5000, {"a": {"b": []}}]


@settings(max_examples=100, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(which=st.integers(0, 10_000), seed=st.integers(0, 2**16),
       edits=st.lists(st.tuples(st.sampled_from(["value", "drop_key", "drop_trial", "repeat_key", "not_object",
                                                 "wrap", "cut"]),
                                st.integers(0, 10_000), st.integers(0, 10_000)), min_size=1, max_size=4))
def test_damaged_jspsych_json_is_refused_or_reconciles(designs, exports, tmp_path_factory, which, seed, edits):
    json_exports = [e for e in exports if e[0].endswith(".json")]
    name, design_name, text = json_exports[which % len(json_exports)]
    trials, rng = json.loads(text), random.Random(seed)
    wrap, cut, repeat = False, None, None
    for kind, a, b in edits:
        if not trials:
            break
        i = a % len(trials)
        keys = list(trials[i]) if isinstance(trials[i], dict) else []
        key = keys[b % len(keys)] if keys else None
        if kind == "value" and key:
            trials[i][key] = rng.choice(JSON_VALUES)
        elif kind == "drop_key" and key:
            del trials[i][key]
        elif kind == "drop_trial":
            trials.pop(i)
        elif kind == "repeat_key" and key:
            repeat = key
        elif kind == "not_object":
            trials[i] = rng.choice(JSON_VALUES)
        elif kind == "wrap":
            wrap = True
        elif kind == "cut":
            cut = b
    out = json.dumps({"trials": trials} if wrap else trials)
    if repeat:   # a key written twice in one trial object (json.loads would keep the last silently)
        out = out.replace(f'"{repeat}": ', f'"{repeat}": "1", "{repeat}": ', 1)
    if cut is not None:
        out = out[:cut % max(len(out), 1)]
    path = tmp_path_factory.mktemp("fuzzj") / name
    path.write_text(out, encoding="utf-8")
    check_import(path, designs[design_name])
