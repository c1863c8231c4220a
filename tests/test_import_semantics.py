"""What an imported value means, which run of a participant is imported, tags that differ only in punctuation,
and additional models that the data do not allow to estimate.

- F1: a choice value's meaning is fixed by its source (jsPsych ``response`` and Qualtrics numbers are screen
  positions; the long format names levels), so levels called ``3``/``12``/``35`` are not mistaken for positions.
- F2: a jsPsych or long file holding two runs of one participant id is never merged.
- F3: a Likert data set that the ordinal model cannot fit still gets its report, the model marked not computed.
- F4: two stimulus ids that differ only in case or punctuation are never mapped to one stimulus.
"""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path

import pandas as pd
import pytest

from analysis.errors import AnalysisError
from analysis.io_design import arrangement_of, load_design
from analysis.io_writers import export_text
from analysis.model_spec import load_model
from analysis.responses import import_responses
from analysis.responses.answers import TagIndex
from analysis.responses.scoring import CHOICE, LEVEL, OutsideScale, score_choice, score_ranking
from analysis.simulate import simulate_responses

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(__file__).parent / "data" / "responses"

# A point-light 3-AFC whose alternatives levels are numbers (body-fat %), positions labelled A-C.
TINY_PL = """\
name: tiny_pl_numeric
title: Which walker looks obese? (point-light, 3-AFC)
seed: 2017
participants: 6
actors:
  - {id: MP, label: MP, sex: M, height_m: 1.758, bmi: 22.0, chest_m: 0.98, body_fat_pct: 12.1}
factors:
  - name: PARAMETER
    role: within
    maps_to: parameter
    levels: [arm_swing, spinal_erectness]
    level_settings:
      arm_swing: {view_deg: 90, modifies: "arm_swing"}
      spinal_erectness: {view_deg: 90, modifies: "spinal_erectness"}
  - name: STRENGTH
    role: alternatives
    maps_to: strength
    levels: ["3", "12", "35"]
display:
  layout: point_light
  body: MP
  point_light_markers: 15
  labels: [A, B, C]
alternatives:
  arrangements: latin_square
  counterbalance: between
clip: {duration_s: 3, cycles: 1, fps: 30, width: 1920, height: 540,
       camera: {azimuth_deg: 45, elevation_deg: -5, distance_m: 9.0, fov_deg: 40}, background: "#000000"}
blocks: {by: [], order: fixed}
repetitions: 1
response:
  type: afc
  question: Which walker looks like an obese person's walk?
analysis: {dependent_measure: votes, alpha: 0.05, posthoc: none}
"""


def _make_design(folder: Path, protocol: Path, participants: int):
    """``shapemotion design PROTOCOL --participants N --seed 1 --out FOLDER/design``, loaded."""
    from stimuli.cli import main
    assert main(["design", str(protocol), "--participants", str(participants), "--seed", "1",
                 "--out", str(folder / "design")]) == 0
    return load_design(folder / "design")


@pytest.fixture(scope="module")
def tiny_pl(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tiny_pl")
    (folder / "tiny_pl.yaml").write_text(TINY_PL)
    return _make_design(folder, folder / "tiny_pl.yaml", 6)


def _simulated(design, participants=12, seed=3) -> pd.DataFrame:
    return simulate_responses(design, load_model(None, design), participants, seed=seed)


def _truth(sim: pd.DataFrame) -> dict:
    """(participant, stimulus) → the level at the simulated (1-based) position."""
    return {(str(r["participant"]), r["stimulus_id"]): arrangement_of(r)[int(r["position"]) - 1]
            for r in sim.to_dict("records")}


def _chosen(result) -> dict:
    return {(str(p), s): c for p, s, c in result.data[["participant", "stimulus_id", "chosen"]].itertuples(index=False)}


def _write(tmp_path: Path, name: str, text: str) -> Path:
    (tmp_path / name).write_text(text, encoding="utf-8")
    return tmp_path / name


# -- F1: numeric level names ---------------------------------------------------------------------------------

@pytest.mark.parametrize("fmt, suffix", [("long", ".csv"), ("qualtrics", ".csv"), ("qualtrics-numeric", ".csv"),
                                         ("qualtrics-legacy", ".csv"), ("jspsych", ".csv"), ("jspsych", ".json")])
def test_numeric_level_names_every_format_scores_the_simulated_choice(tiny_pl, tmp_path, fmt, suffix):
    """Levels "3", "12", "35" on positions A-C: jsPsych's 0-based button 2 (position C) used to become "3" and be
    credited to level "3"; the votes differed per format (28/19/13 vs 38/12/10)."""
    sim = _simulated(tiny_pl)
    path = _write(tmp_path, f"r{suffix}", export_text(sim, tiny_pl, fmt, path_suffix=suffix, seed=3))
    result = import_responses(path, tiny_pl)
    assert result.reconciles and len(result.data) == len(sim)
    assert _chosen(result) == _truth(sim)


def test_numeric_level_names_all_formats_give_identical_votes(tiny_pl, tmp_path):
    sim = _simulated(tiny_pl, participants=30, seed=11)
    votes = {}
    for fmt in ("long", "qualtrics", "qualtrics-numeric", "jspsych"):
        result = import_responses(_write(tmp_path, f"{fmt}.csv", export_text(sim, tiny_pl, fmt, seed=11)), tiny_pl)
        votes[fmt] = result.data["chosen"].value_counts().sort_index().to_dict()
    assert len({json.dumps(v) for v in votes.values()}) == 1, votes
    expected = pd.Series(list(_truth(sim).values())).value_counts().sort_index().to_dict()
    assert votes["jspsych"] == expected


def _always_12(sim: pd.DataFrame) -> tuple[pd.DataFrame, str]:
    """One participant who saw the 12 walker at position C (button 2 in jsPsych, 3 in Qualtrics: also the name
    of level "3") always picks the walker of level 12, wherever it stands."""
    at_c = sim[[arrangement_of(r).index("12") == 2 for r in sim.to_dict("records")]]
    who = at_c["participant"].iloc[0]
    sim = sim.copy()
    mine = sim["participant"] == who
    sim.loc[mine, "position"] = [arrangement_of(r).index("12") + 1 for r in sim[mine].to_dict("records")]
    return sim, str(who)


@pytest.mark.parametrize("fmt", ["jspsych", "qualtrics-numeric", "qualtrics", "long"])
def test_a_participant_always_choosing_12_gets_all_votes_for_12(tiny_pl, tmp_path, fmt):
    sim, who = _always_12(_simulated(tiny_pl))
    text = export_text(sim, tiny_pl, fmt, seed=3)
    if fmt == "jspsych":   # jsPsych's own `chosen` column says 12 on every answer of that participant
        frame = pd.read_csv(io.StringIO(text), dtype=str, keep_default_na=False)
        answered = frame[(frame["participant"] == who) & (frame["stimulus_id"] != "")]
        assert set(answered["chosen"]) == {"12"} and "2" in set(answered["response"])
    result = import_responses(_write(tmp_path, "r.csv", text), tiny_pl)
    mine = result.data[result.data["participant"] == who]
    assert len(mine) == 2 and set(mine["chosen"]) == {"12"}
    assert 3 in set(mine["position"])


def test_choice_and_level_readings_are_fixed_by_the_source():
    levels, labels = ["12", "35", "3"], ["A", "B", "C"]
    # survey options (jsPsych button + 1, Qualtrics numeric recode): numbers are positions
    assert score_choice("3", levels, labels, CHOICE) == ("3", 3)
    assert score_choice("1", levels, labels, CHOICE) == ("12", 1)
    assert score_choice("B", levels, labels, CHOICE) == ("35", 2)
    with pytest.raises(OutsideScale, match="not a screen position 1…3"):
        score_choice("12", levels, labels, CHOICE)
    # the long format names levels; with numeric levels a number is a level, never a position
    assert score_choice("3", levels, labels, LEVEL) == ("3", 3)
    assert score_choice("12", levels, labels, LEVEL) == ("12", 1)
    assert score_choice("c", levels, labels, LEVEL) == ("3", 3)
    with pytest.raises(OutsideScale, match="reads numbers as level names"):
        score_choice("2", levels, labels, LEVEL)
    # levels named like the position labels: the long format reads the level, a survey the position
    assert score_choice("A", ["B", "C", "A"], labels, LEVEL) == ("A", 3)
    assert score_choice("A", ["B", "C", "A"], labels, CHOICE) == ("B", 1)
    # ... and left/right for two clips
    assert score_choice("left", ["right", "left"], [], LEVEL) == ("left", 2)
    assert score_choice("left", ["right", "left"], [], CHOICE) == ("right", 1)
    # without levels like numbers the long format still takes positions, sides and labels
    assert score_choice("2", ["NoCOM", "COM"], ["Left", "Right"], LEVEL) == ("COM", 2)
    # a position label that is a number other than its position is ambiguous in a survey export
    with pytest.raises(OutsideScale, match="ambiguous"):
        score_choice("1", ["x", "y"], ["2", "1"], CHOICE)
    # rankings: jsPsych records the position labels picked, the long format levels
    assert score_ranking(None, "C>A>B", levels, labels, CHOICE) == ["3", "12", "35"]
    assert score_ranking(None, "3>12>35", levels, labels, LEVEL) == ["3", "12", "35"]
    with pytest.raises(OutsideScale):
        score_ranking(None, "12>35>3", levels, labels, CHOICE)   # survey numbers are positions


def test_jspsych_chosen_column_that_contradicts_the_response_is_an_error(tiny_pl, tmp_path):
    sim = _simulated(tiny_pl, participants=6)
    frame = pd.read_csv(io.StringIO(export_text(sim, tiny_pl, "jspsych")), dtype=str, keep_default_na=False)
    row = frame.index[frame["stimulus_id"] != ""][0]
    other = next(level for level in frame.at[row, "positions"].split("|") if level != frame.at[row, "chosen"])
    frame.at[row, "chosen"] = other
    frame.to_csv(tmp_path / "r.csv", index=False)
    with pytest.raises(AnalysisError) as err:
        import_responses(tmp_path / "r.csv", tiny_pl)
    message = str(err.value)
    assert "r.csv" in message and f"row {row + 2}" in message and "column 'chosen'" in message
    assert repr(other) in message and "disagree" in message


# -- F2: several runs of one participant in one file --------------------------------------------------------

def _jspsych_frame(design, sim) -> pd.DataFrame:
    return pd.read_csv(io.StringIO(export_text(sim, design, "jspsych")), dtype=str, keep_default_na=False)


@pytest.fixture(scope="module")
def exp2(tmp_path_factory):
    design = _make_design(tmp_path_factory.mktemp("exp2"), ROOT / "protocols" / "exp2_com_vs_average.yaml", 4)
    return design, _simulated(design, participants=4, seed=2), _simulated(design, participants=4, seed=9)


def _person(frame: pd.DataFrame, participant: str, as_id: str | None = None) -> pd.DataFrame:
    rows = frame[frame["participant"] == participant].copy()
    if as_id is not None:
        rows["participant"] = as_id
    return rows


def _answers_of(result, participant: str) -> dict:
    data = result.data[result.data["participant"] == participant]
    return dict(zip(zip(data["stimulus_id"], data["repetition"].astype(int)), data["chosen"]))


def _session_answers(frame: pd.DataFrame) -> dict:
    rows = frame[frame["stimulus_id"] != ""]
    return dict(zip(zip(rows["stimulus_id"], rows["repetition"].astype(int)), rows["chosen"]))


def _reasons(result, participant: str) -> dict:
    rows = result.exclusions.dropna(subset=["row"])
    return rows[rows["participant"] == participant]["reason"].value_counts().to_dict()


def test_two_complete_runs_in_file_order_keep_the_first_as_duplicate_participant(exp2, tmp_path):
    design, sim_a, sim_b = exp2
    a, b = _jspsych_frame(design, sim_a), _jspsych_frame(design, sim_b)
    first, second = _person(a, "1"), _person(b, "1")          # same list, other answers
    frame = pd.concat([first, second, _person(a, "2")])
    frame.to_csv(tmp_path / "r.csv", index=False)
    result = import_responses(tmp_path / "r.csv", design)
    assert result.reconciles
    assert _answers_of(result, "1") == _session_answers(first)
    second_rows = result.exclusions[result.exclusions["row"].isin(range(len(first) + 2, len(first) + len(second) + 2))]
    assert set(second_rows["reason"]) == {"duplicate participant id"} and len(second_rows) == len(second)
    assert "session 2 of 2 of participant '1'" in second_rows["detail"].iloc[0]
    assert "already imported from session 1" in second_rows["detail"].iloc[0]


def test_unfinished_run_then_complete_run_imports_the_complete_one(exp2, tmp_path):
    design, sim_a, sim_b = exp2
    a, b = _jspsych_frame(design, sim_a), _jspsych_frame(design, sim_b)
    broken = _person(b, "2", "1").iloc[:30]                      # another list, stopped early: no end row
    complete = _person(a, "1")
    pd.concat([broken, complete]).to_csv(tmp_path / "r.csv", index=False)
    result = import_responses(tmp_path / "r.csv", design)
    assert result.reconciles
    assert _answers_of(result, "1") == _session_answers(complete)
    assert _reasons(result, "1") == {"unfinished": 30, "not a stimulus trial": (complete["stimulus_id"] == "").sum()}
    unfinished = result.exclusions[result.exclusions["reason"] == "unfinished"]["detail"].iloc[0]
    assert "session 1 of 2" in unfinished and "list 2" in unfinished


def test_a_blank_session_cell_stays_in_its_run(exp2, tmp_path):
    """Two sessions named by a session column; two answer rows of the first leave the cell blank. They used to
    form a run of their own without a closing row, and the participant's complete first run was lost."""
    design, sim_a, sim_b = exp2
    a, b = _jspsych_frame(design, sim_a), _jspsych_frame(design, sim_b)
    first, second = _person(a, "1").assign(session="s1"), _person(b, "1").assign(session="s2")
    answers = first.index[first["stimulus_id"] != ""]
    first.loc[answers[3:5], "session"] = ""
    pd.concat([first, second]).to_csv(tmp_path / "r.csv", index=False)
    result = import_responses(tmp_path / "r.csv", design)
    assert result.reconciles
    assert _answers_of(result, "1") == _session_answers(first)
    assert "unfinished" not in _reasons(result, "1")


def test_two_runs_on_different_lists_shuffled_are_told_apart_by_list(exp2, tmp_path):
    design, sim_a, _ = exp2
    a = _jspsych_frame(design, sim_a)
    one, two = _person(a, "1"), _person(a, "2", "1")             # participant id 1 ran lists 1 and 2
    frame = pd.concat([one, two, _person(a, "3")]).sample(frac=1, random_state=4)
    frame.to_csv(tmp_path / "r.csv", index=False)
    result = import_responses(tmp_path / "r.csv", design)
    assert result.reconciles
    first_list = frame[frame["participant"] == "1"]["list"].iloc[0]   # the run whose first row comes first
    kept, other = (one, two) if first_list == "1" else (two, one)
    assert _answers_of(result, "1") == _session_answers(kept)   # one run's answers, not a mix
    assert len(result.data[result.data["participant"] == "1"]) == (kept["stimulus_id"] != "").sum()
    assert _reasons(result, "1")["duplicate participant id"] == len(other)


def test_two_runs_of_the_same_list_shuffled_cannot_be_told_apart_and_are_not_merged(exp2, tmp_path):
    design, sim_a, sim_b = exp2
    a, b = _jspsych_frame(design, sim_a), _jspsych_frame(design, sim_b)
    frame = pd.concat([_person(a, "1"), _person(b, "1"), _person(a, "2")]).sample(frac=1, random_state=1)
    frame.to_csv(tmp_path / "r.csv", index=False)
    result = import_responses(tmp_path / "r.csv", design)
    assert result.reconciles
    assert set(result.data["participant"]) == {"2"}
    assert _reasons(result, "1") == {"duplicate participant id": 2 * len(_person(a, "1"))}
    detail = result.exclusions[result.exclusions["participant"] == "1"]["detail"].iloc[0]
    assert "trial_index 0 appears 2 times" in detail and "cannot be told apart" in detail


def test_one_run_with_shuffled_rows_is_imported_whole(exp2, tmp_path):
    design, sim_a, _ = exp2
    a = _jspsych_frame(design, sim_a)
    a.sample(frac=1, random_state=7).to_csv(tmp_path / "r.csv", index=False)
    result = import_responses(tmp_path / "r.csv", design)
    assert result.reconciles and set(result.exclusions["reason"].dropna()) <= {"not a stimulus trial",
                                                                               "column not imported"}
    assert _answers_of(result, "1") == _session_answers(_person(a, "1"))


def test_long_file_with_a_participant_twice_excludes_the_second_run(tiny_pl, tmp_path):
    sim_a, sim_b = _simulated(tiny_pl, 6, seed=1), _simulated(tiny_pl, 6, seed=2)
    a = pd.read_csv(io.StringIO(export_text(sim_a, tiny_pl, "long")), dtype=str)
    b = pd.read_csv(io.StringIO(export_text(sim_b, tiny_pl, "long")), dtype=str)
    again = b[b["participant"] == "1"]
    pd.concat([a, again]).to_csv(tmp_path / "r.csv", index=False)
    result = import_responses(tmp_path / "r.csv", tiny_pl)
    assert result.reconciles
    rows = result.exclusions.dropna(subset=["row"])
    assert rows["reason"].tolist() == ["duplicate participant id"] * len(again)
    mine = result.data[result.data["participant"] == "1"].sort_values("trial")
    assert mine["chosen"].tolist() == a[a["participant"] == "1"]["response"].tolist()


def test_long_file_numbering_trials_per_block_is_one_run(tiny_pl, tmp_path):
    sim = _simulated(tiny_pl, 6, seed=1)
    frame = pd.read_csv(io.StringIO(export_text(sim, tiny_pl, "long")), dtype=str)
    frame["trial"] = "1"       # each answer numbered 1 (e.g. per block): a restart, but no stimulus answered twice
    frame.to_csv(tmp_path / "r.csv", index=False)
    result = import_responses(tmp_path / "r.csv", tiny_pl)
    assert result.reconciles and result.n_excluded_rows == 0 and len(result.data) == len(sim)


def test_long_file_numbering_trials_per_block_with_a_participant_twice(exp2, tmp_path):
    """Per-block trial numbers and a second run of participant 1: every block used to count as a run, so
    block 1 was kept and the participant lost to missing cells; the first run is now kept whole."""
    design, sim_a, sim_b = exp2
    a = pd.read_csv(io.StringIO(export_text(sim_a, design, "long")), dtype=str, keep_default_na=False)
    b = pd.read_csv(io.StringIO(export_text(sim_b, design, "long")), dtype=str, keep_default_na=False)
    frame = pd.concat([a, b[b["participant"] == "1"]], ignore_index=True)
    frame["trial"] = frame.groupby(["participant", "block", frame.index >= len(a)]).cumcount() + 1
    frame.to_csv(tmp_path / "r.csv", index=False)
    result = import_responses(tmp_path / "r.csv", design)
    assert result.reconciles
    assert _reasons(result, "1") == {"duplicate participant id": int((b["participant"] == "1").sum())}
    assert len(result.data[result.data["participant"] == "1"]) == int((a["participant"] == "1").sum())


def test_a_likert_scale_labelled_0_to_4_reads_the_same_in_every_format(tmp_path):
    """A Qualtrics choice-text export writes the scale's labels: with labels 0…4, "3" is the fourth point and
    "0" the first. It was read as the rating 3, and "0" as outside the scale (every respondent excluded)."""
    text = (ROOT / "protocols" / "exp1_shape_motion.yaml").read_text()
    old = "labels: [Very Inconsistent, Inconsistent, Neutral, Consistent, Very Consistent]"
    assert old in text
    protocol = tmp_path / "p.yaml"
    protocol.write_text(text.replace(old, 'labels: ["0", "1", "2", "3", "4"]'))
    design = _make_design(tmp_path, protocol, 4)
    sim = _simulated(design, participants=4, seed=3)
    ratings = {}
    for fmt in ("long", "qualtrics", "qualtrics-numeric", "jspsych"):
        (tmp_path / f"{fmt}.csv").write_text(export_text(sim, design, fmt), encoding="utf-8")
        data = import_responses(tmp_path / f"{fmt}.csv", design).data
        ratings[fmt] = data.sort_values(["participant", "stimulus_id", "repetition"])["rating"].tolist()
    assert len(ratings["long"]) == len(sim) and all(r == ratings["long"] for r in ratings.values())


# -- F3: a model the data do not allow -------------------------------------------------------------------------

@pytest.fixture(scope="module")
def rule_following_likert(tmp_path_factory):
    """Exp. 1, four respondents who give 5 when BODY = MOTION and 1 otherwise (no residual variance)."""
    folder = tmp_path_factory.mktemp("exp1_rule")
    design = _make_design(folder, ROOT / "protocols" / "exp1_shape_motion.yaml", 4)
    sim = _simulated(design, participants=4, seed=1)
    frame = pd.read_csv(io.StringIO(export_text(sim, design, "long")), dtype=str, keep_default_na=False)
    cells = design.conditions.set_index("stimulus_id")
    frame["response"] = ["5" if cells.at[s, "BODY"] == cells.at[s, "MOTION"] else "1" for s in frame["stimulus_id"]]
    frame.to_csv(folder / "responses.csv", index=False)
    return folder, design


def test_additional_models_that_cannot_be_estimated_are_marked_not_computed(rule_following_likert):
    from analysis.models import additional_models, not_computed_models
    folder, design = rule_following_likert
    data = import_responses(folder / "responses.csv", design).data
    table = additional_models(data, design)       # used to raise "need covariance of parameters"
    reasons = not_computed_models(table)
    ordinal = "cumulative link mixed model (Laplace, as ordinal::clmm)"
    assert ordinal in reasons
    assert "no covariance matrix" in reasons[ordinal] and "lowest or highest category" in reasons[ordinal]
    assert "single rating across all participants" in reasons[ordinal]
    assert table[table["term"] == "not computed"][["df", "chi2", "p"]].isna().all().all()


def test_analyze_writes_the_report_when_the_ordinal_model_cannot_be_fitted(rule_following_likert, run_cli,
                                                                           tmp_path):
    folder, _ = rule_following_likert
    code, out, err = run_cli("analyze", folder / "design", "--responses", folder / "responses.csv",
                             "--out", tmp_path / "report")
    assert code == 0 and "Traceback" not in err, err
    report = tmp_path / "report"
    models = pd.read_csv(report / "additional_models.csv")
    ordinal = models[models["model"] == "cumulative link mixed model (Laplace, as ordinal::clmm)"]
    assert ordinal["term"].tolist() == ["not computed"] and ordinal["note"].iloc[0].startswith("not computed: ")
    html = (report / "report.html").read_text(encoding="utf-8")
    assert "cumulative link mixed model (Laplace, as ordinal::clmm) — not computed: the fit has no covariance matrix" in html


def test_gee_under_separation_is_not_computed_instead_of_negative_chi2(tmp_path):
    """Exp. 2 with every choice in one cell (walk/F/Hi1) the same: the GEE's robust covariance is indefinite
    and gave Wald χ² of −40, −280 and −3765 with p = 1; it is now marked not computed, naming the cell."""
    from analysis.models import additional_models, not_computed_models
    design = _make_design(tmp_path, ROOT / "protocols" / "exp2_com_vs_average.yaml", 16)
    frame = pd.read_csv(io.StringIO(export_text(_simulated(design, participants=16, seed=7), design, "long")),
                        dtype=str, keep_default_na=False)
    cells = design.conditions.set_index("stimulus_id")
    one_cell = [(cells.at[s, "GAIT"], cells.at[s, "SEX"], cells.at[s, "BODY"]) == ("walk", "F", "Hi1")
                for s in frame["stimulus_id"]]
    frame.loc[one_cell, "response"] = "NoCOM"
    frame.to_csv(tmp_path / "responses.csv", index=False)
    table = additional_models(import_responses(tmp_path / "responses.csv", design).data, design)
    reasons = not_computed_models(table)
    gee = "logistic GEE (exchangeable, robust SE)"
    assert gee in reasons and "not positive semi-definite" in reasons[gee] and "walk/F/Hi1" in reasons[gee]
    assert (table["chi2"].dropna() >= 0).all()


# -- F4: tags that differ only in case or punctuation ---------------------------------------------------------

def test_tags_differing_only_in_punctuation_are_not_merged():
    index = TagIndex(["X_Y-Z", "X-Y_Z", "walk-0.5", "walk-0_5"])
    assert index.match("X_Y-Z") == ("X_Y-Z", None) and index.match("X-Y_Z") == ("X-Y_Z", None)
    assert index.match("walk-0.5") == ("walk-0.5", None) and index.match("walk-0_5") == ("walk-0_5", None)
    assert index.match("walk-0.5_r2") == ("walk-0.5", 2)
    for tag, names in [("x_y_z", "'X-Y_Z' and 'X_Y-Z'"), ("WALK-0.5", "'walk-0.5' and 'walk-0_5'")]:
        with pytest.raises(AnalysisError) as err:
            index.match(tag)
        assert repr(tag) in str(err.value) and names in str(err.value)
    # a loose match that is also a repetition of another stimulus is ambiguous too
    with pytest.raises(AnalysisError, match="repetition 5 of stimulus 'walk-0'"):
        TagIndex(["walk-0", "walk-0.5"]).match("walk-0_5")
    # the exporter's tag form (characters Qualtrics cannot hold → '_') still matches
    assert TagIndex(["x+y", "z"]).match("x_y") == ("x+y", None)


def test_qualtrics_columns_of_colliding_ids_go_to_their_own_stimuli(tmp_path):
    folder = tmp_path / "design"
    shutil.copytree(DATA / "mini_afc", folder)
    old, new = "walk-Lo1-COM_NoCOM", "walk-Lo1_NoCOM-COM"    # same key as walk-Lo1-NoCOM_COM
    for name in ("conditions.csv", "trials.csv"):
        (folder / name).write_text((folder / name).read_text().replace(old, new))
    design = load_design(folder)
    original = import_responses(DATA / "qualtrics_afc_text.csv", load_design(DATA / "mini_afc"))
    text = (DATA / "qualtrics_afc_text.csv").read_text()
    renamed = _write(tmp_path, "q.csv", text.replace(old, new))
    result = import_responses(renamed, design)
    expected = {(p, s.replace(old, new)): c for (p, s), c in _chosen(original).items()}
    assert result.reconciles and _chosen(result) == expected
    header, rest = text.split("\n", 1)
    clash = _write(tmp_path, "clash.csv", header.replace(old, "WALK-LO1-NOCOM-COM") + "\n" + rest)
    with pytest.raises(AnalysisError) as err:
        import_responses(clash, design)
    message = str(err.value)
    assert "clash.csv" in message and "column 'WALK-LO1-NOCOM-COM'" in message
    assert f"'{new}'" in message and "'walk-Lo1-NoCOM_COM'" in message


def test_ranking_answers_get_their_trial_number_in_every_format(tmp_path):
    """A ranking question's Qualtrics columns are <tag>_1 … <tag>_k while the block's _DO list names <tag>:
    every ranking answer imported with an empty trial number from Qualtrics, numbered from jsPsych."""
    text = (ROOT / "protocols" / "thesis_validation.yaml").read_text()
    for old, new in (("arrangements: fixed ", "arrangements: latin_square "), ("counterbalance: between", "counterbalance: within")):
        assert old in text
        text = text.replace(old, new)
    protocol = tmp_path / "p.yaml"
    protocol.write_text(text)
    design = _make_design(tmp_path, protocol, 4)
    sim = _simulated(design, participants=4, seed=5)
    trials = {}
    for fmt in ("long", "qualtrics", "qualtrics-numeric", "jspsych"):
        (tmp_path / f"{fmt}.csv").write_text(export_text(sim, design, fmt, seed=5), encoding="utf-8")
        data = import_responses(tmp_path / f"{fmt}.csv", design).data.sort_values(["participant", "stimulus_id"])
        trials[fmt] = data["trial"].astype("Int64").tolist()
    assert len(trials["jspsych"]) == 16 and sorted(set(trials["jspsych"])) == [1, 2, 3, 4]
    assert all(t == trials["jspsych"] for t in trials.values()), trials
