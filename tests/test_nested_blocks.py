"""``blocks.nested``: main blocks (the first ``blocks.by`` factor) holding sub-blocks (the others).

Vyas et al. (2023), Exp. 2: "two blocks based on SEX (Male and Female), with sub-blocks for GAIT (Walk
and Jog) ... Before each SEX block, participants viewed subjects' body shapes in increasing BMI order
for familiarization ... 16 questions per block". The flat ``blocks.by: [SEX, GAIT]`` interleaved the
sexes for half the participants and showed the familiarisation before each of the 4 blocks.
"""

from __future__ import annotations

import csv
import hashlib
import json
import re
from collections import Counter, defaultdict
from pathlib import Path

import pandas as pd
import pytest

from stimuli.design import build_design, write_design
from stimuli.errors import StimuliError
from stimuli.protocol import load_protocol, parse_protocol
from stimuli.survey import export_survey
from stimuli.survey.jspsych import config
from stimuli.survey.plan import build_plan
from stimuli.survey.psychopy import psychopy_files
from stimuli.survey.qsf import build_qsf, qsf_text
from stimuli.survey.qualtrics_txt import manual_steps, txt_text
from stimuli.survey.source import load_source

ROOT = Path(__file__).resolve().parents[1]
EXP2 = (ROOT / "protocols" / "exp2_com_vs_average.yaml").read_text()
BASE = "https://media.example.org/exp2"


def exp2_text(nested: str | None = "true", **replace: str) -> str:
    """Exp. 2's protocol with ``blocks.nested`` set (None: the line left out) and other lines replaced."""
    text = re.sub(r"\n  nested: [^\n]*", "", EXP2)
    if nested is not None:
        assert text.count("\nblocks:\n") == 1
        text = text.replace("\nblocks:\n", f"\nblocks:\n  nested: {nested}\n")
    for old, new in replace.items():
        assert old in text, old
        text = text.replace(old, new)
    return text


def folder_of(tmp_path: Path, text: str, name: str = "d", participants: int | None = None) -> Path:
    folder = tmp_path / name
    write_design(build_design(parse_protocol(text), participants=participants), folder)
    return folder


def sex_of(label: str) -> str:
    return dict(part.split("=") for part in label.split("|"))["SEX"]


def gait_of(label: str) -> str:
    return dict(part.split("=") for part in label.split("|"))["GAIT"]


def trials_of(folder: Path) -> pd.DataFrame:
    return pd.read_csv(folder / "trials.csv").sort_values(["participant", "trial"])


@pytest.fixture(scope="module")
def exp2(tmp_path_factory):
    """The bundled Exp. 2 design (16 participants), written by the CLI as a user would."""
    from stimuli.cli import main

    out = tmp_path_factory.mktemp("exp2")
    assert main(["design", str(ROOT / "protocols" / "exp2_com_vs_average.yaml"), "--out", str(out)]) == 0
    return out


# -- the protocol --------------------------------------------------------------------------------------

def test_bundled_exp2_nests_gait_inside_sex():
    p = load_protocol(ROOT / "protocols" / "exp2_com_vs_average.yaml")
    assert p.blocks.by == ["SEX", "GAIT"] and p.blocks.nested is True and p.blocks.order == "counterbalanced"
    assert p.to_json_dict()["blocks"]["nested"] is True


def test_default_is_flat_and_left_out_of_design_json():
    p = load_protocol(ROOT / "protocols" / "exp1_shape_motion.yaml")
    assert p.blocks.nested is False
    assert "nested" not in p.to_json_dict()["blocks"]       # designs written before the option stay identical


def test_explicit_false_gives_the_bytes_of_no_setting(tmp_path):
    implicit = folder_of(tmp_path, exp2_text(None), "implicit")
    explicit = folder_of(tmp_path, exp2_text("false"), "explicit")
    for name in ("trials.csv", "conditions.csv", "design.json"):
        assert (implicit / name).read_bytes() == (explicit / name).read_bytes()
    design = json.loads((implicit / "design.json").read_text())
    assert "block_nesting" not in design and "nested" not in design["protocol"]["blocks"]


@pytest.mark.parametrize("by", ["[GAIT]", "[]"])
def test_nested_needs_two_block_factors(by):
    with pytest.raises(StimuliError, match=r"blocks\.nested \(line \d+\): .*at least two factors in blocks\.by.*"
                                           r"main blocks.*sub-blocks"):
        parse_protocol(exp2_text("true", **{"by: [SEX, GAIT]": f"by: {by}"}))


@pytest.mark.parametrize("value", ["sometimes", '"true"', "1"])
def test_nested_is_true_or_false(value):
    with pytest.raises(StimuliError, match=r"blocks\.nested \(line \d+\):.*true or false"):
        parse_protocol(exp2_text(value))


def test_nested_misspelt_lists_the_known_fields():
    text = exp2_text(None).replace("\nblocks:\n", "\nblocks:\n  nest: true\n")
    with pytest.raises(StimuliError, match=r"blocks\.nest \(line \d+\): unknown field .*nested"):
        parse_protocol(text)


# -- the design ------------------------------------------------------------------------------------------

def test_exp2_sub_blocks_of_one_sex_are_consecutive(exp2):
    design = json.loads((exp2 / "design.json").read_text())
    orders = design["block_orders"]
    assert len(orders) == 16
    for participant, order in orders.items():
        assert sorted(order) == sorted(design["blocks"]), participant
        sexes = [sex_of(label) for label in order]
        assert sexes[0] == sexes[1] != sexes[2] == sexes[3], (participant, order)
        # the same GAIT order inside both SEX blocks (one Williams row for the sub-blocks)
        assert [gait_of(label) for label in order[:2]] == [gait_of(label) for label in order[2:]], order
    trials = trials_of(exp2)
    for participant, part in trials.groupby("participant"):
        labels = part.drop_duplicates("block")[["block", "block_label"]].values.tolist()
        assert labels == [[i + 1, label] for i, label in enumerate(orders[str(participant)])]
        assert part.block.is_monotonic_increasing


def test_exp2_orders_are_counterbalanced_at_both_levels(exp2):
    orders = json.loads((exp2 / "design.json").read_text())["block_orders"].values()
    assert Counter("".join(sex_of(label) for label in o) for o in orders) == {"FFMM": 8, "MMFF": 8}
    assert Counter("".join(gait_of(label)[0] for label in o) for o in orders) == {"wjwj": 8, "jwjw": 8}
    assert Counter(sex_of(o[0]) for o in orders) == {"F": 8, "M": 8}
    assert Counter(gait_of(o[0]) for o in orders) == {"walk": 8, "jog": 8}
    assert Counter((sex_of(o[0]), gait_of(o[0])) for o in orders) == {
        ("F", "walk"): 4, ("F", "jog"): 4, ("M", "walk"): 4, ("M", "jog"): 4}
    assert len({tuple(o) for o in orders}) == 4


def test_exp2_familiarisation_once_before_each_sex_block(exp2):
    trials = trials_of(exp2)
    bmi = {a.id: a.bmi for a in load_protocol(ROOT / "protocols" / "exp2_com_vs_average.yaml").actors}
    for participant, part in trials.groupby("participant"):
        fam = part[part.kind == "familiarization"]
        assert len(fam) == 8, participant
        assert sorted(fam.block.unique()) == [1, 3]
        for block_number, block in part.groupby("block"):
            kinds = block.kind.tolist()
            expected = ["familiarization"] * 4 if block_number in (1, 3) else []
            assert kinds == expected + ["practice"] * 4 + ["test"] * 16, (participant, block_number)
            if block_number in (1, 3):
                actors = [sid.removeprefix("fam-") for sid in block[block.kind == "familiarization"].stimulus_id]
                sex = sex_of(block.block_label.iloc[0])
                assert all(a.startswith(sex + "_") for a in actors)
                assert [bmi[a] for a in actors] == sorted(bmi[a] for a in actors)
                assert len(set(actors)) == 4
        assert set(fam.stimulus_id) == {f"fam-{s}_{b}" for s in "FM" for b in ("Hi1", "Hi2", "Lo1", "Lo2")}


def test_exp2_test_trials_and_left_right_balance_unchanged(exp2):
    conditions = pd.read_csv(exp2 / "conditions.csv")
    assert Counter(conditions.kind) == {"test": 32, "practice": 16, "familiarization": 8}
    trials = trials_of(exp2)
    tests = conditions[conditions.kind == "test"][["stimulus_id", "GAIT", "SEX", "BODY"]]
    for participant, part in trials[trials.kind == "test"].groupby("participant"):
        assert len(part) == 64 and set(part.stimulus_id.value_counts()) == {2}
        for _, block in part.groupby("block"):
            assert len(block) == 16 and block.stimulus_id.nunique() == 8
            ids = block.stimulus_id.tolist()
            assert all(a != b for a, b in zip(ids, ids[1:]))
        merged = part.merge(tests, on="stimulus_id")
        per_cell = merged.groupby(["GAIT", "SEX", "BODY"]).left.value_counts().unstack()
        assert (per_cell["NoCOM"] == per_cell["COM"]).all()
        assert (merged.apply(lambda r: f"SEX={r.SEX}|GAIT={r.GAIT}", axis=1).tolist()
                == part.block_label.tolist())
    assert Counter(trials.groupby("participant").size()) == {64 + 16 + 8: 16}


def test_design_json_describes_the_nesting(exp2):
    design = json.loads((exp2 / "design.json").read_text())
    assert design["blocks"] == ["SEX=F|GAIT=walk", "SEX=F|GAIT=jog", "SEX=M|GAIT=walk", "SEX=M|GAIT=jog"]
    assert design["block_nesting"] == {
        "main": ["SEX"], "sub": ["GAIT"],
        "main_blocks": {"SEX=F": ["SEX=F|GAIT=walk", "SEX=F|GAIT=jog"],
                        "SEX=M": ["SEX=M|GAIT=walk", "SEX=M|GAIT=jog"]}}
    assert design["protocol"]["blocks"]["nested"] is True


def test_group_sizes_the_orders_do_not_divide_keep_both_levels_even(tmp_path, run_cli):
    """10 participants over the 2 × 2 order combinations: 3, 3, 2, 2 — dealt so that SEX-first and
    GAIT-first are still 5 / 5 — and the command says the combinations cannot be balanced."""
    path = tmp_path / "p.yaml"
    path.write_text(exp2_text())
    code, stdout, stderr = run_cli("design", path, "--participants", "10", "--out", tmp_path / "out")
    assert code == 0, stderr
    orders = json.loads((tmp_path / "out" / "design.json").read_text())["block_orders"].values()
    assert Counter(sex_of(o[0]) for o in orders) == {"F": 5, "M": 5}
    assert Counter(gait_of(o[0]) for o in orders) == {"walk": 5, "jog": 5}
    assert sorted(Counter(tuple(o) for o in orders).values()) == [2, 2, 3, 3]
    note = " ".join(stdout.split())
    assert "note: blocks.order: 10 participants cannot see the 4 counterbalanced block orders equally often" in note
    assert "A multiple of 4 participants" in note


def test_between_groups_each_get_every_combination(tmp_path):
    """Exp. 1 with GAIT as the main blocks and MOTION as sub-blocks (SEX between): each SEX group of 8 sees
    each of the 2 × 4 order combinations (Williams rows of 2 and of 4) once, and the familiarisation (the
    group's 4 bodies) comes once per GAIT block."""
    text = (ROOT / "protocols" / "exp1_shape_motion.yaml").read_text()
    text = text.replace("  by: [GAIT]", "  by: [GAIT, MOTION]\n  nested: true")
    text = text.replace("levels: {BODY: [P1, P2], MOTION: [P1, P2]}", "levels: {BODY: [P1, P2]}")
    text += "\nfamiliarization:\n  enabled: true\n"
    p = parse_protocol(text)
    assert p.blocks.nested and p.familiarization.enabled
    d = build_design(p, participants=16)
    by_group = defaultdict(Counter)
    for participant, order in d.block_orders.items():
        group = next(t.groups["SEX"] for t in d.trials if t.participant == participant)
        mains = [label.split("|")[0] for label in order]
        assert len(order) == 8 and all(len(set(mains[i:i + 4])) == 1 for i in (0, 4)) and mains[0] != mains[4]
        subs = [label.split("|")[1] for label in order]
        assert subs[:4] == subs[4:]
        by_group[group][(mains[0], subs[0], subs[1])] += 1
        fam = [t for t in d.trials if t.participant == participant and t.kind == "familiarization"]
        assert sorted({t.block for t in fam}) == [1, 5] and len(fam) == 8
    assert {g: sorted(c.values()) for g, c in by_group.items()} == {"F": [1] * 8, "M": [1] * 8}


def test_random_order_shuffles_both_levels_and_keeps_sub_blocks_together(tmp_path):
    d = build_design(parse_protocol(exp2_text(**{"order: counterbalanced": "order: random"})), participants=40)
    orders = list(d.block_orders.values())
    for order in orders:
        assert sex_of(order[0]) == sex_of(order[1]) != sex_of(order[2]) == sex_of(order[3])
    assert {sex_of(o[0]) for o in orders} == {"F", "M"}
    assert {gait_of(o[0]) for o in orders} == {"walk", "jog"}
    # a sub-block order is drawn for each main block, as Qualtrics's nested randomizers do
    assert any(gait_of(o[0]) != gait_of(o[2]) for o in orders)
    assert any(gait_of(o[0]) == gait_of(o[2]) for o in orders)
    fam = Counter(t.participant for t in d.trials if t.kind == "familiarization")
    assert set(fam.values()) == {8}


def test_fixed_order_is_the_declared_order_with_one_familiarisation_per_main_block():
    d = build_design(parse_protocol(exp2_text(**{"order: counterbalanced": "order: fixed"})))
    declared = ["SEX=F|GAIT=walk", "SEX=F|GAIT=jog", "SEX=M|GAIT=walk", "SEX=M|GAIT=jog"]
    assert all(order == declared for order in d.block_orders.values())
    fam_blocks = Counter(t.block for t in d.trials if t.kind == "familiarization" and t.participant == 1)
    assert fam_blocks == {1: 4, 3: 4}


def test_same_seed_same_bytes(tmp_path):
    a, b = folder_of(tmp_path, exp2_text(), "a"), folder_of(tmp_path, exp2_text(), "b")
    for name in ("trials.csv", "conditions.csv", "design.json"):
        assert (a / name).read_bytes() == (b / name).read_bytes()


# -- the survey exports ----------------------------------------------------------------------------------

def flow_root(qsf: dict) -> dict:
    return next(e for e in qsf["SurveyElements"] if e["Element"] == "FL")["Payload"]


def block_table(qsf: dict) -> dict[str, dict]:
    return {b["ID"]: b for b in next(e for e in qsf["SurveyElements"] if e["Element"] == "BL")["Payload"]}


def tags_of(qsf: dict, block: dict) -> list[str]:
    by_qid = {e["Payload"]["QuestionID"]: e["Payload"]["DataExportTag"] for e in qsf["SurveyElements"]
              if e["Element"] == "SQ"}
    return [by_qid[e["QuestionID"]] for e in block["BlockElements"] if e["Type"] == "Question"]


def test_qsf_flow_nests_a_gait_randomizer_inside_each_sex_group(exp2):
    qsf = build_qsf(load_source(exp2), BASE)
    blocks = block_table(qsf)
    flow = flow_root(qsf)["Flow"]
    assert [n["Type"] for n in flow] == ["EmbeddedData", "Block", "Standard", "BlockRandomizer", "EndSurvey"]
    outer = flow[3]
    assert (outer["SubSet"], outer["EvenPresentation"]) == (2, True)
    assert [g["Type"] for g in outer["Flow"]] == ["Group", "Group"]
    assert [g["Description"] for g in outer["Flow"]] == ["all participants | SEX=F", "all participants | SEX=M"]
    bmi = {a.id: a.bmi for a in load_protocol(ROOT / "protocols" / "exp2_com_vs_average.yaml").actors}
    for group, sex in zip(outer["Flow"], "FM"):
        fam, inner = group["Flow"]
        assert fam["Type"] == "Standard" and blocks[fam["ID"]]["Description"].endswith(f"SEX={sex} familiarization")
        clips = tags_of(qsf, blocks[fam["ID"]])
        assert clips[0] == "fam_intro" and [c[4] for c in clips[1:]] == [sex] * 4
        bmis = [bmi[c.removeprefix("fam-")] for c in clips[1:]]
        assert bmis == sorted(bmis)
        assert inner["Type"] == "BlockRandomizer" and (inner["SubSet"], inner["EvenPresentation"]) == (2, True)
        assert [g["Description"] for g in inner["Flow"]] == [f"all participants | SEX={sex}|GAIT=walk",
                                                             f"all participants | SEX={sex}|GAIT=jog"]
        for sub in inner["Flow"]:
            parts = [blocks[n["ID"]]["Description"].rsplit(" ", 1)[-1] for n in sub["Flow"]]
            assert parts == ["intro", "practice", "test"]          # no familiarisation inside a sub-block
            test = blocks[sub["Flow"][-1]["ID"]]
            tags = tags_of(qsf, test)
            gait = gait_of(sub["Description"].split(" | ")[1])
            assert len(tags) == 16 and all(t.startswith(f"{gait}-{sex}-") for t in tags)
    fam_blocks = [b for b in blocks.values() if b["Description"].endswith("familiarization")]
    assert len(fam_blocks) == 2


def test_qsf_fixed_nested_order_has_no_randomizer(tmp_path):
    folder = folder_of(tmp_path, exp2_text(**{"order: counterbalanced": "order: fixed"}))
    qsf = build_qsf(load_source(folder), BASE)
    blocks = block_table(qsf)
    flow = flow_root(qsf)["Flow"]
    assert "BlockRandomizer" not in json.dumps(flow)
    mains = flow[3:-1]
    assert [g["Description"] for g in mains] == ["all participants | SEX=F", "all participants | SEX=M"]
    for group in mains:
        assert blocks[group["Flow"][0]["ID"]]["Description"].endswith("familiarization")
        assert [g["Type"] for g in group["Flow"][1:]] == ["Group", "Group"]


def test_qsf_flow_ids_and_blocks_stay_consistent(exp2):
    qsf = build_qsf(load_source(exp2), BASE)

    def nodes(node):
        yield node
        for child in node.get("Flow", []):
            yield from nodes(child)

    root = flow_root(qsf)
    ids = [n["FlowID"] for n in nodes(root)]
    assert len(ids) == len(set(ids)) and root["Properties"]["Count"] == max(int(i[3:]) for i in ids)
    referenced = [n["ID"] for n in nodes(root) if "ID" in n]
    assert sorted(referenced) == sorted(b["ID"] for b in block_table(qsf).values() if b["Type"] != "Trash")


def test_txt_writes_one_familiarisation_per_main_block_and_states_the_nesting(exp2):
    source = load_source(exp2)
    text = txt_text(source, BASE)
    names = re.findall(r"\[\[Block:([^\]]+)\]\]", text)
    assert names == ["Consent", "Instructions",
                     "all participants | SEX=F familiarization",
                     "all participants | SEX=F|GAIT=walk practice", "all participants | SEX=F|GAIT=walk test",
                     "all participants | SEX=F|GAIT=jog practice", "all participants | SEX=F|GAIT=jog test",
                     "all participants | SEX=M familiarization",
                     "all participants | SEX=M|GAIT=walk practice", "all participants | SEX=M|GAIT=walk test",
                     "all participants | SEX=M|GAIT=jog practice", "all participants | SEX=M|GAIT=jog test"]
    steps = "\n".join(manual_steps(source))
    assert "Randomizer presenting all 2 main-block Groups" in steps and "SEX=F, SEX=M" in steps
    assert "Randomizer presenting its 2 sub-block Groups" in steps and "after its familiarization block" in steps
    assert "Randomizer presenting all 4 Groups" not in steps


def test_psychopy_has_an_outer_loop_over_main_blocks(exp2, tmp_path):
    files = psychopy_files(load_source(exp2))
    mains = list(csv.DictReader(files["main_blocks.csv"].splitlines()))
    assert [m["main_block"] for m in mains] == ["SEX=F", "SEX=M"]
    for main in mains:
        assert main["familiarization_file"] == f"conditions/{main['main_block'].replace('=', '-')}_familiarization.csv"
        fam = list(csv.DictReader(files[main["familiarization_file"]].splitlines()))
        assert len(fam) == 4 and all(r["SEX"] == main["main_block"][-1] for r in fam)
        subs = list(csv.DictReader(files[main["blocks_file"]].splitlines()))
        assert [s["block_label"] for s in subs] == [f"{main['main_block']}|GAIT=walk", f"{main['main_block']}|GAIT=jog"]
        assert all(s["familiarization_file"] == "" and s["main_block"] == main["main_block"] for s in subs)
        assert all(s["practice_per_block"] == "4" and s["nReps"] == "2" for s in subs)
    flat = list(csv.DictReader(files["blocks.csv"].splitlines()))
    assert [b["main_block"] for b in flat] == ["SEX=F", "SEX=F", "SEX=M", "SEX=M"]
    assert not any(b["familiarization_file"] for b in flat)


def test_jspsych_replays_the_nested_design(exp2):
    lists = config(load_source(exp2))["lists"]
    orders = json.loads((exp2 / "design.json").read_text())["block_orders"]
    assert len(lists) == 16
    for entry in lists:
        kinds = Counter(t["kind"] for t in entry["trials"])
        assert kinds == {"test": 64, "practice": 16, "familiarization": 8}
        labels = list(dict.fromkeys(t["block_label"] for t in entry["trials"]))
        assert labels == orders[str(entry["list"])]
        assert {t["block"] for t in entry["trials"] if t["kind"] == "familiarization"} == {1, 3}


def test_plan_groups_sub_blocks_under_their_main_block(exp2):
    (group,) = build_plan(load_source(exp2))
    (rotation,) = group.rotations
    assert [m.label for m in rotation.main_blocks] == ["SEX=F", "SEX=M"]
    assert [[b.label for b in m.blocks] for m in rotation.main_blocks] == [
        ["SEX=F|GAIT=walk", "SEX=F|GAIT=jog"], ["SEX=M|GAIT=walk", "SEX=M|GAIT=jog"]]
    assert [len(m.familiarization) for m in rotation.main_blocks] == [4, 4]
    assert all(not b.familiarization for b in rotation.blocks) and len(rotation.blocks) == 4


def test_every_export_is_deterministic(exp2, tmp_path):
    def digest(path: Path) -> str:
        h = hashlib.sha256()
        for f in sorted(p for p in ([path] if path.is_file() else path.rglob("*")) if p.is_file()):
            h.update(str(f.relative_to(path.parent)).encode() + f.read_bytes())
        return h.hexdigest()

    for fmt, name in (("qsf", "s.qsf"), ("qualtrics-txt", "s.txt"), ("jspsych", "js"), ("psychopy", "pp")):
        export_survey(exp2, fmt, tmp_path / "1" / name, BASE)
        export_survey(exp2, fmt, tmp_path / "2" / name, BASE)
        assert digest(tmp_path / "1" / name) == digest(tmp_path / "2" / name), fmt
    assert qsf_text(load_source(exp2), BASE) == (tmp_path / "1" / "s.qsf").read_text()


def test_psychopy_export_over_a_nested_one_removes_its_files_but_not_the_labs(tmp_path):
    """Exporting a flat design into the folder of a nested one left main_blocks.csv and the per-SEX files,
    which a Builder experiment set up for the nested layout went on reading."""
    out = tmp_path / "psychopy"
    export_survey(folder_of(tmp_path, exp2_text("true"), "nested"), "psychopy", out)
    assert (out / "main_blocks.csv").is_file() and (out / "conditions" / "SEX-F_blocks.csv").is_file()
    (out / "study.psyexp").write_text("<PsychoPy2experiment/>")          # the lab's own experiment
    (out / "conditions" / "my_lab_extra.csv").write_text("a,b\n1,2\n")      # and its own conditions
    export_survey(folder_of(tmp_path, exp2_text(None), "flat"), "psychopy", out)
    assert not (out / "main_blocks.csv").exists()
    assert not list((out / "conditions").glob("SEX-?_blocks.csv"))
    assert (out / "study.psyexp").read_text() == "<PsychoPy2experiment/>"
    assert (out / "conditions" / "my_lab_extra.csv").read_text() == "a,b\n1,2\n"
    listed = {row["test_file"] for row in csv.DictReader((out / "blocks.csv").read_text().splitlines())}
    assert listed and all((out / name).is_file() for name in listed)
