"""``blocks.trials``: the order of the test trials inside a block (``random``, the default, or
``fixed`` = the declared order of the factor levels, once per repetition), in the design and in
every survey export."""

from __future__ import annotations

import csv
import io
import itertools
import json
import re
from collections import Counter, defaultdict
from pathlib import Path

import pytest

from stimuli.design import build_design, design_json, write_design
from stimuli.errors import StimuliError
from stimuli.protocol import load_protocol, parse_protocol
from stimuli.survey.jspsych import config
from stimuli.survey.psychopy import psychopy_files
from stimuli.survey.qsf import build_qsf
from stimuli.survey.qualtrics_txt import manual_steps, txt_text
from stimuli.survey.source import load_source

ROOT = Path(__file__).resolve().parents[1]
BASE = "https://media.example.org/study"
# Shewhorak (2017), Table 4-2 "Angle and order of point light walker matrices": survey order → view
# angle (FL = full length is not reproduced: every walker walks on the spot).
TABLE_4_2 = [("hip_torso_twist", 45), ("upper_body", 45), ("lower_body", 45), ("arm_abduction_swing", 45),
             ("whole_body", 45), ("arm_swing", 90), ("spinal_erectness", 90), ("speed_cadence", 45),
             ("arm_abduction_bob", 0), ("arm_abduction", 0)]


def text_of(name: str, trials: str | None = "fixed", **replace: str) -> str:
    """A bundled protocol's text with ``blocks.trials`` set (None: as bundled) and other lines replaced."""
    text = (ROOT / "protocols" / f"{name}.yaml").read_text()
    text = re.sub(r"\n  trials: \w+[^\n]*", "", text)
    if trials is not None:
        assert text.count("\nblocks:\n") == 1
        text = text.replace("\nblocks:\n", f"\nblocks:\n  trials: {trials}\n")
    for old, new in replace.items():
        assert old in text, old
        text = text.replace(old, new)
    return text


def folder_of(tmp_path: Path, text: str, name: str = "d") -> Path:
    folder = tmp_path / name
    write_design(build_design(parse_protocol(text)), folder)
    return folder


def shown_tests(folder: Path) -> dict[int, list[tuple[str, str, int]]]:
    """participant → its test trials as (block label, stimulus id, repetition), in presentation order."""
    out: dict[int, list] = defaultdict(list)
    for row in sorted(csv.DictReader(open(folder / "trials.csv")), key=lambda r: (int(r["participant"]),
                                                                                  int(r["trial"]))):
        if row["kind"] == "test":
            out[int(row["participant"])].append((row["block_label"], row["stimulus_id"], int(row["repetition"])))
    return dict(out)


def by_block(sequence):
    blocks: dict[str, list] = defaultdict(list)
    for label, sid, rep in sequence:
        blocks[label].append((sid, rep))
    return blocks


# -- the protocol -----------------------------------------------------------------------------

def test_default_is_random_and_left_out_of_design_json():
    p = load_protocol(ROOT / "protocols" / "exp1_shape_motion.yaml")
    assert p.blocks.trials == "random"
    assert "trials" not in p.to_json_dict()["blocks"]      # designs written before the option stay identical
    fixed = parse_protocol(text_of("exp1_shape_motion"))
    assert fixed.to_json_dict()["blocks"]["trials"] == "fixed"


def test_explicit_random_gives_the_same_bytes_as_none(tmp_path):
    implicit = folder_of(tmp_path, text_of("exp2_com_vs_average", None), "implicit")
    explicit = folder_of(tmp_path, text_of("exp2_com_vs_average", "random"), "explicit")
    for name in ("trials.csv", "conditions.csv", "design.json"):
        assert (implicit / name).read_bytes() == (explicit / name).read_bytes()


def test_fixed_survives_the_design_json_round_trip(tmp_path):
    folder = folder_of(tmp_path, text_of("exp1_shape_motion"))
    assert json.loads((folder / "design.json").read_text())["protocol"]["blocks"]["trials"] == "fixed"
    assert load_source(folder).protocol.blocks.trials == "fixed"


def test_unknown_value_names_the_field():
    with pytest.raises(StimuliError, match=r"blocks\.trials \(line \d+\):.*'random' or 'fixed'"):
        parse_protocol(text_of("exp1_shape_motion", "sequential"))


def test_one_clip_per_block_cannot_repeat_in_a_fixed_order():
    """Point-light rows blocked by PARAMETER with rotated arrangements: one clip per block and
    participant, so a second repetition would play it back to back; refused, naming the field."""
    one_clip = text_of("thesis_pointlight", **{"  by: []": "  by: [PARAMETER]", "repetitions: 1": "repetitions: 2"})
    with pytest.raises(StimuliError, match=r"blocks\.trials \(line \d+\): fixed .*only 1 test clip.*2 times back "
                                           r"to back.*repetitions: 1.*blocks\.by"):
        parse_protocol(one_clip)
    parse_protocol(one_clip.replace("repetitions: 2", "repetitions: 1"))        # once each: fine
    parse_protocol(one_clip.replace("counterbalance: between", "counterbalance: within"))   # 6 arrangements
    parse_protocol(one_clip.replace("trials: fixed", "trials: random"))         # random keeps its old rule


# -- the point-light protocol: Table 4-2's survey order ---------------------------------------------

def test_pointlight_levels_are_table_4_2_in_order():
    p = load_protocol(ROOT / "protocols" / "thesis_pointlight.yaml")
    assert p.blocks.trials == "fixed"
    factor = p.factor("PARAMETER")
    assert [(level, factor.level_settings[level]["view_deg"]) for level in factor.levels] == TABLE_4_2


def test_pointlight_every_participant_sees_table_4_2_in_order_with_rotated_rows():
    d = build_design(load_protocol(ROOT / "protocols" / "thesis_pointlight.yaml"))
    positions = defaultdict(Counter)
    for participant in range(1, d.participants + 1):
        tests = [t for t in d.trials if t.participant == participant and t.kind == "test"]
        shown = [d.stimulus(t.stimulus_id) for t in tests]
        assert [s.levels["PARAMETER"] for s in shown] == [level for level, _ in TABLE_4_2]
        assert [t.trial for t in tests] == list(range(1, 11)) and {t.repetition for t in tests} == {1}
        for s in shown:
            for position, strength in enumerate(s.arrangement):
                positions[(s.levels["PARAMETER"], position)][strength] += 1
    # the Latin square still rotates over participants: each strength 10 times at each position
    assert all(counts == Counter({lv: 10 for lv in ["0.5", "12", "23.5", "35", "46.5", "58"]})
               for counts in positions.values())


# -- the design with repetitions, several blocks and between groups -------------------------------

def test_fixed_order_repeats_the_declared_sequence_once_per_repetition(tmp_path):
    """Exp. 2 (4 blocks in counterbalanced order, both arrangements of every body, 2 repetitions)."""
    folder = folder_of(tmp_path, text_of("exp2_com_vs_average"))
    d = load_source(folder)
    bodies = ["Hi1", "Hi2", "Lo1", "Lo2"]
    expected = [(body, arrangement) for body in bodies for arrangement in itertools.permutations(["NoCOM", "COM"])]
    orders = set()
    for participant, sequence in shown_tests(folder).items():
        blocks = by_block(sequence)
        orders.add(tuple(blocks))
        for label, shown in blocks.items():
            got = [(d.stimulus(sid).levels["BODY"], d.stimulus(sid).arrangement) for sid, _ in shown]
            assert got == expected * 2
            assert [rep for _, rep in shown] == [1] * 8 + [2] * 8
            assert all(a != b for a, b in zip(shown, shown[1:]))
            cell = dict(part.split("=") for part in label.split("|"))
            assert all(d.stimulus(sid).levels[k] == v for sid, _ in shown for k, v in cell.items())
    assert len(orders) > 1                      # the block order is still counterbalanced


def test_practice_and_familiarisation_keep_their_rules(tmp_path):
    fixed = folder_of(tmp_path, text_of("exp2_com_vs_average"), "fixed")
    default = folder_of(tmp_path, text_of("exp2_com_vs_average", None), "default")

    def parts(folder, kind):
        rows = list(csv.DictReader(open(folder / "trials.csv")))
        out = defaultdict(list)
        for r in rows:
            if r["kind"] == kind:
                out[(r["participant"], r["block_label"])].append(r["stimulus_id"])
        return out

    assert parts(fixed, "familiarization") == parts(default, "familiarization")
    practice = parts(fixed, "practice")
    assert len({tuple(v) for v in practice.values()}) > 4            # still shuffled per participant
    assert all(a != b for v in practice.values() for a, b in zip(v, v[1:]))


def test_random_stays_random(tmp_path):
    sequences = shown_tests(folder_of(tmp_path, text_of("exp1_shape_motion", None)))
    firsts = {tuple(sid for _, sid, _ in seq[:32]) for seq in sequences.values()}
    assert len(firsts) > 2


# -- the exports ------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def pointlight(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("pointlight") / "d"
    write_design(build_design(load_protocol(ROOT / "protocols" / "thesis_pointlight.yaml")), folder)
    return folder


def design_lists(folder: Path) -> set[tuple[str, ...]]:
    return {tuple(sid for _, sid, _ in seq) for seq in shown_tests(folder).values()}


def test_qsf_test_blocks_keep_the_fixed_order_a_page_each(pointlight):
    qsf = build_qsf(load_source(pointlight), BASE)
    tags = {e["Payload"]["QuestionID"]: e["Payload"]["DataExportTag"]
            for e in qsf["SurveyElements"] if e["Element"] == "SQ"}
    blocks = next(e for e in qsf["SurveyElements"] if e["Element"] == "BL")["Payload"]
    tests = [b for b in blocks if b["Description"].endswith(" test")]
    assert len(tests) == 6                                             # one per Latin-square rotation
    lists = set()
    for block in tests:
        assert block["Options"]["RandomizeQuestions"] == "false" and "Randomization" not in block["Options"]
        elements = block["BlockElements"]
        assert [e["Type"] for e in elements] == ["Question", "Page Break"] * 9 + ["Question"]
        lists.add(tuple(tags[e["QuestionID"]] for e in elements if e["Type"] == "Question"))
    assert lists == design_lists(pointlight)


def test_qsf_of_a_random_protocol_still_randomises(tmp_path):
    qsf = build_qsf(load_source(folder_of(tmp_path, text_of("thesis_pointlight", "random"))), BASE)
    blocks = next(e for e in qsf["SurveyElements"] if e["Element"] == "BL")["Payload"]
    assert {b["Options"]["RandomizeQuestions"] for b in blocks if b["Description"].endswith(" test")} == \
        {"RandomWithXPerPage"}


def test_qsf_with_repetitions_lists_each_repetition_in_order(tmp_path):
    folder = folder_of(tmp_path, text_of("exp1_shape_motion"))
    qsf = build_qsf(load_source(folder), BASE)
    tags = {e["Payload"]["QuestionID"]: e["Payload"]["DataExportTag"]
            for e in qsf["SurveyElements"] if e["Element"] == "SQ"}
    blocks = next(e for e in qsf["SurveyElements"] if e["Element"] == "BL")["Payload"]
    qsf_blocks = {}
    for b in blocks:
        if b["Description"].endswith(" test"):
            assert b["Options"]["RandomizeQuestions"] == "false"
            qsf_blocks[b["Description"]] = [tags[e["QuestionID"]] for e in b["BlockElements"]
                                            if e["Type"] == "Question"]
    for participant, sequence in shown_tests(folder).items():
        for label, shown in by_block(sequence).items():
            want = [f"{sid}_r{rep}" for sid, rep in shown]
            assert want in qsf_blocks.values()
            assert [t.rsplit("_r", 1)[1] for t in want] == ["1"] * 16 + ["2"] * 16


def test_txt_writes_the_fixed_order_and_asks_to_leave_randomisation_off(pointlight):
    source = load_source(pointlight)
    text = txt_text(source, BASE)
    lists = set()
    for block in text.split("[[Block:")[1:]:
        name = block.split("]]", 1)[0]
        if name.endswith(" test"):
            lists.add(tuple(re.findall(r"\[\[ID:([^\]]+)\]\]", block)))
            assert block.count("[[PageBreak]]") == 9
    assert lists == {tuple(t.replace("+", "_") for t in lst) for lst in design_lists(pointlight)}
    steps = " ".join(manual_steps(source))
    assert "leave Block Options > Question Randomization off" in steps and "Randomly present" not in steps


def test_psychopy_test_loops_are_sequential_in_declared_order(pointlight, tmp_path):
    files = psychopy_files(load_source(pointlight))
    blocks = list(csv.DictReader(io.StringIO(files["blocks.csv"])))
    assert len(blocks) == 6 and {b["test_loop"] for b in blocks} == {"sequential"}
    lists = {tuple(r["stimulus_id"] for r in csv.DictReader(io.StringIO(files[b["test_file"]]))) for b in blocks}
    assert lists == design_lists(pointlight)
    default = psychopy_files(load_source(folder_of(tmp_path, text_of("thesis_pointlight", "random"))))
    assert "test_loop" not in default["blocks.csv"].splitlines()[0]


def test_psychopy_export_notes_the_loop_type(pointlight, tmp_path):
    from stimuli.survey import export_survey

    result = export_survey(pointlight, "psychopy", tmp_path / "pp")
    assert any("sequential" in note for note in result.notes)


def test_jspsych_replays_the_fixed_order(pointlight):
    lists = config(load_source(pointlight))["lists"]
    assert len(lists) == 60
    for entry in lists:
        shown = [t["id"].split("-")[0] for t in entry["trials"] if t["kind"] == "test"]
        assert shown == [level for level, _ in TABLE_4_2]


def test_design_json_of_the_fixed_protocol_names_the_order(pointlight):
    p = load_protocol(ROOT / "protocols" / "thesis_pointlight.yaml")
    assert design_json(build_design(p, participants=6))["protocol"]["blocks"] == {"by": [], "order": "fixed",
                                                                                  "trials": "fixed"}


def test_a_qualtrics_export_of_a_fixed_block_imports(pointlight, tmp_path):
    """Qualtrics writes no ``<block>_DO`` column for a block whose questions are not randomised: the
    answers still import by their export tags (only the trial numbers stay empty)."""
    from analysis.io_design import load_design
    from analysis.io_writers import qualtrics_text
    from analysis.model_spec import load_model
    from analysis.responses import import_responses
    from analysis.simulate import simulate_responses

    design = load_design(pointlight)
    sim = simulate_responses(design, load_model(None, design), 12, seed=3)
    text = qualtrics_text(sim, design, "numeric")   # the simulated export is shaped the same way
    assert [c for c in next(csv.reader(io.StringIO(text))) if c.endswith("_DO")] == ["FL_5_DO"]
    path = tmp_path / "qualtrics.csv"
    path.write_text(text, encoding="utf-8")
    result = import_responses(path, design)
    assert result.reconciles and len(result.data) == 120
