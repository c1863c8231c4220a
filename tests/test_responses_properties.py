"""Property tests of the importer: whatever damage a file has, every row is imported or excluded exactly once,
and every imported participant has every design cell."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from analysis.io_design import load_design
from analysis.io_writers import export_text
from analysis.model_spec import load_model
from analysis.responses import import_responses
from analysis.simulate import simulate_responses

DATA = Path(__file__).parent / "data" / "responses"
DAMAGE = ["drop", "garbage", "duplicate", "unknown", "blank_participant", "short"]


@pytest.fixture(scope="module")
def clean():
    design = load_design(DATA / "mini_afc")
    sim = simulate_responses(design, load_model(None, design), participants=6, seed=1)
    rows = list(csv.reader(io.StringIO(export_text(sim, design, "long"))))
    return design, rows


def _damage(rows, edits):
    header, body = rows[0], [list(r) for r in rows[1:]]
    response = header.index("response")
    for kind, index in edits:
        if not body:
            break
        i = index % len(body)
        if kind in ("garbage", "unknown", "blank_participant") and len(body[i]) < len(header):
            continue  # a truncated row has no such cell any more
        if kind == "drop":
            body.pop(i)
        elif kind == "garbage":
            body[i][response] = "maybe"
        elif kind == "duplicate":
            body.insert(i, list(body[i]))
        elif kind == "unknown":
            body[i][header.index("stimulus_id")] = "no-such-clip"
        elif kind == "blank_participant":
            body[i][0] = ""
        else:
            body[i] = body[i][:3]
    return [header] + body


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(edits=st.lists(st.tuples(st.sampled_from(DAMAGE), st.integers(0, 10_000)), max_size=12))
def test_rows_reconcile_and_imported_participants_are_complete(clean, tmp_path_factory, edits):
    design, rows = clean
    damaged = _damage(rows, edits)
    path = tmp_path_factory.mktemp("prop") / "long.csv"
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="\n").writerows(damaged)
    path.write_text(buffer.getvalue())
    result = import_responses(path, design)
    assert result.n_rows == len(damaged) - 1
    assert result.reconciles
    listed = result.exclusions["row"].dropna().astype(int)
    assert listed.is_unique and not set(listed) & set(result.data["row"].astype(int))
    cells = {(g, b) for g in ("walk", "jog") for b in ("Hi1", "Lo1")}
    for _, answers in result.data.groupby("participant"):
        assert set(zip(answers["GAIT"], answers["BODY"])) == cells
    if not edits:
        assert result.n_excluded_rows == 0


@pytest.fixture(scope="module")
def qualtrics():
    design = load_design(DATA / "mini_likert")
    sim = simulate_responses(design, load_model(None, design), participants=6, seed=2)
    rows = list(csv.reader(io.StringIO(export_text(sim, design, "qualtrics", seed=2))))
    return design, rows


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(edits=st.lists(st.tuples(st.sampled_from(["blank", "garbage", "duplicate", "short", "unfinished"]),
                                st.integers(0, 10_000), st.integers(0, 10_000)), max_size=10))
def test_qualtrics_rows_reconcile_under_damage(qualtrics, tmp_path_factory, edits):
    design, rows = qualtrics
    header, body = rows[:3], [list(r) for r in rows[3:]]
    questions = [i for i, c in enumerate(header[0]) if c.startswith(("F-", "M-"))]
    for kind, r, c in edits:
        i, col = r % len(body), questions[c % len(questions)]
        if kind in ("blank", "garbage", "unfinished") and len(body[i]) < len(header[0]):
            continue  # a truncated row has no such cell any more
        if kind == "blank":
            body[i][col] = ""
        elif kind == "garbage":
            body[i][col] = "Sehr stimmig"
        elif kind == "duplicate":
            body.insert(i, list(body[i]))
        elif kind == "short":
            body[i] = body[i][:5]
        else:
            body[i][header[0].index("Finished")] = "False"
    path = tmp_path_factory.mktemp("propq") / "q.csv"
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="\n").writerows(header + body)
    path.write_text(buffer.getvalue())
    result = import_responses(path, design)
    assert result.n_rows == len(body) and result.reconciles
    for participant, answers in result.data[~result.data["practice"]].groupby("participant"):
        sex = answers["SEX"].iloc[0]
        assert (answers["SEX"] == sex).all()
        assert len(set(zip(answers["GAIT"], answers["BODY"]))) == 4
    assert (result.data.groupby("participant")["row"].nunique() == 1).all()   # one row = one respondent
