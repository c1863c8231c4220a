"""Attention checks in the Qualtrics (QSF, TXT) and PsychoPy exports, and scored on a Qualtrics import.

The checks take fixed slots inside the test blocks (stimuli/survey/checks.py): per participant as many as
jsPsych/serve show for the same trials, wherever the block randomizer puts the blocks. A Qualtrics-shaped
CSV export (three header rows) of such a survey is scored by the same function as jsPsych's checks.
"""

from __future__ import annotations

import csv
import json
import random
from pathlib import Path

import pandas as pd
import pytest

from stimuli.design import build_design, write_design
from stimuli.protocol import parse_protocol
from stimuli.serve.study import with_checks
from stimuli.survey import export_all, export_survey
from stimuli.survey.checks import check_slots, checks_per_participant
from stimuli.survey.qsf import RANDOMIZED_SLOT, build_qsf
from stimuli.survey.qualtrics_txt import manual_steps, txt_text
from stimuli.survey.source import load_source

PROTOCOLS = Path(__file__).resolve().parents[1] / "protocols"
BASE = "https://media.example.org/study-1"
LABELS = ["Very Inconsistent", "Inconsistent", "Neutral", "Consistent", "Very Consistent"]


def protocol_with_checks(name: str, block: str, edit=lambda text: text):
    return parse_protocol(edit((PROTOCOLS / f"{name}.yaml").read_text()) + "\n" + block + "\n")


@pytest.fixture(scope="module")
def exp1(tmp_path_factory):
    """Exp. 1 (2 SEX groups × 2 GAIT blocks of 32 test questions) with a check after every 10th test trial."""
    folder = tmp_path_factory.mktemp("exp1")
    write_design(build_design(protocol_with_checks(
        "exp1_shape_motion", "attention_checks: {every: 10, answer: neutral, exclude_if_failed: 2}")), folder)
    return folder


def payloads(qsf: dict, kind: str) -> list:
    return [e["Payload"] for e in qsf["SurveyElements"] if e["Element"] == kind]


def test_slots_give_jspsych_count_for_any_block_sizes():
    rng = random.Random(5)
    for _ in range(500):
        counts = [rng.randint(1, 40) for _ in range(rng.randint(1, 6))]
        every = rng.randint(1, 30)
        slots = check_slots(counts, every)
        assert checks_per_participant(counts, every) == (sum(counts) - 1) // every
        assert all(all(1 <= s <= n for s in block) for block, n in zip(slots, counts))
    # declared order: exactly jsPsych's positions
    flat = [start + s for start, block in zip([0, 10, 20], check_slots([10, 10, 10], 4)) for s in block]
    assert flat == [4, 8, 12, 16, 20, 24, 28]


def test_qsf_keeps_checks_in_fixed_slots_of_randomised_test_blocks(exp1):
    qsf = build_qsf(load_source(exp1), BASE)
    by_qid = {q["QuestionID"]: q for q in payloads(qsf, "SQ")}
    checks = {qid: q for qid, q in by_qid.items() if q["DataExportTag"].startswith("attention_check_")}
    # one set per SEX group: 6 checks for its 64 test trials, as jsPsych ((64 - 1) // 10)
    assert sorted(q["DataExportTag"] for q in checks.values()) == sorted(f"attention_check_{k}" for k in range(1, 13))
    tests = [b for b in payloads(qsf, "BL")[0] if b["Description"].endswith(" test")]
    assert len(tests) == 4
    slots = []
    for block in tests:
        qids = [e["QuestionID"] for e in block["BlockElements"] if e["Type"] == "Question"]
        kinds = [e["Type"] for e in block["BlockElements"]]
        assert kinds == ["Question", "Page Break"] * (len(qids) - 1) + ["Question"]   # one question per page
        options = block["Options"]
        assert options["RandomizeQuestions"] == "Advanced"
        advanced = options["Randomization"]["Advanced"]
        assert len(advanced["FixedOrder"]) == len(qids) == 32 + sum(q in checks for q in qids)
        assert [q for q in advanced["FixedOrder"] if q != RANDOMIZED_SLOT] == [q for q in qids if q in checks]
        assert sorted(advanced["RandomizeAll"]) == sorted(q for q in qids if q not in checks)
        assert {k: advanced[k] for k in ("RandomSubSet", "Undisplayed", "TotalRandSubset")} == {
            "RandomSubSet": [], "Undisplayed": [], "TotalRandSubset": 0}
        # the slot of each check: after the n-th test question of the block
        fixed = advanced["FixedOrder"]
        slots.append([fixed[:i].count(RANDOMIZED_SLOT) for i, q in enumerate(fixed) if q != RANDOMIZED_SLOT])
    assert slots == [[10, 20, 30], [8, 18, 28]] * 2
    for q in checks.values():
        assert q["QuestionType"] == "MC" and q["Selector"] == "SAHR" and "QuestionJS" not in q
        assert [c["Display"] for c in q["Choices"].values()] == LABELS
        assert q["Validation"]["Settings"]["ForceResponse"] == "ON"
        assert "please select &#x27;neutral&#x27;" in q["QuestionText"] and "<video" not in q["QuestionText"]
    assert len(by_qid) == int(next(e for e in qsf["SurveyElements"] if e["Element"] == "QC")["SecondaryAttribute"])


def test_same_count_as_jspsych_for_every_participant(exp1):
    trials = pd.read_csv(exp1 / "trials.csv", dtype=str)
    qsf = build_qsf(load_source(exp1), BASE)
    per_group = {}
    for block in (b for b in payloads(qsf, "BL")[0] if b["Description"].endswith(" test")):
        fixed = block["Options"]["Randomization"]["Advanced"]["FixedOrder"]
        group = block["Description"].split(" | ")[0]
        per_group[group] = per_group.get(group, 0) + sum(q != RANDOMIZED_SLOT for q in fixed)
    for pid, rows in trials.groupby("participant"):
        served = with_checks(rows.to_dict("records"), {"every": 10})
        assert sum(t["kind"] == "attention_check" for t in served) == per_group[f"SEX={rows['SEX'].iloc[0]}"] == 6


def test_fixed_trials_interleave_checks_in_order(tmp_path):
    folder = tmp_path / "pl"
    write_design(build_design(protocol_with_checks("thesis_pointlight", "attention_checks: {every: 4, answer: C}")),
                 folder)
    qsf = build_qsf(load_source(folder), BASE)
    by_qid = {q["QuestionID"]: q for q in payloads(qsf, "SQ")}
    for block in (b for b in payloads(qsf, "BL")[0] if b["Description"].endswith(" test")):
        assert block["Options"]["RandomizeQuestions"] == "false"
        tags = [by_qid[e["QuestionID"]]["DataExportTag"] for e in block["BlockElements"] if e["Type"] == "Question"]
        positions = [i for i, t in enumerate(tags) if t.startswith("attention_check_")]
        assert positions == [4, 9]    # after the 4th and 8th of its 10 questions (none after the last)
        check = by_qid[next(e["QuestionID"] for e in block["BlockElements"]
                            if e.get("QuestionID") and by_qid[e["QuestionID"]]["DataExportTag"].startswith("att"))]
        assert check["QuestionType"] == "MC" and [c["Display"] for c in check["Choices"].values()] == list("ABCDEF")


def test_txt_writes_checks_at_the_slots_and_says_how_to_keep_them(exp1):
    source = load_source(exp1)
    text = txt_text(source, BASE)
    for block in text.split("[[Block:")[1:]:
        if " test]]" not in block.splitlines()[0]:
            assert "attention_check" not in block
            continue
        ids = [line[5:-2] for line in block.splitlines() if line.startswith("[[ID:")]
        assert [i for i, t in enumerate(ids) if t.startswith("attention_check_")] in ([10, 21, 32], [8, 19, 30])
        assert block.count("[[PageBreak]]") == len(ids) - 1
    check = text.split("[[ID:attention_check_1]]\n")[1].split("\n\n")[0].splitlines()
    assert check == ["<p>To show that you are reading this, please select &#x27;neutral&#x27;.</p>", "[[Choices]]",
                     *LABELS]
    steps = manual_steps(source)
    assert any("Advanced Randomization" in s and "attention_check_" in s for s in steps)
    assert not any("'Randomly present" in s for s in steps)


def test_psychopy_blocks_name_the_check_slots(exp1, tmp_path):
    result = export_survey(exp1, "psychopy", tmp_path / "pp")
    blocks = pd.read_csv(tmp_path / "pp" / "blocks.csv", dtype=str, keep_default_na=False)
    assert blocks["check_after"].tolist() == ["10 20 30", "8 18 28"] * 2
    assert blocks["nReps"].tolist() == ["2"] * 4            # 16 rows × 2 repetitions = 32 trials per test loop
    row = pd.read_csv(tmp_path / "pp" / "conditions" / "attention_check.csv", dtype=str).to_dict("records")
    assert row == [{"attention_check": "1", "attention_answer": "Neutral",
                    "prompt": "To show that you are reading this, please select 'neutral'.",
                    "options": "|".join(LABELS)}]
    assert any("check_after" in n for n in result.notes)
    # the replay lists: a check row where jsPsych/serve show one in that participant's list
    replay = pd.read_csv(tmp_path / "pp" / "trials.csv", dtype=str, keep_default_na=False)
    design = pd.read_csv(exp1 / "trials.csv", dtype=str, keep_default_na=False)
    for pid, rows in design.groupby("participant", sort=False):
        served = [t["kind"] for t in with_checks(rows.to_dict("records"), {"every": 10})]
        mine = replay[replay["participant"] == pid]
        assert mine["kind"].tolist() == served
        assert (mine.loc[mine["kind"] == "attention_check", ["stimulus_id", "movie"]] == "").all().all()


def test_export_all_writes_every_format(exp1, tmp_path):
    results = {r.format: r for r in export_all(exp1, tmp_path / "all", video_base_url=BASE)}
    assert not any("attention" in note for r in results.values() for note in r.notes if "check_after" not in note)
    assert "attention_check_1" in (tmp_path / "all" / "survey.qsf").read_text()
    assert "attention_check_1" in (tmp_path / "all" / "survey_qualtrics.txt").read_text()
    assert (tmp_path / "all" / "psychopy" / "conditions" / "attention_check.csv").exists()


# -- import: a Qualtrics CSV export of that survey ----------------------------------------------------

def qualtrics_csv(qsf: dict, path: Path, answers: dict[str, str], numeric: bool = True) -> None:
    """A Qualtrics-shaped export (3 header rows) of ``qsf``: ``answers`` participant → the check answer given
    (a label); every clip rated 3; two participants per SEX group."""
    questions = [q for q in payloads(qsf, "SQ") if q["QuestionType"] == "MC"
                 and not q["DataExportTag"].startswith("practice-")]
    meta = ["StartDate", "EndDate", "Status", "Progress", "Finished", "ResponseId"]
    tags = [q["DataExportTag"] for q in questions]
    rows = [meta + tags + ["SEX", "shapemotion_protocol"],
            meta + [q["QuestionDescription"] for q in questions] + ["SEX", "shapemotion_protocol"],
            [json.dumps({"ImportId": c[0].lower() + c[1:]}) for c in meta]
            + [json.dumps({"ImportId": q["QuestionID"]}) for q in questions]
            + [json.dumps({"ImportId": "SEX"}), json.dumps({"ImportId": "shapemotion_protocol"})]]
    checks_of = {"F": {f"attention_check_{k}" for k in range(1, 7)},
                 "M": {f"attention_check_{k}" for k in range(7, 13)}}
    for n, (pid, given) in enumerate(answers.items()):
        sex = "F" if n < 2 else "M"
        values = []
        for tag in tags:
            if tag.startswith("attention_check_"):
                value = (str(LABELS.index(given) + 1) if numeric else given) if tag in checks_of[sex] else ""
            else:
                value = ("3" if numeric else "Neutral") if tag.startswith(sex) else ""
            values.append(value)
        rows.append(["2024-01-01 10:00:00", "2024-01-01 10:20:00", "0" if numeric else "IP Address", "100",
                     "1" if numeric else "True", pid] + values + [sex, "exp1_shape_motion"])
    with open(path, "w", newline="") as handle:
        csv.writer(handle).writerows(rows)


@pytest.mark.parametrize("numeric", [True, False])
def test_qualtrics_import_scores_and_excludes(exp1, tmp_path, numeric):
    from analysis.io_design import load_design
    from analysis.responses import import_responses

    # R_2 and R_4 fail every check (6 ≥ exclude_if_failed 2); R_1, R_3 pass
    qualtrics_csv(build_qsf(load_source(exp1), BASE), tmp_path / "q.csv",
                  {"R_1": "Neutral", "R_2": "Consistent", "R_3": "Neutral", "R_4": "Very Inconsistent"}, numeric)
    result = import_responses(tmp_path / "q.csv", load_design(exp1))
    summary = result.summary()
    assert result.reconciles and result.format == "qualtrics"
    assert summary["attention_checks"] == [{"participant": p, "checks": 6, "failed": 6 * (p in ("R_2", "R_4"))}
                                           for p in ("R_1", "R_2", "R_3", "R_4")]
    assert sorted(result.data["participant"].unique()) == ["R_1", "R_3"] and len(result.data) == 2 * 64
    failed = result.excluded_rows[result.excluded_rows["reason"] == "failed attention checks"]
    assert sorted(failed["participant"]) == ["R_2", "R_4"]
    assert failed["detail"].str.startswith("failed 6 of 6 attention checks").all()
    # the check columns are no answers: listed, not reported as unknown tags
    notes = result.exclusions[result.exclusions["scope"] == "column"]
    assert sorted(notes.loc[notes["reason"] == "attention check", "column"]) == sorted(
        f"attention_check_{k}" for k in range(1, 13))
    assert "unknown export tag" not in set(notes["reason"])
    # ``responses inspect`` names them too
    from analysis.responses.inspect import inspect_file

    kinds = {c["name"]: c["kind"] for c in inspect_file(tmp_path / "q.csv")["columns"]}
    assert {kinds[f"attention_check_{k}"] for k in range(1, 13)} == {"attention check"}


def test_analyze_lists_failures_of_a_qualtrics_export(exp1, tmp_path):
    """A choice-text export: the label is matched ignoring case and spacing, as jsPsych's."""
    from analysis.report import analyze

    qualtrics_csv(build_qsf(load_source(exp1), BASE), tmp_path / "q.csv",
                  {"R_1": "Neutral", "R_2": "neutral ", "R_3": "Inconsistent", "R_4": "Neutral"}, numeric=False)
    summary = analyze(exp1, tmp_path / "q.csv", tmp_path / "report", models=False)
    assert [c["failed"] for c in summary["import"]["attention_checks"]] == [0, 0, 6, 0]
    assert summary["import"]["participants"] == 3
    exclusions = pd.read_csv(tmp_path / "report" / "exclusions.csv", dtype=str)
    assert set(exclusions.loc[exclusions["reason"] == "failed attention checks", "participant"]) == {"R_3"}
