"""Bad input to the analysis commands: exit code 2, a message naming the file, option, row or column and what
was expected, no traceback, nothing written over and nothing a user gave dropped without a note.

One test (or a few) per defect of the input-validation review; each failed before its fix.
"""

from __future__ import annotations

import csv
import io
import json
import re
import shutil
from pathlib import Path

import pandas as pd
import pytest

from analysis.errors import AnalysisError
from analysis.io_design import load_design
from analysis.io_writers import export_text
from analysis.model_spec import load_model
from analysis.simulate import simulate_responses, trial_plan

ROOT = Path(__file__).resolve().parents[1]


def flat(text: str) -> str:
    """Without white space: the CLI wraps long messages, also inside hyphenated names."""
    return re.sub(r"\s+", "", text)


def says(err: str, *parts: str) -> bool:
    return all(flat(p) in flat(err) for p in parts)


@pytest.fixture(scope="module")
def designs(tmp_path_factory):
    """Design directories of Exp. 1 (SEX between, 2 repetitions) and Exp. 2, as `shapemotion design` writes them."""
    from stimuli.cli import main
    out = {}
    for name in ("exp1_shape_motion", "exp2_com_vs_average"):
        folder = tmp_path_factory.mktemp(name) / "design"
        assert main(["design", str(ROOT / "protocols" / f"{name}.yaml"), "--participants", "16", "--seed", "3",
                     "--out", str(folder)]) == 0
        out[name] = folder
    return out


def responses(design_dir: Path, path: Path, fmt: str, participants: int = 4, seed: int = 2) -> Path:
    """Simulated responses to the design in ``fmt`` written to ``path``."""
    design = load_design(design_dir)
    sim = simulate_responses(design, load_model(None, design), participants, seed)
    path.write_text(export_text(sim, design, fmt, path.suffix, seed=seed), encoding="utf-8")
    return path


def rewrite_csv(path: Path, edit) -> Path:
    """Apply ``edit(rows)`` to the CSV rows of ``path`` in place."""
    rows = list(csv.reader(io.StringIO(path.read_text(encoding="utf-8"), newline="")))
    edit(rows)
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="\n").writerows(rows)
    path.write_text(buffer.getvalue(), encoding="utf-8")
    return path


# -- 1. analyze --out --------------------------------------------------------------------------------------

def test_analyze_out_that_is_a_file_is_refused_and_left_alone(designs, run_cli, tmp_path):
    answers = responses(designs["exp1_shape_motion"], tmp_path / "r.csv", "qualtrics")
    before = answers.read_bytes()
    other = tmp_path / "notes.txt"
    other.write_text("keep me")
    for out in (other, answers):
        code, _, err = run_cli("analyze", designs["exp1_shape_motion"], "--responses", answers, "--out", out)
        assert code == 2 and says(err, f"--out {out}: exists and is not a folder") and "Traceback" not in err
    assert other.read_text() == "keep me" and answers.read_bytes() == before
    assert not (tmp_path / ".notes.txt.old").exists() and not (tmp_path / ".r.csv.old").exists()


def test_analyze_out_never_replaces_an_input_folder(designs, run_cli, tmp_path):
    design = tmp_path / "design"
    shutil.copytree(designs["exp1_shape_motion"], design)
    answers = responses(design, design / "r.csv", "qualtrics")
    code, _, err = run_cli("analyze", design, "--responses", answers, "--out", design)
    assert code == 2 and says(err, "would replace the input")
    assert (design / "design.json").exists() and answers.exists()


# -- 2. a Qualtrics column not in the design -----------------------------------------------------------------

def test_analyze_lists_qualtrics_columns_not_imported_and_still_works(designs, run_cli, tmp_path):
    answers = responses(designs["exp1_shape_motion"], tmp_path / "r.csv", "qualtrics")
    rewrite_csv(answers, lambda rows: rows[0].__setitem__(rows[0].index("F-walk-Hi1-Hi1_r1"), "F-wlak-Hi1-Hi1_r1"))
    code, out, err = run_cli("analyze", designs["exp1_shape_motion"], "--responses", answers,
                             "--out", tmp_path / "report", "--no-models")
    assert code == 0, err
    assert "columns not imported: F-wlak-Hi1-Hi1_r1" in out
    exclusions = pd.read_csv(tmp_path / "report" / "exclusions.csv", keep_default_na=False)
    assert "F-wlak-Hi1-Hi1_r1" in set(exclusions["column"])
    assert "F-wlak-Hi1-Hi1_r1" in (tmp_path / "report" / "report.html").read_text(encoding="utf-8")


# -- 3. long CSV: extra and contradicting columns ------------------------------------------------------------

def test_long_csv_extra_column_is_reported_as_not_imported(designs, run_cli, tmp_path):
    answers = rewrite_csv(responses(designs["exp1_shape_motion"], tmp_path / "r.csv", "long"),
                          lambda rows: [r.append("comment" if i == 0 else "ok") for i, r in enumerate(rows)])
    code, out, err = run_cli("responses", "inspect", answers, "--design", designs["exp1_shape_motion"])
    assert code == 0, err
    assert "columns not imported: comment" in out


@pytest.mark.parametrize("suffix", [".csv", ".json"])
def test_jspsych_column_of_the_lab_is_reported_as_not_imported(designs, run_cli, tmp_path, suffix):
    """jsPsych's own fields and the exported experiment's bookkeeping pass without a note; a field the lab
    added (here ``age``, as ``jsPsych.data.addProperties`` would) is listed, like in the other formats."""
    answers = responses(designs["exp1_shape_motion"], tmp_path / f"r{suffix}", "jspsych")
    code, out, err = run_cli("responses", "inspect", answers, "--design", designs["exp1_shape_motion"])
    assert code == 0 and "not imported" not in out, err + out
    if suffix == ".json":
        trials = json.loads(answers.read_text(encoding="utf-8"))
        answers.write_text(json.dumps([dict(t, age=30) for t in trials]), encoding="utf-8")
    else:
        rewrite_csv(answers, lambda rows: [r.append("age" if i == 0 else "30") for i, r in enumerate(rows)])
    code, out, err = run_cli("responses", "inspect", answers, "--design", designs["exp1_shape_motion"])
    assert code == 0 and "columns not imported: age" in out, err + out


def test_long_csv_factor_column_that_contradicts_the_design_is_an_error(designs, run_cli, tmp_path):
    def gait_walk(rows):
        for i, r in enumerate(rows):
            r.append("GAIT" if i == 0 else "walk")

    answers = rewrite_csv(responses(designs["exp1_shape_motion"], tmp_path / "r.csv", "long"), gait_walk)
    data = pd.read_csv(answers)
    line = int(data.index[data["stimulus_id"].str.contains("-jog-")][0]) + 2
    code, _, err = run_cli("analyze", designs["exp1_shape_motion"], "--responses", answers, "--out", tmp_path / "out")
    assert code == 2 and says(err, f"r.csv: row {line}: column 'GAIT' is 'walk'", "GAIT = 'jog'")
    assert not (tmp_path / "out").exists()


def test_long_csv_placement_that_contradicts_the_design_is_an_error(designs, run_cli, tmp_path):
    """A 2AFC answer is scored through the design's left/right placement: a file whose clips stood the
    other way round would have been scored against the wrong alternative without a word."""
    placement = pd.read_csv(designs["exp2_com_vs_average"] / "conditions.csv").set_index("stimulus_id")

    def add_placement(rows, swap_once=True):
        sid, practice = rows[0].index("stimulus_id"), rows[0].index("practice")
        rows[0] += ["left", "right"]
        for r in rows[1:]:
            r += [placement.loc[r[sid], "left"], placement.loc[r[sid], "right"]]
        if swap_once:
            row = next(r for r in rows[1:] if r[practice] == "0")
            row[-2], row[-1] = row[-1], row[-2]

    agreeing = rewrite_csv(responses(designs["exp2_com_vs_average"], tmp_path / "ok.csv", "long"),
                           lambda rows: add_placement(rows, swap_once=False))
    code, _, err = run_cli("analyze", designs["exp2_com_vs_average"], "--responses", agreeing, "--out",
                           tmp_path / "ok", "--no-models")
    assert code == 0, err

    answers = rewrite_csv(responses(designs["exp2_com_vs_average"], tmp_path / "r.csv", "long"), add_placement)
    code, _, err = run_cli("analyze", designs["exp2_com_vs_average"], "--responses", answers, "--out", tmp_path / "out")
    assert code == 2 and says(err, "r.csv: row", "column 'left' is", "in conditions.csv")
    assert not (tmp_path / "out").exists()


# -- 4. repetitions outside the design ------------------------------------------------------------------------

def test_qualtrics_column_with_a_repetition_the_design_lacks_is_named(designs, run_cli, tmp_path):
    def add_r3(rows):
        i = rows[0].index("F-walk-Hi1-Hi1_r2") + 1
        extra = ["F-walk-Hi1-Hi1_r3", "Q - F-walk-Hi1-Hi1_r3", '{"ImportId":"QID999"}'] + ["3"] * (len(rows) - 3)
        for row, cell in zip(rows, extra):
            row.insert(i, cell)

    answers = rewrite_csv(responses(designs["exp1_shape_motion"], tmp_path / "r.csv", "qualtrics"), add_r3)
    code, out, err = run_cli("analyze", designs["exp1_shape_motion"], "--responses", answers, "--out", tmp_path / "out")
    # a fault of the column, not of the respondents: the column is listed once and not imported (it used to
    # exclude every respondent, and the analysis stopped with no one left)
    assert code == 0, err
    assert says(out, "columns not imported: F-walk-Hi1-Hi1_r3")
    excluded = pd.read_csv(tmp_path / "out" / "exclusions.csv", dtype=str, keep_default_na=False)
    note = excluded[excluded["column"] == "F-walk-Hi1-Hi1_r3"]
    assert note[["row", "reason", "scope"]].values.tolist() == [["", "repetition outside the design", "column"]]
    assert says(note["detail"].iloc[0], "'F-walk-Hi1-Hi1_r3' (repetition 3", "column not imported")
    assert "duplicate answer" not in set(excluded["reason"])


def import_with_repetition(designs, tmp_path, value: str):
    """Exp. 1 long-CSV responses with the first test row's ``repetition`` cell set to ``value``:
    the import result and its row exclusions."""
    def edit(rows):
        i, practice = rows[0].index("repetition"), rows[0].index("practice")
        next(r for r in rows[1:] if r[practice] == "0")[i] = value

    from analysis.responses import import_responses
    result = import_responses(rewrite_csv(responses(designs["exp1_shape_motion"], tmp_path / "r.csv", "long"), edit),
                              load_design(designs["exp1_shape_motion"]))
    return result, result.exclusions.dropna(subset=["row"])


def test_long_csv_repetition_outside_the_range_is_not_called_a_duplicate(designs, tmp_path):
    result, excluded = import_with_repetition(designs, tmp_path, "7")
    assert list(excluded["reason"]) == ["repetition outside the design"]
    assert "column 'repetition' is 7" in excluded["detail"].iloc[0] and "times" not in excluded["detail"].iloc[0]
    assert result.reconciles


def test_long_csv_repetition_that_is_not_a_number_is_a_malformed_row(designs, tmp_path):
    """It used to be renumbered by the importer without a word."""
    _, excluded = import_with_repetition(designs, tmp_path, "two")
    assert list(excluded["reason"]) == ["malformed row"]
    assert "column 'repetition' is 'two'" in excluded["detail"].iloc[0]


# -- 5. a between factor left with one level ------------------------------------------------------------------

def test_lost_between_level_names_the_file_and_the_excluded_participant(designs, run_cli, tmp_path):
    """Two participants, one per SEX; one row of participant 1 states the other SEX."""
    flip = {"F": "M", "M": "F"}
    found = {}

    def participant_1_says_the_other_sex(rows):
        sex, practice = rows[0].index("SEX"), rows[0].index("practice")
        row = next(r for r in rows[1:] if r[0] == "1" and r[practice] == "0")
        found["own"] = row[sex]
        row[sex] = flip[row[sex]]

    answers = rewrite_csv(responses(designs["exp1_shape_motion"], tmp_path / "r.csv", "long", participants=2),
                          participant_1_says_the_other_sex)
    own, other = found["own"], flip[found["own"]]
    code, _, err = run_cli("analyze", designs["exp1_shape_motion"], "--responses", answers, "--out", tmp_path / "out")
    assert code == 2 and "Traceback" not in err
    assert says(err, f"r.csv: after the exclusions only SEX = {other} is left", "participant '1'",
                "several between-subject groups", f"says SEX={other} for a stimulus of SEX={own}")


# -- 6. JSON that holds no jsPsych responses ------------------------------------------------------------------

@pytest.mark.parametrize("text, message", [("[]", "holds no responses"), ('{"x": 1}', "not a jsPsych export")])
def test_inspect_json_without_responses_exits_2(run_cli, tmp_path, text, message):
    path = tmp_path / "data.json"
    path.write_text(text)
    code, out, err = run_cli("responses", "inspect", path)
    assert code == 2 and says(err, "data.json", message) and "participants" not in out


# -- 7. responses of another protocol ---------------------------------------------------------------------------

@pytest.mark.parametrize("fmt, suffix, column", [("qualtrics", ".csv", "shapemotion_protocol"),
                                                 ("jspsych", ".json", "protocol")])
def test_responses_of_another_protocol_are_refused(designs, run_cli, tmp_path, fmt, suffix, column):
    answers = responses(designs["exp2_com_vs_average"], tmp_path / f"r{suffix}", fmt)
    code, _, err = run_cli("analyze", designs["exp1_shape_motion"], "--responses", answers, "--out", tmp_path / "out")
    assert code == 2 and says(err, f"column '{column}' says the responses are from protocol 'exp2_com_vs_average'",
                              "is 'exp1_shape_motion'")


# -- 8. design directories --------------------------------------------------------------------------------------

def copy_design(designs, tmp_path) -> Path:
    folder = tmp_path / "design"
    shutil.copytree(designs["exp1_shape_motion"], folder)
    return folder


def test_design_json_that_is_a_list_is_refused(designs, run_cli, tmp_path):
    folder = copy_design(designs, tmp_path)
    (folder / "design.json").write_text("[1, 2]")
    for command in (["simulate", folder, "--participants", "2", "--seed", "1", "--out", tmp_path / "x.csv"],
                    ["analyze", folder, "--responses", tmp_path / "x.csv", "--out", tmp_path / "out"]):
        code, _, err = run_cli(*command)
        assert code == 2 and says(err, "design.json: expected a JSON object") and "Traceback" not in err


def test_design_json_without_protocol_names_the_model_used(designs, run_cli, tmp_path):
    folder = copy_design(designs, tmp_path)
    meta = json.loads((folder / "design.json").read_text())
    del meta["protocol"]
    (folder / "design.json").write_text(json.dumps(meta))
    assert load_design(folder).repetitions == 2          # the top-level field, not a silent default of 1
    code, out, _ = run_cli("simulate", folder, "--participants", "2", "--seed", "1", "--out", tmp_path / "a.csv")
    assert code == 0 and "model exp1_shape_motion" in out
    del meta["name"]
    (folder / "design.json").write_text(json.dumps(meta))
    code, out, err = run_cli("simulate", folder, "--participants", "2", "--seed", "1", "--out", tmp_path / "b.csv")
    assert code == 0 and "model null" in out and says(err, "names no protocol", "using the null model")


def test_trials_with_an_unknown_stimulus_name_file_row_and_id(designs, run_cli, tmp_path):
    folder = copy_design(designs, tmp_path)
    rewrite_csv(folder / "trials.csv", lambda rows: rows[2].__setitem__(rows[0].index("stimulus_id"), "F-wlak-X"))
    code, _, err = run_cli("simulate", folder, "--participants", "2", "--seed", "1", "--out", tmp_path / "x.csv")
    assert code == 2 and says(err, "trials.csv: row 3: stimulus_id 'F-wlak-X' is not a stimulus of conditions.csv")


# -- 9. power and simulate options ------------------------------------------------------------------------------

@pytest.mark.parametrize("options, message", [
    (["--participants", "4", "4"], "--participants: N = 4 given more than once"),
    (["--participants", "4", "--target", "1.5"], "--target: expected a power between 0 and 1"),
    (["--participants", "4", "--target", "-1"], "--target: expected a power between 0 and 1"),
    (["--participants", "4", "--seed", "-1"], "--seed: expected a non-negative whole number"),
])
def test_power_refuses_bad_options(designs, run_cli, options, message):
    code, out, err = run_cli("power", designs["exp1_shape_motion"], "--sims", "5", *options)
    assert code == 2 and says(err, message) and "Traceback" not in err and out == ""


def test_power_csv_path_is_checked_before_the_simulation(designs, run_cli, tmp_path):
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    for path, message in ((tmp_path, "is a folder"), (blocker / "p.csv", "is a file, not a folder")):
        code, out, err = run_cli("power", designs["exp1_shape_motion"], "--participants", "4", "--sims", "5",
                                 "--csv", path)
        assert code == 2 and says(err, f"--csv {path}", message) and out == ""


@pytest.mark.parametrize("options, message", [
    (["--participants", "0", "--seed", "1"], "--participants: expected a positive number of participants, got 0"),
    (["--participants", "2", "--seed", "-5"], "--seed: expected a non-negative whole number, got -5"),
])
def test_simulate_refuses_bad_options(designs, run_cli, tmp_path, options, message):
    code, _, err = run_cli("simulate", designs["exp1_shape_motion"], *options, "--out", tmp_path / "x.csv")
    assert code == 2 and says(err, message) and not (tmp_path / "x.csv").exists()


@pytest.mark.parametrize("participants", [2, 4, 6, 16, 20])
def test_simulated_participants_are_balanced_over_between_groups(designs, participants):
    plan = trial_plan(load_design(designs["exp1_shape_motion"]), participants)
    counts = plan.groups["SEX"].value_counts()
    assert set(counts.index) == {"F", "M"} and counts["F"] == counts["M"] == participants // 2


def test_four_simulated_participants_are_counterbalanced_within_groups(designs):
    plan = trial_plan(load_design(designs["exp1_shape_motion"]), 4)
    first_block = plan.trials.sort_values("trial").groupby("participant")["block_label"].first()
    sex = plan.groups.set_index("participant")["SEX"]
    for group in ("F", "M"):
        assert sorted(first_block[sex[sex == group].index]) == ["GAIT=jog", "GAIT=walk"]


def test_sixteen_simulated_participants_keep_the_design_lists(designs):
    design = load_design(designs["exp1_shape_motion"])
    plan = trial_plan(design, 16)
    expected = design.trials.assign(participant=design.trials["participant"].astype(int))
    for p in (1, 2, 16):
        mine = plan.trials[plan.trials["participant"] == p]["stimulus_id"].tolist()
        assert mine == expected[expected["participant"] == p]["stimulus_id"].tolist()


# -- 10. output file paths ---------------------------------------------------------------------------------------

def test_output_files_under_a_file_or_onto_a_folder_are_refused(designs, run_cli, tmp_path):
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    data = tmp_path / "data.csv"
    data.write_text("s,g,y\n" + "".join(f"{s},{g},{s * 2 + (g == 'b') + (s % 2) * (g == 'a')}\n"
                                        for s in range(1, 5) for g in "ab"))
    cases = [
        (["simulate", designs["exp1_shape_motion"], "--participants", "2", "--seed", "1", "--out", tmp_path],
         f"--out {tmp_path}: is a folder"),
        (["simulate", designs["exp1_shape_motion"], "--participants", "2", "--seed", "1", "--out", blocker / "x.csv"],
         "is a file, not a folder"),
        (["anova", data, "--dv", "y", "--subject", "s", "--within", "g", "--out", blocker / "x.md"],
         f"--out {blocker / 'x.md'}: {blocker} is a file"),
        (["anova", data, "--dv", "y", "--subject", "s", "--within", "g", "--json", blocker / "x.json"],
         f"--json {blocker / 'x.json'}: {blocker} is a file"),
        (["anova", data, "--dv", "y", "--subject", "s", "--within", "g", "--out", data], "is the input"),
    ]
    for command, message in cases:
        code, _, err = run_cli(*command)
        assert code == 2 and says(err, message) and "Traceback" not in err, command
    assert blocker.read_text() == "x" and data.read_text().startswith("s,g,y")


# -- 11. anova options and data -----------------------------------------------------------------------------------

@pytest.fixture
def anova_csv(tmp_path):
    """4 subjects × GAIT (walk, jog) × BODY (Hi1, Lo1), one rating per cell."""
    rows = [f"{s},{g},{b},{(s * 7 + len(g) * 3 + (b == 'Lo1') * 2) % 5 + 1}"
            for s in range(1, 5) for g in ("walk", "jog") for b in ("Hi1", "Lo1")]
    path = tmp_path / "d.csv"
    path.write_text("subject,GAIT,BODY,rating\n" + "\n".join(rows) + "\n")
    return path


@pytest.mark.parametrize("abbrev, message", [("Hi9=X", "'Hi9' is not a level of any factor"),
                                             ("FOO:Hi1=X", "'FOO' is not a factor"),
                                             ("BODY:walk=X", "'walk' is not a level of BODY")])
def test_anova_abbreviation_of_an_unknown_level_or_factor(anova_csv, run_cli, abbrev, message):
    code, _, err = run_cli("anova", anova_csv, "--dv", "rating", "--subject", "subject", "--within", "GAIT", "BODY",
                           "--posthoc", "tukey", "--abbrev", abbrev)
    assert code == 2 and says(err, f"--abbrev {abbrev.split('=')[0].split(':')[0]}", message)


def test_anova_duplicate_header_is_named(anova_csv, run_cli):
    lines = anova_csv.read_text().splitlines()
    anova_csv.write_text("\n".join([lines[0] + ",rating"] + [line + ",1" for line in lines[1:]]) + "\n")
    code, _, err = run_cli("anova", anova_csv, "--dv", "rating", "--subject", "subject", "--within", "GAIT", "BODY")
    assert code == 2 and says(err, "d.csv: line 1", "'rating' in columns 4, 5")


def test_anova_level_typo_names_its_line(anova_csv, run_cli):
    lines = anova_csv.read_text().splitlines()
    lines[2] = lines[2].replace(",walk,", ",wlak,")   # CSV line 3
    anova_csv.write_text("\n".join(lines) + "\n")
    assert ",wlak," in lines[2]
    code, _, err = run_cli("anova", anova_csv, "--dv", "rating", "--subject", "subject", "--within", "GAIT", "BODY")
    assert code == 2 and says(err, "level 'wlak' of GAIT appears only on CSV line 3")


# -- 12. duplicate keys in a model file ---------------------------------------------------------------------------

def test_model_yaml_with_a_duplicate_key_is_refused(designs, tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text("name: m\neffects:\n  - term: BODY\n    values: {Hi2: -0.12, Hi2: 0.90}\n"
                    "thresholds: [-1.5, -0.5, 0.5, 1.5]\n")
    with pytest.raises(AnalysisError, match=r"m\.yaml: line 4, column \d+: key 'Hi2' appears twice"):
        load_model(path, load_design(designs["exp1_shape_motion"]))


# -- 13. user walkthrough ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("where, field", [("top", "dependent_measure"),
                                          ("protocol", "protocol.analysis.dependent_measure")])
def test_design_json_with_a_measure_the_responses_cannot_give_is_refused(designs, run_cli, tmp_path, where, field):
    """A Likert design asking for percent_chosen used to crash with KeyError 'chosen' deep in the measures."""
    folder = copy_design(designs, tmp_path)
    meta = json.loads((folder / "design.json").read_text())
    answers = responses(folder, tmp_path / "r.csv", "long", participants=2)
    if where == "top":
        meta["dependent_measure"] = "percent_chosen"
    else:
        del meta["dependent_measure"]
        meta["protocol"]["analysis"]["dependent_measure"] = "percent_chosen"
    (folder / "design.json").write_text(json.dumps(meta))
    code, _, err = run_cli("analyze", folder, "--responses", answers, "--out", tmp_path / "out")
    assert code == 2 and "Traceback" not in err and not (tmp_path / "out").exists()
    assert says(err, f"design.json: field '{field}' is 'percent_chosen'", "response.type 'likert' allows only "
                                                                          "mean_rating")


def test_anova_refuses_practice_rows(anova_csv, run_cli, tmp_path):
    """responses_tidy.csv holds the practice trials: their BODY level must not become one more condition."""
    lines = anova_csv.read_text().splitlines()
    practice = [f"{s},walk,Prac,3,True" for s in range(1, 5)]
    test_rows = [line + ",False" for line in lines[1:]]
    anova_csv.write_text("\n".join([lines[0] + ",practice", *test_rows, *practice]) + "\n")
    code, out, err = run_cli("anova", anova_csv, "--dv", "rating", "--subject", "subject", "--within", "GAIT", "BODY",
                             "--out", tmp_path / "table.md")
    assert code == 2 and out == "" and not (tmp_path / "table.md").exists()
    assert says(err, "d.csv: 4 of 20 rows are practice trials", "CSV lines 18, 19, 20, 21",
                "cell_values.csv", "drop the practice rows")
    anova_csv.write_text("\n".join(anova_csv.read_text().splitlines()[:17]) + "\n")   # test trials only: fine
    code, out, _ = run_cli("anova", anova_csv, "--dv", "rating", "--subject", "subject", "--within", "GAIT", "BODY",
                           "--all")
    assert code == 0 and "Prac" not in out and "| BODY |" in out


def test_inspect_a_folder_of_jspsych_files(designs, run_cli, tmp_path, jspsych_folder):
    """analyze --responses accepts a folder of per-participant files; inspect reads it the same way."""
    folder = jspsych_folder(load_design(designs["exp2_com_vs_average"]), tmp_path / "responses", 3, seed=4)
    (folder / "notes.txt").write_text("not a response file")
    single = json.loads(run_cli("responses", "inspect", folder / "p1.csv", "--json")[1])
    code, out, _ = run_cli("responses", "inspect", folder, "--json")
    info = json.loads(out)
    assert code == 0 and [f["file"] for f in info["files"]] == ["p1.csv", "p1_again.csv", "p2.csv", "p3.csv"]
    assert info["rows"] == 4 * single["rows"] and info["responses"] == 4 * single["responses"]
    assert info["participants"] == 3                      # participant 1's second file is the same person
    assert [c["name"] for c in info["columns"]] == [c["name"] for c in single["columns"]]
    code, out, _ = run_cli("responses", "inspect", folder, "--design", designs["exp2_com_vs_average"])
    assert code == 0 and says(out, f"folder: {folder}", "files: 4", f"p2.csv: jspsych-csv; rows {single['rows']}",
                              "participants: 3", "3 participants")
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = run_cli("responses", "inspect", empty)
    assert code == 2 and says(err, "the folder holds no .csv or .json response file")


@pytest.mark.parametrize("value", ["y", "T", "YES", "t", "1.0", "1"])
def test_anova_practice_column_accepts_the_usual_true_spellings(anova_csv, run_cli, value):
    """Only true/1/1.0/yes used to count as practice: `y` or `T` made the practice row a silent test row."""
    lines = anova_csv.read_text().splitlines()
    rows = [line + ",n" for line in lines[1:]] + [f"{s},walk,Prac,3,{value}" for s in range(1, 5)]
    anova_csv.write_text("\n".join([lines[0] + ",practice", *rows]) + "\n")
    code, out, err = run_cli("anova", anova_csv, "--dv", "rating", "--subject", "subject", "--within", "GAIT", "BODY")
    assert code == 2 and out == "" and says(err, "4 of 20 rows are practice trials", "CSV lines 18, 19, 20, 21")


@pytest.mark.parametrize("value", ["2", "practice", "maybe", "nan", "-1"])
def test_anova_practice_column_with_an_unknown_value_names_its_line(anova_csv, run_cli, tmp_path, value):
    lines = anova_csv.read_text().splitlines()
    rows = [line + (f",{value}" if i == 2 else ",False") for i, line in enumerate(lines[1:])]
    anova_csv.write_text("\n".join([lines[0] + ",practice", *rows]) + "\n")
    code, out, err = run_cli("anova", anova_csv, "--dv", "rating", "--subject", "subject", "--within", "GAIT", "BODY",
                             "--out", tmp_path / "t.md")
    assert code == 2 and out == "" and "Traceback" not in err and not (tmp_path / "t.md").exists()
    assert says(err, "d.csv: column 'practice' must be true or false", f"CSV line 4: '{value}'")


@pytest.mark.parametrize("values", [["F", "no", "N", "0", "0.0", "false", ""]])
def test_anova_practice_column_false_spellings_and_blank_are_test_rows(anova_csv, run_cli, values):
    lines = anova_csv.read_text().splitlines()
    rows = [line + "," + values[i % len(values)] for i, line in enumerate(lines[1:])]
    anova_csv.write_text("\n".join([lines[0] + ",practice", *rows]) + "\n")
    code, out, _ = run_cli("anova", anova_csv, "--dv", "rating", "--subject", "subject", "--within", "GAIT", "BODY",
                           "--all")
    assert code == 0 and "| BODY |" in out


# -- 12. one reader of the practice column (anova, load_design, simulate) -----------------------------------------

def _spell_practice(path: Path, spelling: dict) -> Path:
    """Rewrite the ``practice`` cells of a design CSV through ``spelling`` (e.g. {"1": "1.0", "0": "0.0"})."""
    def edit(rows):
        i = rows[0].index("practice")
        for r in rows[1:]:
            r[i] = spelling.get(r[i], r[i])
    return rewrite_csv(path, edit)


def test_practice_written_as_1_0_is_practice_for_the_design_and_for_simulate(designs, tmp_path):
    """`anova` read `1.0` as practice, load_design and simulate read only true/1/yes: a practice stimulus written
    `1.0` (a spreadsheet's export) became a test condition of the analysis and its trials test trials."""
    folder = shutil.copytree(designs["exp1_shape_motion"], tmp_path / "design")
    for name in ("conditions.csv", "trials.csv"):
        _spell_practice(folder / name, {"1": "1.0", "0": "0.0"})
    original, design = load_design(designs["exp1_shape_motion"]), load_design(folder)
    assert original.conditions["practice"].any()
    assert design.conditions["practice"].tolist() == original.conditions["practice"].tolist()
    assert len(design.test_conditions) == len(original.test_conditions)
    simulated = simulate_responses(design, load_model(None, design), 4, seed=2)
    pd.testing.assert_frame_equal(simulated, simulate_responses(original, load_model(None, original), 4, seed=2))


@pytest.mark.parametrize("name, command", [("conditions.csv", "analyze"), ("trials.csv", "simulate")])
def test_design_practice_value_that_cannot_be_read_is_refused(designs, run_cli, tmp_path, name, command):
    """A `maybe` in the practice column used to be a test trial without a word."""
    folder = shutil.copytree(designs["exp1_shape_motion"], tmp_path / "design")

    def edit(rows):
        rows[3][rows[0].index("practice")] = "maybe"   # CSV line 4
    rewrite_csv(folder / name, edit)
    if command == "analyze":
        answers = responses(designs["exp1_shape_motion"], tmp_path / "r.csv", "long")
        args = ["analyze", folder, "--responses", answers, "--out", tmp_path / "out"]
    else:
        args = ["simulate", folder, "--participants", "4", "--seed", "1", "--out", tmp_path / "out"]
    code, _, err = run_cli(*args)
    assert code == 2 and "Traceback" not in err and not (tmp_path / "out").exists()
    assert says(err, f"{name}: column 'practice' must be true or false", "CSV line 4: 'maybe'")


def test_anova_csv_is_read_once_with_practice_cells_as_written_and_missing_values_as_missing(anova_csv, tmp_path):
    """read_anova_csv reads the practice cells as written (`nan` is refused, not a blank) in the same pass in
    which the other columns keep pandas' missing values (`NA` in the DV is missing); the library's messages
    name CSV lines itself."""
    from analysis.anova import anova
    from analysis.anova_data import read_anova_csv

    lines = anova_csv.read_text().splitlines()
    rows = [line + ",0" for line in lines[1:]]
    rows[4] = rows[4].rsplit(",", 2)[0] + ",NA,0"   # CSV line 6
    anova_csv.write_text("\n".join([lines[0] + ",practice", *rows]) + "\n")
    data = read_anova_csv(anova_csv, used=["rating", "subject", "GAIT", "BODY"])
    assert data.loc[6, "rating"] != data.loc[6, "rating"] and data.loc[7, "practice"] == "0"
    with pytest.raises(AnalysisError, match=r"column 'rating' has 1 missing value\(s\).* on CSV line 6;"):
        anova(data, dv="rating", subject="subject", within=["GAIT", "BODY"])
    anova_csv.write_text(anova_csv.read_text().replace(",NA,0", ",3,nan"))
    with pytest.raises(AnalysisError, match="d.csv: column 'practice' must be true or false.*CSV line 6: 'nan'"):
        read_anova_csv(anova_csv, used=["rating", "subject", "GAIT", "BODY"])
    assert read_anova_csv(anova_csv, used=["practice"]).loc[6, "practice"] != "nan"   # the user's column: pandas'


@pytest.mark.parametrize("module", ["analysis.practice", "analysis.io_files", "analysis.io_design", "analysis.report",
                                    "analysis.simulate", "analysis.power", "analysis.measures",
                                    "analysis.responses.scoring", "analysis.models", "analysis.io_yaml"])
def test_docstring_examples_run(module):
    import doctest
    import importlib
    result = doctest.testmod(importlib.import_module(module))
    assert result.failed == 0
