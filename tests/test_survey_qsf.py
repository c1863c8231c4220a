"""The QSF export against the structure of real Qualtrics exports, and the procedure it encodes."""

from __future__ import annotations

import json
import re
from collections import Counter
from pathlib import Path

import pytest

from stimuli.design import build_design, write_design
from stimuli.protocol import load_protocol
from stimuli.survey.qsf import build_qsf, qsf_text
from stimuli.survey.source import load_source

REFERENCE = Path(__file__).parent / "data" / "qualtrics_reference" / "reference_export.qsf"
BASE = "https://media.example.org/study-1"


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    """Design folders of the five bundled protocols."""
    root = Path(__file__).resolve().parents[1] / "protocols"
    out = {}
    for name in ("exp1_shape_motion", "exp2_com_vs_average", "thesis_pointlight", "thesis_mesh", "thesis_validation"):
        folder = tmp_path_factory.mktemp(name)
        write_design(build_design(load_protocol(root / f"{name}.yaml")), folder)
        out[name] = folder
    return out


@pytest.fixture(scope="module")
def qsfs(folders):
    return {name: build_qsf(load_source(folder), BASE) for name, folder in folders.items()}


def reference() -> dict:
    return json.loads(REFERENCE.read_text())


def elements(qsf: dict, kind: str) -> list[dict]:
    return [e for e in qsf["SurveyElements"] if e["Element"] == kind]


def questions(qsf: dict) -> list[dict]:
    return [e["Payload"] for e in elements(qsf, "SQ")]


def flow_nodes(node: dict):
    yield node
    for child in node.get("Flow", []):
        yield from flow_nodes(child)


def blocks(qsf: dict) -> dict[str, dict]:
    return {b["ID"]: b for b in elements(qsf, "BL")[0]["Payload"]}


# -- structure ------------------------------------------------------------------------------------

def test_survey_entry_has_the_keys_of_a_real_export(qsfs):
    for qsf in qsfs.values():
        assert list(qsf) == ["SurveyEntry", "SurveyElements"]
        assert set(qsf["SurveyEntry"]) == set(reference()["SurveyEntry"])


def test_every_element_is_shaped_like_the_reference(qsfs):
    ref_kinds = {e["Element"] for e in reference()["SurveyElements"]}
    ref_keys = set(reference()["SurveyElements"][0])
    for qsf in qsfs.values():
        kinds = Counter(e["Element"] for e in qsf["SurveyElements"])
        assert set(kinds) == ref_kinds
        assert all(kinds[k] == 1 for k in kinds if k != "SQ")
        assert all(set(e) == ref_keys for e in qsf["SurveyElements"])
        survey_id = qsf["SurveyEntry"]["SurveyID"]
        assert all(e["SurveyID"] == survey_id for e in qsf["SurveyElements"])
        assert elements(qsf, "QC")[0]["SecondaryAttribute"] == str(kinds["SQ"])


@pytest.mark.parametrize("qtype", ["MC", "DB", "RO"])
def test_question_payloads_have_the_reference_fields(qsfs, qtype):
    ref = [q for q in questions(reference()) if q["QuestionType"] == qtype]
    required = set.intersection(*(set(q) for q in ref)) | ({"QuestionJS"} if qtype != "DB" else set())
    mine = [q for qsf in qsfs.values() for q in questions(qsf) if q["QuestionType"] == qtype]
    assert mine, qtype
    for q in mine:
        missing = required - set(q)
        assert not missing, (q["DataExportTag"], missing)
        assert q["Selector"] in {r["Selector"] for r in ref}
        if qtype != "DB":
            assert list(q["Choices"]) == q["ChoiceOrder"] == [str(i) for i in range(1, len(q["Choices"]) + 1)]
            assert q["Validation"]["Settings"]["ForceResponse"] == "ON"


def test_flow_and_block_elements_have_the_reference_keys(qsfs):
    ref_nodes = {n["Type"]: set(n) for n in flow_nodes(elements(reference(), "FL")[0]["Payload"])}
    ref_options = set(next(b for b in elements(reference(), "BL")[0]["Payload"] if "Options" in b)["Options"])
    for qsf in qsfs.values():
        root = elements(qsf, "FL")[0]["Payload"]
        ids = [n["FlowID"] for n in flow_nodes(root)]
        assert len(ids) == len(set(ids)) and root["Properties"]["Count"] == max(int(i[3:]) for i in ids)
        for node in flow_nodes(root):
            assert set(node) == ref_nodes[node["Type"]], node["Type"]
        for block in blocks(qsf).values():
            assert set(block.get("Options", {})) <= ref_options | {"Randomization"}
        referenced = {n["ID"] for n in flow_nodes(root) if "ID" in n}
        assert referenced == {b["ID"] for b in blocks(qsf).values() if b["Type"] != "Trash"}
        in_blocks = [e["QuestionID"] for b in blocks(qsf).values() for e in b["BlockElements"]
                     if e["Type"] == "Question"]
        assert sorted(in_blocks) == sorted(q["QuestionID"] for q in questions(qsf))


def test_question_descriptions_are_plain_text_as_qualtrics_writes_them(qsfs):
    """Qualtrics exports ``QuestionDescription`` (also the SQ ``SecondaryAttribute``, the label in the data
    export's second header row) as plain text: tags stripped and entities decoded (a real export has
    ``&nbsp;`` in the text and U+00A0 in the description). The escaped question text must not leak
    ``&#x27;`` into it (``&lt;``/``&gt;`` may stay: protocol markup is never raw, see test_survey_exports)."""
    for qsf in qsfs.values():
        for element in elements(qsf, "SQ"):
            description = element["Payload"]["QuestionDescription"]
            assert element["SecondaryAttribute"] == description
            assert "<" not in description and not re.search(r"&(#x27|#39|quot|amp);", description), description
    pointlight = [q for q in answered(qsfs["thesis_pointlight"])]
    assert {q["QuestionDescription"] for q in pointlight} == {"Which walker looks like an obese person's walk?"}
    assert all("person&#x27;s walk?" in q["QuestionText"] for q in pointlight)   # the HTML stays escaped
    from stimuli.survey.qsf_questions import plain

    assert plain("Rock&amp;roll") == "Rock&roll"                # an ampersand near the end is kept
    assert plain("Rock&amp;roll", limit=6) == "Rock"            # a cut never ends inside an entity


# -- the procedure ----------------------------------------------------------------------------------

def answered(qsf: dict) -> list[dict]:
    return [q for q in questions(qsf) if q["QuestionType"] != "DB"]


def test_exp1_questions_tags_and_likert_labels(qsfs, folders):
    qsf = qsfs["exp1_shape_motion"]
    tags = [q["DataExportTag"] for q in answered(qsf)]
    tests = [t for t in tags if not t.startswith("practice-")]
    # 2 SEX groups x 2 GAIT blocks x 16 stimuli x 2 repetitions; practice 4 per block
    assert len(tests) == 128 and len(tags) - len(tests) == 16
    stimuli = {s.stimulus_id for s in load_source(folders["exp1_shape_motion"]).of_kind("test")}
    assert {t.rsplit("_r", 1)[0] for t in tests} == stimuli
    assert Counter(t.rsplit("_r", 1)[1] for t in tests) == {"1": 64, "2": 64}
    labels = ["Very Inconsistent", "Inconsistent", "Neutral", "Consistent", "Very Consistent"]
    for q in answered(qsf):
        assert [c["Display"] for c in q["Choices"].values()] == labels
        assert q["RecodeValues"] == {str(i): str(i) for i in range(1, 6)}


def test_exp1_between_groups_are_balanced_by_an_even_randomizer(qsfs):
    root = elements(qsfs["exp1_shape_motion"], "FL")[0]["Payload"]
    randomizers = [n for n in flow_nodes(root) if n["Type"] == "BlockRandomizer"]
    top = randomizers[0]
    assert top["SubSet"] == 1 and top["EvenPresentation"] is True
    groups = [n["Flow"][0]["EmbeddedData"][0] for n in top["Flow"]]
    assert [(g["Field"], g["Value"]) for g in groups] == [("SEX", "F"), ("SEX", "M")]
    # inside each group, the two GAIT blocks in random (counterbalanced) order
    block_orders = [n for n in randomizers[1:] if n["SubSet"] == 2]
    assert len(block_orders) == 2 and all(n["EvenPresentation"] for n in block_orders)


def test_exp1_blocks_randomise_questions_and_practice_comes_first(qsfs):
    qsf = qsfs["exp1_shape_motion"]
    by_id = blocks(qsf)
    root = elements(qsf, "FL")[0]["Payload"]
    units = [n for n in flow_nodes(root) if n["Type"] == "Group" and "GAIT=" in n["Description"]]
    assert len(units) == 4
    for unit in units:
        descriptions = [by_id[n["ID"]]["Description"] for n in unit["Flow"]]
        assert [d.rsplit(" ", 1)[-1] for d in descriptions] == ["intro", "practice", "test"]
        test = by_id[unit["Flow"][-1]["ID"]]
        assert test["Options"]["RandomizeQuestions"] == "RandomWithXPerPage"
        assert test["Options"]["Randomization"]["Advanced"]["QuestionsPerPage"] == 1
        assert len(test["BlockElements"]) == 32


def test_exp2_familiarisation_in_bmi_order_and_side_tags(qsfs, folders):
    qsf = qsfs["exp2_com_vs_average"]
    by_tag = {q["DataExportTag"]: q for q in questions(qsf)}
    by_qid = {q["QuestionID"]: q for q in questions(qsf)}
    fam_blocks = [b for b in blocks(qsf).values() if b["Description"].endswith("familiarization")]
    assert len(fam_blocks) == 2      # nested blocks: once per SEX block
    source = load_source(folders["exp2_com_vs_average"])
    bmi = {a.id: a.bmi for a in source.protocol.actors}
    for block in fam_blocks:
        shown = [by_qid[e["QuestionID"]]["DataExportTag"] for e in block["BlockElements"] if e["Type"] == "Question"]
        assert shown[0] == "fam_intro"
        bmis = [bmi[tag.removeprefix("fam-")] for tag in shown[1:]]
        assert len(bmis) == 4 and bmis == sorted(bmis)
    assert [c["Display"] for c in by_tag["walk-F-Hi1-COM_NoCOM_r2"]["Choices"].values()] == ["Left", "Right"]
    assert len([t for t in by_tag if t.endswith(("_r1", "_r2")) and not t.startswith("practice")]) == 64
    # no between factor: no group randomizer, but the 2 SEX blocks are randomised, evenly, and inside each
    # its 2 GAIT sub-blocks (nested blocks; tests/test_nested_blocks.py checks the tree)
    root = elements(qsf, "FL")[0]["Payload"]
    randomizers = [n for n in flow_nodes(root) if n["Type"] == "BlockRandomizer"]
    assert [(r["SubSet"], r["EvenPresentation"]) for r in randomizers] == [(2, True)] * 3


def test_video_urls_use_the_base_url_and_the_clip_files(qsfs, folders):
    source = load_source(folders["exp2_com_vs_average"])
    for q in questions(qsfs["exp2_com_vs_average"]):
        sid = q["DataExportTag"].rsplit("_r", 1)[0] if q["QuestionType"] != "DB" else q["DataExportTag"]
        if q["QuestionType"] == "DB" and not sid.startswith("fam-"):
            assert "<video" not in q["QuestionText"]
            continue
        url = f'src="{BASE}/{source.stimulus(sid).file}"'
        assert url in q["QuestionText"] and "playsinline" in q["QuestionText"] and " controls" in q["QuestionText"]
        assert "hideNextButton" in q["QuestionJS"] and '"ended"' in q["QuestionJS"]


def test_rotations_reproduce_the_latin_square_of_the_design(qsfs, folders):
    qsf = qsfs["thesis_pointlight"]
    source = load_source(folders["thesis_pointlight"])
    by_qid = {q["QuestionID"]: q for q in questions(qsf)}
    tests = [b for b in blocks(qsf).values() if b["Description"].endswith("test")]
    assert len(tests) == 6
    seen = Counter()
    for block in tests:
        tags = [by_qid[e["QuestionID"]]["DataExportTag"] for e in block["BlockElements"] if e["Type"] == "Question"]
        conditions = [source.stimulus(t).condition_id for t in tags]
        assert sorted(conditions) == sorted(set(conditions)) and len(conditions) == 10
        seen.update(tags)
    assert set(seen) == {s.stimulus_id for s in source.of_kind("test")} and set(seen.values()) == {1}
    # each design participant's list is exactly one rotation's block
    lists = {}
    for t in source.trials:
        lists.setdefault(t["participant"], set()).add(t["stimulus_id"])
    block_sets = [{by_qid[e["QuestionID"]]["DataExportTag"] for e in b["BlockElements"] if e["Type"] == "Question"}
                  for b in tests]
    assert all(s in block_sets for s in lists.values())


def test_ranking_question_is_rank_order_with_labels(qsfs):
    (q,) = answered(qsfs["thesis_validation"])
    assert (q["QuestionType"], q["Selector"]) == ("RO", "DND")
    assert [c["Display"] for c in q["Choices"].values()] == ["A", "B", "C", "D"]
    assert q["DataExportTag"] == "all-lean_mocap_keyframed_modifier_obese_mocap"


def test_same_design_gives_identical_text_and_valid_json(folders):
    source = load_source(folders["exp1_shape_motion"])
    first, second = qsf_text(source, BASE), qsf_text(load_source(folders["exp1_shape_motion"]), BASE)
    assert first == second
    assert json.loads(first) == build_qsf(source, BASE)


def test_an_export_of_this_survey_imports_by_its_tags(qsfs, folders, tmp_path):
    """A response file shaped like Qualtrics's CSV export of this QSF (3 header rows: export tags,
    question text, ImportId) maps every answer to its stimulus through the export tags alone."""
    import csv

    from analysis.io_design import load_design
    from analysis.responses import import_responses

    qsf = qsfs["exp1_shape_motion"]
    answers = [q for q in answered(qsf) if not q["DataExportTag"].startswith("practice-")]
    sex_of = {q["DataExportTag"]: q["DataExportTag"][0] for q in answers}
    columns = ["StartDate", "EndDate", "Status", "Progress", "Finished", "ResponseId"]
    rows = [columns + [q["DataExportTag"] for q in answers] + ["SEX", "shapemotion_protocol"],
            columns + [q["QuestionDescription"] for q in answers] + ["SEX", "shapemotion_protocol"],
            [json.dumps({"ImportId": c[0].lower() + c[1:]}) for c in columns]
            + [json.dumps({"ImportId": q["QuestionID"]}) for q in answers]
            + [json.dumps({"ImportId": "SEX"}), json.dumps({"ImportId": "shapemotion_protocol"})]]
    expected = {}
    for n, sex in enumerate(["F", "F", "M", "M"], start=1):
        values = []
        for i, q in enumerate(answers):   # only the group's own questions are shown (and answered)
            value = str(1 + (i + n) % 5) if sex_of[q["DataExportTag"]] == sex else ""
            values.append(value)
            if value:
                expected[(f"R_{n}", q["DataExportTag"].rsplit("_r", 1)[0], q["DataExportTag"][-1])] = int(value)
        rows.append(["2024-01-01 10:00:00", "2024-01-01 10:20:00", "0", "100", "1", f"R_{n}"] + values
                    + [sex, "exp1_shape_motion"])
    path = tmp_path / "qualtrics.csv"
    with open(path, "w", newline="") as handle:
        csv.writer(handle).writerows(rows)
    result = import_responses(path, load_design(folders["exp1_shape_motion"]))
    assert result.reconciles and result.format == "qualtrics"
    got = {(r.participant, r.stimulus_id, str(r.repetition)): int(r.rating) for r in result.data.itertuples()}
    assert got == expected and len(got) == 4 * 64


@pytest.mark.parametrize("per_block, questions_per_block, mode", [(2, 4, "RandomWithOnlyX"),
                                                                  (6, 8, "RandomWithOnlyX"),
                                                                  (4, 4, "RandomWithXPerPage")])
def test_practice_draws_per_block_from_the_pool(tmp_path, per_block, questions_per_block, mode):
    text = (Path(__file__).resolve().parents[1] / "protocols" / "exp1_shape_motion.yaml").read_text()
    text = text.replace("per_block: 4 ", f"per_block: {per_block} ")
    from stimuli.protocol import parse_protocol

    write_design(build_design(parse_protocol(text)), tmp_path / "d")
    qsf = build_qsf(load_source(tmp_path / "d"), BASE)
    by_qid = {q["QuestionID"]: q for q in questions(qsf)}
    practice = [b for b in blocks(qsf).values() if b["Description"].endswith(" practice")]
    assert len(practice) == 4
    for block in practice:
        tags = [by_qid[e["QuestionID"]]["DataExportTag"] for e in block["BlockElements"] if e["Type"] == "Question"]
        assert len(tags) == questions_per_block and len(set(tags)) == len(tags)
        assert all(t.startswith("practice-") for t in tags)
        assert all(t.endswith(("_r1", "_r2")) for t in tags) == (per_block > 4)
        assert block["Options"]["RandomizeQuestions"] == mode
        if mode == "RandomWithOnlyX":
            assert block["Options"]["Randomization"]["Advanced"]["TotalRandSubset"] == per_block
