"""Response import on hand-written exports (tests/data/responses/README.md lists what each file exercises)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.errors import AnalysisError
from analysis.io_design import load_design
from analysis.measures import anova_input
from analysis.responses import import_responses, read_response_file
from analysis.responses.inspect import inspect_file

DATA = Path(__file__).parent / "data" / "responses"
P01 = {("walk", "Hi1"): 2.5, ("walk", "Lo1"): 4.5, ("jog", "Hi1"): 1.5, ("jog", "Lo1"): 4.0}
P02 = {("walk", "Hi1"): 4.5, ("walk", "Lo1"): 2.0, ("jog", "Hi1"): 3.5, ("jog", "Lo1"): 2.0}


@pytest.fixture(scope="module")
def likert():
    return load_design(DATA / "mini_likert")


@pytest.fixture(scope="module")
def afc():
    return load_design(DATA / "mini_afc")


def cell_means(result, design) -> dict:
    frame = anova_input(result.data, design).data
    return {(r["participant"], r["GAIT"], r["BODY"]): r["rating"] for r in frame.to_dict("records")}


def expected_means(**people) -> dict:
    return {(p, g, b): v for p, cells in people.items() for (g, b), v in cells.items()}


def test_qualtrics_3row_choice_text_german_question_text(likert):
    result = import_responses(DATA / "qualtrics_likert_text.csv", likert)
    assert result.format == "qualtrics"
    assert (result.n_rows, result.n_imported_rows, result.n_excluded_rows) == (3, 2, 1)
    assert result.reconciles
    excluded = result.exclusions.dropna(subset=["row"])
    assert excluded[["row", "participant", "reason"]].values.tolist() == [[6, "p03", "unfinished"]]
    assert "Progress = 40" in excluded["detail"].iloc[0]
    assert cell_means(result, likert) == expected_means(p01=P01, p02=P02)
    # the practice answer is imported and flagged, not counted in the cells
    practice = result.data[result.data["practice"]]
    assert practice[["participant", "stimulus_id", "rating"]].values.tolist() == [
        ["p01", "practice-F-walk-P1", 3], ["p02", "practice-M-walk-P1", 2]]


def test_display_order_columns_give_the_presentation_order(likert):
    result = import_responses(DATA / "qualtrics_likert_text.csv", likert)
    p01 = result.data[result.data["participant"] == "p01"].sort_values("trial")
    trials = likert.trials[likert.trials["participant"] == "1"]
    assert p01[["stimulus_id", "repetition"]].astype(str).values.tolist() == \
        trials[["stimulus_id", "repetition"]].values.tolist()
    assert p01["trial"].tolist() == list(range(1, 10))


def test_numeric_export_and_legacy_export_equal_the_text_export(likert):
    text = import_responses(DATA / "qualtrics_likert_text.csv", likert)
    numeric = import_responses(DATA / "qualtrics_likert_numeric.csv", likert)
    legacy = import_responses(DATA / "qualtrics_legacy.csv", likert)
    assert legacy.format == "qualtrics-legacy" and numeric.format == "qualtrics"
    cols = ["participant", "stimulus_id", "repetition", "rating"]
    key = ["participant", "stimulus_id", "repetition"]
    for other in (numeric, legacy):
        pd.testing.assert_frame_equal(other.data[cols].sort_values(key).reset_index(drop=True),
                                      text.data[cols].sort_values(key).reset_index(drop=True))
    assert numeric.exclusions.dropna(subset=["row"])["reason"].tolist() == ["unfinished"]
    assert legacy.n_excluded_rows == 0 and legacy.n_rows == 2


def test_afc_left_right_choice_text_maps_to_the_chosen_method(afc):
    result = import_responses(DATA / "qualtrics_afc_text.csv", afc)
    assert result.reconciles and result.n_imported_rows == 2
    chosen = {(r["participant"], r["stimulus_id"]): r["chosen"] for r in result.data.to_dict("records")}
    p1 = "R_afc0001aaaaaa"
    assert chosen[(p1, "walk-Hi1-NoCOM_COM")] == "NoCOM"      # Left, NoCOM on the left
    assert chosen[(p1, "walk-Hi1-COM_NoCOM")] == "NoCOM"      # Right, NoCOM on the right
    assert chosen[(p1, "walk-Lo1-NoCOM_COM")] == "COM"
    assert chosen[(p1, "jog-Hi1-COM_NoCOM")] == "COM"
    pct = anova_input(result.data, afc).data
    nocom = pct[pct["METHOD"] == "NoCOM"].set_index(["participant", "GAIT", "BODY"])["percent"].to_dict()
    assert nocom == {(p1, "walk", "Hi1"): 100.0, (p1, "walk", "Lo1"): 50.0, (p1, "jog", "Hi1"): 50.0,
                     (p1, "jog", "Lo1"): 100.0, **{("R_afc0002bbbbbb", g, b): 50.0
                                                   for g in ("walk", "jog") for b in ("Hi1", "Lo1")}}
    # percentages summed in float: equal to 100 up to rounding, not bit for bit
    assert np.allclose(pct.groupby(["participant", "GAIT", "BODY"])["percent"].sum(), 100.0, atol=1e-9)


def test_corrupted_export_lists_every_row_with_its_reason(likert):
    result = import_responses(DATA / "qualtrics_corrupt.csv", likert)
    assert result.n_rows == 8 and result.reconciles
    rows = result.excluded_rows
    assert dict(zip(rows["row"], rows["reason"])) == {
        5: "duplicate participant id", 7: "missing cells",
        8: "survey preview or test", 9: "malformed row", 10: "several between-subject groups"}
    # p04's one answer outside the scale excludes that answer, not p04 (it used to exclude the whole row)
    answers = result.excluded_answers
    assert answers[["row", "participant", "reason", "column"]].values.tolist() == [
        [6, "p04", "answer outside the scale", "F-walk-Lo1_r2"]]
    assert "'7' is outside 1…5" in answers["detail"].iloc[0]
    assert sorted(result.data["participant"].unique()) == ["p01", "p04", "p09"]
    assert len(result.data[result.data["participant"] == "p04"]) == 8     # 9 answers, one excluded
    columns = result.exclusions[result.exclusions["row"].isna()]
    assert columns[["reason", "column"]].values.tolist() == [["unknown export tag", "Q99"]]
    missing = rows.set_index("row").loc[7]
    assert "1 of 4 design cells" in missing["detail"] and missing["column"] == "F-jog-Lo1_r1, F-jog-Lo1_r2"


def test_jspsych_csv_unfinished_participant_and_non_trial_rows(likert):
    result = import_responses(DATA / "jspsych_likert.csv", likert)
    assert result.format == "jspsych-csv"
    assert (result.n_rows, result.n_imported_rows, result.n_excluded_rows) == (14, 9, 5)
    reasons = result.exclusions["reason"].value_counts().to_dict()
    assert reasons == {"not a stimulus trial": 2, "unfinished": 3}
    assert cell_means(result, likert) == expected_means(p01=P01)
    first = result.data.sort_values("trial").iloc[0]
    assert (first["stimulus_id"], first["rating"], first["rt"]) == ("F-jog-Lo1", 4, pytest.approx(2.301))


def test_long_csv_excludes_single_answers_and_duplicates(afc):
    result = import_responses(DATA / "long_afc.csv", afc)
    assert result.format == "long"
    assert (result.n_rows, result.n_imported_rows, result.n_excluded_rows) == (17, 15, 2)
    rows = result.exclusions.set_index("row")
    assert rows.loc[6, "reason"] == "answer outside the scale"
    assert rows.loc[18, "reason"] == "duplicate answer"
    pct = anova_input(result.data, afc).data
    a = pct[(pct["participant"] == "A") & (pct["METHOD"] == "NoCOM")].set_index(["GAIT", "BODY"])["percent"]
    assert a.to_dict() == {("jog", "Hi1"): 0.0, ("jog", "Lo1"): 100.0, ("walk", "Hi1"): 100.0, ("walk", "Lo1"): 0.0}


@pytest.mark.parametrize("name, message", [
    ("bad_binary.xlsx", "not a text file"),
    ("bad_latin1.csv", "not UTF-8"),
    ("bad_no_header.csv", "no recognisable header"),
    ("bad_empty.csv", "empty"),
    ("bad_utf16.csv", "UTF-16"),
    ("does_not_exist.csv", "not found"),
])
def test_bad_files_raise_a_clear_error(name, message, likert):
    with pytest.raises(AnalysisError, match=message) as info:
        import_responses(DATA / name, likert)
    assert name in str(info.value)


def test_format_detection():
    assert read_response_file(DATA / "qualtrics_legacy.csv").format == "qualtrics-legacy"
    raw = read_response_file(DATA / "qualtrics_likert_text.csv")
    assert raw.format == "qualtrics" and raw.row_numbers == [4, 5, 6]
    assert raw.question_text[17].startswith("Wie stimmig")


def test_inspect_reports_format_counts_and_question_text():
    info = inspect_file(DATA / "qualtrics_likert_text.csv")
    assert (info["format"], info["responses"], info["unfinished"]) == ("qualtrics", 3, 1)
    kinds = {c["name"]: c["kind"] for c in info["columns"]}
    assert kinds["Finished"] == "metadata" and kinds["F_walk_DO"] == "display order"
    assert kinds["F-walk-Hi1_r1"] == "question"
    text = {c["name"]: c["question_text"] for c in info["columns"]}
    assert text["M-jog-Lo1_r2"] == "Wie stimmig ist die Bewegung mit der Körperform der Figur? - M-jog-Lo1_r2"


def test_cli_inspect_and_bad_file_exit_code(run_cli):
    code, out, _ = run_cli("responses", "inspect", str(DATA / "qualtrics_legacy.csv"))
    assert code == 0 and "format: qualtrics-legacy" in out and "responses: 2" in out
    code, out, _ = run_cli("responses", "inspect", str(DATA / "jspsych_likert.csv"), "--json")
    assert code == 0 and '"responses": 11' in out
    code, out, _ = run_cli("responses", "inspect", str(DATA / "qualtrics_corrupt.csv"), "--design",
                           str(DATA / "mini_likert"))
    assert code == 0 and "3 rows imported, 5 excluded" in out and "columns not imported: Q99" in out
    assert "answers excluded one by one (the rest of their row imported): 1 (answer outside the scale: 1)" in out
    code, _, err = run_cli("responses", "inspect", str(DATA / "bad_binary.xlsx"))
    assert code == 2 and "not a text file" in err and "Traceback" not in err


def test_export_tag_column_of_the_manifest_maps_other_tags(tmp_path):
    """A manifest/conditions `export_tag` column lets surveys use their own question names (Q1, Q2 …)."""
    import shutil
    folder = tmp_path / "design"
    shutil.copytree(DATA / "mini_afc", folder)
    conditions = pd.read_csv(folder / "conditions.csv", dtype=str, keep_default_na=False)
    manifest = conditions[["stimulus_id"]].assign(export_tag=[f"Q{i + 1}" for i in range(len(conditions))])
    manifest.to_csv(folder / "manifest.csv", index=False)
    text = (DATA / "qualtrics_afc_text.csv").read_text()
    header, rest = text.split("\n", 1)
    for i, sid in enumerate(conditions["stimulus_id"]):
        header = header.replace(f",{sid},", f",Q{i + 1},")
    (tmp_path / "q.csv").write_text(header + "\n" + rest)
    design = load_design(folder)
    renamed = import_responses(tmp_path / "q.csv", design)
    original = import_responses(DATA / "qualtrics_afc_text.csv", design)
    assert renamed.reconciles and len(renamed.data) == 16
    key = ["participant", "stimulus_id"]
    assert renamed.data.sort_values(key)[key + ["chosen"]].values.tolist() == \
        original.data.sort_values(key)[key + ["chosen"]].values.tolist()


def test_a_folder_of_per_participant_files(likert, tmp_path):
    """The self-hosted survey saves one CSV per participant; a folder of them imports as one data set."""
    lines = (DATA / "jspsych_likert.csv").read_text().splitlines(keepends=True)
    header, p01, p09 = lines[0], lines[1:12], lines[12:]
    (tmp_path / "shapemotion_mini_likert_p01.csv").write_text(header + "".join(p01))
    (tmp_path / "shapemotion_mini_likert_p09.csv").write_text(header + "".join(p09))
    (tmp_path / "shapemotion_mini_likert_p01_again.csv").write_text(header + "".join(p01))
    (tmp_path / "notes.txt").write_text("not a response file")
    result = import_responses(tmp_path, likert)
    assert result.format == "jspsych-csv" and result.n_rows == 11 + 3 + 11
    assert result.reconciles and result.n_imported_rows == 9
    assert set(result.data["file"]) == {"shapemotion_mini_likert_p01.csv"}
    dup = result.exclusions[result.exclusions["reason"] == "duplicate participant id"]
    assert len(dup) == 9 and set(dup["file"]) == {"shapemotion_mini_likert_p01_again.csv"}
    assert cell_means(result, likert) == expected_means(p01=P01)
    (tmp_path / "empty").mkdir()
    with pytest.raises(AnalysisError, match="no .csv or .json"):
        import_responses(tmp_path / "empty", likert)


def test_a_folder_lists_what_it_does_not_read(likert, tmp_path):
    """Subfolders, hidden and other files used to be dropped silently ("files: 1"); now each is listed, in
    inspect and in the import's exclusions / summary, and the subfolder's files are counted."""
    lines = (DATA / "jspsych_likert.csv").read_text().splitlines(keepends=True)
    header, p01, p09 = lines[0], lines[1:12], lines[12:]
    (tmp_path / "p01.csv").write_text(header + "".join(p01))
    (tmp_path / "sub" / "more").mkdir(parents=True)
    (tmp_path / "sub" / "more" / "p09.csv").write_text(header + "".join(p09))
    (tmp_path / "README.txt").write_text("notes")
    (tmp_path / ".DS_Store").write_text("x")
    (tmp_path / ".p09_hidden.csv").write_text(header + "".join(p09))
    expected = [{"name": ".DS_Store", "reason": "hidden file"},
                {"name": ".p09_hidden.csv", "reason": "hidden file"},
                {"name": "README.txt", "reason": "not a .csv or .json file"},
                {"name": "sub/", "reason": "subfolder: subfolders are not searched; it holds 1 .csv/.json file"}]
    info = inspect_file(tmp_path)
    assert [f["file"] for f in info["files"]] == ["p01.csv"] and info["skipped"] == expected
    from analysis.responses.inspect import describe_text
    text = describe_text(info)
    assert "skipped (not read): 4" in text and "  sub/: subfolder: subfolders are not searched" in text
    result = import_responses(tmp_path, likert)
    assert result.reconciles and result.n_rows == 11 and set(result.data["file"]) == {"p01.csv"}
    assert result.summary()["files_not_read"] == expected and result.summary()["columns_not_imported"] == []
    skipped = result.exclusions[result.exclusions["reason"] == "file not read"]
    assert skipped["file"].tolist() == [e["name"] for e in expected] and skipped["row"].isna().all()


def test_a_folder_whose_responses_are_only_in_a_subfolder_says_so(likert, tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "p01.csv").write_text((DATA / "jspsych_likert.csv").read_text())
    (tmp_path / "notes.txt").write_text("x")
    for call in (lambda: import_responses(tmp_path, likert), lambda: inspect_file(tmp_path)):
        with pytest.raises(AnalysisError) as err:
            call()
        assert "no .csv or .json response file directly inside it" in str(err.value)
        assert "a/ (subfolder: subfolders are not searched; it holds 1 .csv/.json file)" in str(err.value)
        assert "notes.txt (not a .csv or .json file)" in str(err.value) and "pass the subfolder" in str(err.value)
