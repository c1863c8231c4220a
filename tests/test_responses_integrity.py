"""Response imports that never silently corrupt data (issue 26, items 1, 6 and the response parts of 9).

- a repeated column header (a merge, a hand edit) is refused in every format, naming both columns;
- one bad cell of a Qualtrics export excludes that answer, not the respondent (as jsPsych excludes one row);
- a jsPsych ``rt`` that is no time, a missing participant column, a missing cell's column, and files that are
  not regular files or are too large are each named, never a traceback, a hang or a misleading message.
"""

from __future__ import annotations

import csv
import io
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from analysis.errors import AnalysisError
from analysis.io_design import load_design
from analysis.io_writers import export_text
from analysis.model_spec import load_model
from analysis.responses import import_responses, read_response_file
from analysis.responses.inspect import describe_text, inspect_file
from analysis.simulate import simulate_responses

DATA = Path(__file__).parent / "data" / "responses"


@pytest.fixture(scope="module")
def likert():
    design = load_design(DATA / "mini_likert")
    sim = simulate_responses(design, load_model(None, design), participants=6, seed=2)
    return design, sim


def _rows(text: str) -> list[list[str]]:
    return list(csv.reader(io.StringIO(text)))


def _write(path: Path, rows: list[list[str]]) -> Path:
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="\n").writerows(rows)
    path.write_text(buffer.getvalue(), encoding="utf-8")
    return path


def _export(likert, fmt: str) -> list[list[str]]:
    design, sim = likert
    return _rows(export_text(sim, design, fmt, seed=2))


# -- item 1: a repeated column header -------------------------------------------------------------------------

def test_qualtrics_export_with_a_stimulus_column_twice_is_refused(likert, tmp_path, run_cli):
    """The second copy used to replace the first column's answers: "6 imported, 0 excluded", exit 0."""
    rows = _export(likert, "qualtrics")
    col = rows[0].index("F-walk-Hi1_r1")
    # a merge appended another copy of the column, with other answers in it
    merged = [r + [r[col]] for r in rows[:3]] + [r + ["Very Inconsistent" if r[col] else ""] for r in rows[3:]]
    path = _write(tmp_path / "merged.csv", merged)
    with pytest.raises(AnalysisError) as err:
        import_responses(path, likert[0])
    message = str(err.value)
    assert "merged.csv" in message
    assert f"columns {col + 1} and {len(rows[0]) + 1} are both named 'F-walk-Hi1_r1'" in message
    code, _, stderr = run_cli("analyze", DATA / "mini_likert", "--responses", path, "--out", tmp_path / "report")
    assert code == 2 and "both named 'F-walk-Hi1_r1'" in _said(stderr) and "Traceback" not in stderr
    assert not (tmp_path / "report").exists()
    # inspect, which describes a file before any import, says so instead of listing the tag twice silently
    info = inspect_file(path)
    assert info["repeated_columns"] == [f"columns {col + 1} and {len(rows[0]) + 1} are both named 'F-walk-Hi1_r1'"]
    assert "repeated column names (the import refuses this file):" in describe_text(info)
    code, out, stderr = run_cli("responses", "inspect", path, "--design", DATA / "mini_likert")
    assert code == 2 and "both named 'F-walk-Hi1_r1'" in _said(stderr)


def test_qualtrics_columns_naming_one_stimulus_and_repetition_are_refused(likert, tmp_path):
    """Two different tags that both read as F-walk-Hi1 repetition 1 (case and punctuation aside)."""
    rows = _export(likert, "qualtrics")
    col = rows[0].index("F-walk-Hi1_r1")
    rows = [r + [r[col]] for r in rows]
    rows[0][-1] = "f_walk_hi1_r1"
    with pytest.raises(AnalysisError) as err:
        import_responses(_write(tmp_path / "q.csv", rows), likert[0])
    assert f"columns {col + 1} and {len(rows[0])} ('F-walk-Hi1_r1' and 'f_walk_hi1_r1')" in str(err.value)
    assert "repetition 1 of stimulus 'F-walk-Hi1'" in str(err.value)


def test_long_csv_with_a_second_response_column_is_refused(likert, tmp_path):
    """All ratings used to come from the second column (every rating 1), exit 0."""
    rows = _export(likert, "long")
    rows = [rows[0] + ["response"]] + [r + ["1"] for r in rows[1:]]
    with pytest.raises(AnalysisError) as err:
        import_responses(_write(tmp_path / "long.csv", rows), likert[0])
    position = rows[0].index("response") + 1
    assert "long.csv" in str(err.value)
    assert f"columns {position} and {len(rows[0])} are both named 'response'" in str(err.value)


def test_jspsych_csv_and_json_with_a_repeated_column_or_key_are_refused(likert, tmp_path):
    rows = _export(likert, "jspsych")
    doubled = [rows[0] + ["participant"]] + [r + ["99"] for r in rows[1:]]
    first, second = rows[0].index("participant") + 1, len(doubled[0])
    with pytest.raises(AnalysisError, match=f"columns {first} and {second} are both named 'participant'"):
        import_responses(_write(tmp_path / "j.csv", doubled), likert[0])
    trials = [dict(zip(rows[0], r)) for r in rows[1:]]
    text = json.dumps(trials)
    # a JSON object with a key twice: json.loads keeps the last one silently
    text = text.replace('"response": ', '"response": "4", "response": ', 1)
    (tmp_path / "j.json").write_text(text)
    with pytest.raises(AnalysisError) as err:
        import_responses(tmp_path / "j.json", likert[0])
    assert "j.json" in str(err.value) and "trial 1 has the key 'response' twice" in str(err.value)


def test_a_participant_column_twice_in_other_case_is_refused(likert, tmp_path):
    rows = _export(likert, "long")
    rows = [rows[0] + ["Participant"]] + [r + ["7"] for r in rows[1:]]
    match = rf"columns 1 and {len(rows[0])} \('participant' and 'Participant'\) both name the participant"
    with pytest.raises(AnalysisError, match=match):
        import_responses(_write(tmp_path / "long.csv", rows), likert[0])


# -- item 6: one bad cell excludes the answer, not the respondent ----------------------------------------------

BAD_CELLS = ["6", "0", "-1", "99"]


def _answered_columns(rows, record, test_only=False):
    """The question columns (test clips, and practice clips unless ``test_only``) answered in ``record``."""
    kinds = ("F-", "M-") if test_only else ("F-", "M-", "practice-")
    return [i for i, name in enumerate(rows[0]) if name.startswith(kinds) and record[i]]


def _said(text: str) -> str:
    """CLI output with its line wrapping undone."""
    return " ".join(text.split())


def test_one_bad_likert_cell_excludes_that_answer_not_the_respondent(likert, tmp_path):
    """6, 0, −1 and 99 in one cell each of 4 respondents: all 4 respondents used to be excluded (their 64 test
    answers lost, the groups unbalanced) while the same faults in jsPsych excluded 4 answers."""
    design, sim = likert
    rows = _export(likert, "qualtrics-numeric")
    changed = {}
    for value, record in zip(BAD_CELLS, rows[3:7]):
        col = _answered_columns(rows, record, test_only=True)[1]
        record[col] = value
        changed[rows[0][col]] = value
    result = import_responses(_write(tmp_path / "q.csv", rows), design)
    assert result.reconciles and result.n_excluded_rows == 0
    assert result.data["participant"].nunique() == 6
    answers = result.exclusions[result.exclusions["scope"] == "answer"]
    assert len(answers) == 4 and set(answers["reason"]) == {"answer outside the scale"}
    assert dict(zip(answers["column"], [d.split("'")[1] for d in answers["detail"]])) == changed
    assert answers["row"].tolist() == [4, 5, 6, 7]
    assert len(result.data) == len(sim) - 4
    summary = result.summary()
    assert summary["excluded_answers"] == 4 and summary["answers_excluded_by_reason"] == {
        "answer outside the scale": 4}
    assert summary["excluded_by_reason"] == {}
    # each answered cell is either imported or listed
    for number, record in zip(range(4, len(rows) + 1), rows[3:]):
        given = len(_answered_columns(rows, record))
        kept = int((result.data["row"] == number).sum())
        assert given == kept + int((answers["row"] == number).sum())

    # the same four faults in jsPsych: four answers (rows) excluded, as before
    jrows = _export(likert, "jspsych")
    response, sid = jrows[0].index("response"), jrows[0].index("stimulus_id")
    answer_rows = [r for r in jrows[1:] if r[sid]]
    for value, record in zip(["5", "-1", "-2", "98"], answer_rows[::13][:4]):   # 0-based buttons: 6, 0, −1, 99
        record[response] = value
    jresult = import_responses(_write(tmp_path / "j.csv", jrows), design)
    assert (jresult.exclusions["reason"] == "answer outside the scale").sum() == 4
    assert len(jresult.data) == len(result.data)


def test_a_respondent_whose_bad_cells_empty_a_design_cell_is_excluded_naming_that_cells_columns(likert, tmp_path):
    """Both answers of one cell unusable: the respondent lacks the cell and is excluded as "missing cells"; the
    exclusion used to name the first column the respondent answered, which is not the missing cell's."""
    design, _ = likert
    rows = _export(likert, "qualtrics-numeric")
    record = rows[3]
    cols = _answered_columns(rows, record, test_only=True)
    first = rows[0][cols[0]]                      # e.g. F-walk-Hi1_r1
    pair = [c for c in cols if rows[0][c].rsplit("_", 1)[0] == first.rsplit("_", 1)[0]]
    record[pair[0]], record[pair[1]] = "", "99"
    result = import_responses(_write(tmp_path / "q.csv", rows), design)
    assert result.reconciles
    mine = result.exclusions[result.exclusions["row"] == 4]
    whole = mine[mine["scope"] == "row"].iloc[0]
    assert whole["reason"] == "missing cells"
    assert whole["column"] == ", ".join(rows[0][c] for c in pair)
    assert "1 answer there excluded (answer outside the scale)" in whole["detail"]
    assert mine[mine["scope"] == "answer"]["column"].tolist() == [rows[0][pair[1]]]
    assert 4 not in set(result.data["row"])


def test_every_answer_of_a_respondent_bad_is_no_valid_answers(likert, tmp_path):
    rows = _export(likert, "qualtrics-numeric")
    for col in _answered_columns(rows, rows[3]):
        rows[3][col] = "99"
    result = import_responses(_write(tmp_path / "q.csv", rows), likert[0])
    assert result.reconciles
    whole = result.exclusions[(result.exclusions["row"] == 4) & (result.exclusions["scope"] == "row")]
    assert whole[["reason"]].values.tolist() == [["no valid answers"]]
    assert "all 9 answers of the row are excluded" in whole["detail"].iloc[0]


def test_long_format_missing_cell_names_the_stimulus_column(likert, tmp_path):
    rows = _export(likert, "long")
    sid = rows[0].index("stimulus_id")
    gone = [r for r in rows[1:] if r[0] == "1" and r[sid].startswith(("F-walk-Hi1", "M-walk-Hi1"))]
    rows = [r for r in rows if not any(r is g for g in gone)]
    result = import_responses(_write(tmp_path / "long.csv", rows), likert[0])
    missing = result.exclusions[result.exclusions["reason"] == "missing cells"]
    assert len(missing) and set(missing["column"]) == {"stimulus_id"}


# -- item 9: rt, the participant column, files that are not files ---------------------------------------------

@pytest.mark.parametrize("rt", ["fast", "-5", "inf"])
def test_jspsych_rt_that_is_not_a_time_excludes_that_answer(likert, tmp_path, rt):
    rows = _export(likert, "jspsych")
    sid, rt_col = rows[0].index("stimulus_id"), rows[0].index("rt")
    number, record = next((n, r) for n, r in enumerate(rows[1:], 2) if r[sid] and not r[sid].startswith("practice"))
    record[rt_col] = rt
    result = import_responses(_write(tmp_path / "j.csv", rows), likert[0])
    assert result.reconciles
    row = result.exclusions[result.exclusions["row"] == number].iloc[0]
    assert (row["reason"], row["column"]) == ("malformed row", "rt")
    assert f"column 'rt' is {rt!r}" in row["detail"] and "milliseconds" in row["detail"]
    assert number not in set(result.data["row"])


def test_jspsych_rt_missing_or_null_is_accepted(likert, tmp_path):
    rows = _export(likert, "jspsych")
    sid, rt_col = rows[0].index("stimulus_id"), rows[0].index("rt")
    for value, record in zip(["", "null"], [r for r in rows[1:] if r[sid]][:2]):
        record[rt_col] = value
    result = import_responses(_write(tmp_path / "j.csv", rows), likert[0])
    assert "malformed row" not in set(result.exclusions["reason"]) and result.data["rt"].isna().sum() == 2


def test_jspsych_file_without_a_participant_column_but_several_runs_is_refused(likert, tmp_path, run_cli):
    """It used to be read as one participant (the file name) who ran the experiment 6 times; the report then
    said "the responses hold only SEX = M"."""
    rows = _export(likert, "jspsych")
    pid = rows[0].index("participant")
    path = _write(tmp_path / "all.csv", [r[:pid] + r[pid + 1:] for r in rows])
    with pytest.raises(AnalysisError) as err:
        import_responses(path, likert[0])
    message = str(err.value)
    assert "all.csv" in message and "no participant column" in message and "6 runs" in message
    code, _, stderr = run_cli("analyze", DATA / "mini_likert", "--responses", path, "--out", tmp_path / "r")
    assert code == 2 and "no participant column" in _said(stderr) and "hold only" not in stderr


def test_one_participants_jspsych_file_without_participant_column_still_imports(likert, tmp_path):
    rows = _export(likert, "jspsych")
    pid = rows[0].index("participant")
    mine = [rows[0]] + [r for r in rows[1:] if r[pid] == "1"]
    result = import_responses(_write(tmp_path / "p1.csv", [r[:pid] + r[pid + 1:] for r in mine]), likert[0])
    assert set(result.data["participant"]) == {"p1"} and result.reconciles


def _alarm(seconds: int):
    def fail(*_):
        raise TimeoutError(f"the import hung for {seconds} s")
    signal.signal(signal.SIGALRM, fail)
    signal.alarm(seconds)


def test_non_regular_files_are_refused_before_reading(likert, tmp_path, run_cli):
    """/dev/zero gave a MemoryError traceback; a FIFO hung the import."""
    # in a child process whose memory is capped: a regression fails fast instead of filling this machine's memory
    code = ("import resource, sys; resource.setrlimit(resource.RLIMIT_AS, (1 << 31, 1 << 31));"
            "from stimuli.cli import main; sys.exit(main(['responses', 'inspect', '/dev/zero']))")
    child = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                           cwd=Path(__file__).resolve().parents[1])
    assert child.returncode == 2 and "Traceback" not in child.stderr
    assert "/dev/zero: not a regular file (a character device)" in _said(child.stderr)
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    _alarm(10)
    try:
        with pytest.raises(AnalysisError, match=r"pipe.csv: not a regular file \(a FIFO"):
            read_response_file(fifo)
        code, _, stderr = run_cli("responses", "inspect", fifo)
    finally:
        signal.alarm(0)
    assert code == 2 and "not a regular file" in _said(stderr) and "Traceback" not in stderr


def test_files_over_the_size_limit_are_refused(likert, tmp_path, monkeypatch):
    import analysis.io_files as io_files
    path = _write(tmp_path / "long.csv", _export(likert, "long"))
    monkeypatch.setattr(io_files, "MAX_INPUT_BYTES", 1000)
    with pytest.raises(AnalysisError) as err:
        import_responses(path, likert[0])
    assert "long.csv" in str(err.value) and "over the limit of 1,000 bytes" in str(err.value)
    assert f"{path.stat().st_size:,} bytes" in str(err.value)


# -- found by tests/test_responses_fuzz.py --------------------------------------------------------------------

def test_a_trial_number_too_large_for_a_float_is_no_trial_number(likert, tmp_path):
    """``trial`` = 1e309 is infinite as a float: int() of it raised OverflowError (a traceback)."""
    rows = _export(likert, "jspsych")
    sid, trial = rows[0].index("stimulus_id"), rows[0].index("trial")
    next(r for r in rows[1:] if r[sid])[trial] = "1e309"
    result = import_responses(_write(tmp_path / "j.csv", rows), likert[0])
    assert result.reconciles and len(result.data) == len(likert[1])


def test_a_huge_cell_is_cut_in_the_error_message(likert, tmp_path):
    """A 100,000-character protocol cell used to be repeated whole (twice) in the one-line error."""
    rows = _export(likert, "long")
    rows = [rows[0] + ["shapemotion_protocol"]] + [r + ["mini_likert"] for r in rows[1:]]
    rows[3][-1] = "x" * 100_000
    with pytest.raises(AnalysisError) as err:
        import_responses(_write(tmp_path / "long.csv", rows), likert[0])
    assert "(100,000 characters)" in str(err.value) and len(str(err.value)) < 1000


def test_analyze_reports_the_answers_excluded_one_by_one(likert, tmp_path, run_cli):
    """The printed counts, summary.json, exclusions.csv and report.html agree on the single answers left out."""
    rows = _export(likert, "qualtrics-numeric")
    for value, record in zip(["6", "0"], rows[3:5]):
        record[_answered_columns(rows, record, test_only=True)[0]] = value
    path = _write(tmp_path / "q.csv", rows)
    code, out, err = run_cli("analyze", DATA / "mini_likert", "--responses", path, "--out", tmp_path / "report",
                             "--no-models")
    assert code == 0, err
    assert "6 rows: 6 imported, 0 excluded" in _said(out)
    assert "answers excluded one by one (the rest of their row imported): 2 (answer outside the scale: 2)" in _said(out)
    summary = json.loads((tmp_path / "report" / "summary.json").read_text())["import"]
    assert (summary["excluded_answers"], summary["participants"]) == (2, 6)
    excluded = pd.read_csv(tmp_path / "report" / "exclusions.csv", dtype=str, keep_default_na=False)
    assert excluded[["row", "scope", "reason"]].values.tolist() == [["4", "answer", "answer outside the scale"],
                                                                   ["5", "answer", "answer outside the scale"]]
    html = (tmp_path / "report" / "report.html").read_text(encoding="utf-8")
    assert "2 single answers were excluded one by one" in _said(html)
