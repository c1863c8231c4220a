"""Qualtrics TXT, PsychoPy and jsPsych exports, HTML escaping, and the ``survey`` command."""

from __future__ import annotations

import csv
import hashlib
import json
import re
from pathlib import Path

import pytest

from stimuli.design import build_design, write_design
from stimuli.errors import StimuliError
from stimuli.protocol import load_protocol, parse_protocol
from stimuli.survey import export_survey
from stimuli.survey.qualtrics_txt import manual_steps, txt_text
from stimuli.survey.source import load_source

ROOT = Path(__file__).resolve().parents[1]
EVIL = "<script>alert(1)</script>"
EVIL_IMG = '<img src=x onerror="window.__xss=1">'


def design_folder(tmp_path: Path, name: str, text: str | None = None) -> Path:
    protocol = parse_protocol(text) if text else load_protocol(ROOT / "protocols" / f"{name}.yaml")
    folder = tmp_path / name
    write_design(build_design(protocol), folder)
    return folder


def evil_protocol_text() -> str:
    """Exp. 1 with markup in the title, consent, instructions, question and a Likert label."""
    text = (ROOT / "protocols" / "exp1_shape_motion.yaml").read_text()
    text = text.replace("title: Shape and motion consistency (Experiment 1)", f"title: '{EVIL} study'")
    text = text.replace("question: How consistent", f"question: '{EVIL_IMG}' # How consistent")
    text = text.replace("labels: [Very Inconsistent,", "labels: ['<b>Very</b> Inconsistent',")
    text = re.sub(r"instructions: >-\n", f"instructions: >-\n    {EVIL} & {EVIL_IMG}\n", text, count=1)
    return text.replace("consent: >-\n", f"consent: >-\n  {EVIL}\n", 1)


def tree_digest(folder: Path) -> str:
    digest = hashlib.sha256()
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        digest.update(str(path.relative_to(folder)).encode() + path.read_bytes())
    return digest.hexdigest()


# -- Qualtrics TXT --------------------------------------------------------------------------------

def test_txt_has_one_tagged_question_per_clip_and_lists_manual_steps(tmp_path):
    source = load_source(design_folder(tmp_path, "exp1_shape_motion"))
    text = txt_text(source, "https://x.org/s")
    assert text.startswith("[[AdvancedFormat]]\n") and "[[ED:shapemotion_protocol:exp1_shape_motion]]" in text
    tags = re.findall(r"\[\[Question:MC:SingleAnswer:Horizontal\]\]\n\[\[ID:([^\]]+)\]\]", text)
    assert len(tags) == 144 and len(set(tags)) == 144
    assert "F-walk-Hi1-Lo2_r2" in tags and text.count("[[Block:") == 2 + 8
    assert 'src="https://x.org/s/clips/F-walk-Hi1-Lo2.mp4"' in text
    steps = "\n".join(manual_steps(source))
    assert "Evenly Present" in steps and "SEX" in steps and "hideNextButton" in steps


def test_txt_ranking_is_a_matrix_of_ranks(tmp_path):
    text = txt_text(load_source(design_folder(tmp_path, "thesis_validation")))
    block = text.split("[[Question:Matrix]]\n")[1]
    assert block.split("[[Choices]]\n")[1].split("[[Answers]]")[0].split() == ["A", "B", "C", "D"]
    assert block.split("[[Answers]]\n")[1].split() == ["1", "2", "3", "4"]


# -- PsychoPy -------------------------------------------------------------------------------------

def test_psychopy_conditions_per_block_and_trials(tmp_path):
    folder = design_folder(tmp_path, "exp2_com_vs_average")
    export_survey(folder, "psychopy", tmp_path / "pp")
    blocks = list(csv.DictReader(open(tmp_path / "pp" / "blocks.csv")))
    assert [b["block_label"] for b in blocks] == ["SEX=F|GAIT=walk", "SEX=F|GAIT=jog", "SEX=M|GAIT=walk",
                                                  "SEX=M|GAIT=jog"]
    for b in blocks:
        tests = list(csv.DictReader(open(tmp_path / "pp" / b["test_file"])))
        assert len(tests) == 8 and b["nReps"] == "2"
        assert {(t["left"], t["right"]) for t in tests} == {("NoCOM", "COM"), ("COM", "NoCOM")}
        assert b["familiarization_file"] == "" and b["practice_per_block"] == "4"   # nested: per SEX block
        assert (tmp_path / "pp" / tests[0]["movie"]).resolve() == (folder / "clips" / f"{tests[0]['stimulus_id']}.mp4").resolve()
    for main in csv.DictReader(open(tmp_path / "pp" / "main_blocks.csv")):
        fam = [r["stimulus_id"] for r in csv.DictReader(open(tmp_path / "pp" / main["familiarization_file"]))]
        assert len(fam) == 4 and all(sid.startswith(f"fam-{main['main_block'][-1]}_") for sid in fam)
    trials = list(csv.DictReader(open(tmp_path / "pp" / "trials.csv")))
    assert len(trials) == 16 * 88 and trials[0]["movie"].endswith(trials[0]["stimulus_id"] + ".mp4")


# -- jsPsych folder (the browser run is in test_survey_browser.py) ---------------------------------

def read_config(folder: Path) -> dict:
    text = (folder / "config.js").read_text()
    return json.loads(text.removeprefix("window.SHAPEMOTION_CONFIG = ").removesuffix(";\n"))


def test_jspsych_folder_replays_trials_csv(tmp_path):
    folder = design_folder(tmp_path, "exp1_shape_motion")
    result = export_survey(folder, "jspsych", tmp_path / "js")
    out = tmp_path / "js"
    assert {p.name for p in (out / "lib").iterdir()} >= {"jspsych.js", "plugin-video-button-response.js",
                                                          "plugin-preload.js", "jspsych.css"}
    config = read_config(out)
    rows = list(csv.DictReader(open(folder / "trials.csv")))
    assert len(config["lists"]) == 16 and config["between"] == ["SEX"]
    first = [t for t in config["lists"] if t["list"] == 1][0]
    expected = [r for r in rows if r["participant"] == "1"]
    assert [t["id"] for t in first["trials"]] == [r["stimulus_id"] for r in expected]
    assert first["groups"] == {"SEX": expected[0]["SEX"]}
    assert config["clips"]["F-walk-Hi1-Lo2"] == "clips/F-walk-Hi1-Lo2.mp4"
    assert result.notes and "not found" in result.notes[0]      # no clips rendered yet


def test_jspsych_uses_manifest_files_and_copies_clips(tmp_path):
    folder = design_folder(tmp_path, "thesis_validation")
    (folder / "media").mkdir()
    (folder / "media" / "v.mp4").write_bytes(b"not really a video")
    with open(folder / "manifest.csv", "w") as handle:
        handle.write("stimulus_id,file,sha256\nall-lean_mocap_keyframed_modifier_obese_mocap,media/v.mp4,x\n")
    result = export_survey(folder, "jspsych", tmp_path / "js")
    assert not result.notes
    assert (tmp_path / "js" / "media" / "v.mp4").read_bytes() == b"not really a video"
    assert read_config(tmp_path / "js")["clips"] == {"all-lean_mocap_keyframed_modifier_obese_mocap": "media/v.mp4"}


def test_jspsych_with_a_base_url_references_the_clips_there(tmp_path):
    folder = design_folder(tmp_path, "thesis_validation")
    (folder / "clips").mkdir()
    (folder / "clips" / "all-lean_mocap_keyframed_modifier_obese_mocap.mp4").write_bytes(b"x")
    result = export_survey(folder, "jspsych", tmp_path / "js", "https://cdn.example.org/v1/")
    assert read_config(tmp_path / "js")["clips"] == {
        "all-lean_mocap_keyframed_modifier_obese_mocap":
            "https://cdn.example.org/v1/clips/all-lean_mocap_keyframed_modifier_obese_mocap.mp4"}
    assert not (tmp_path / "js" / "clips").exists() and not result.notes


def test_exports_are_deterministic(tmp_path):
    folder = design_folder(tmp_path, "exp2_com_vs_average")
    for fmt in ("jspsych", "psychopy"):
        export_survey(folder, fmt, tmp_path / f"{fmt}1")
        export_survey(folder, fmt, tmp_path / f"{fmt}2")
        assert tree_digest(tmp_path / f"{fmt}1") == tree_digest(tmp_path / f"{fmt}2")


# -- escaping --------------------------------------------------------------------------------------

def test_protocol_markup_is_text_in_every_export(tmp_path):
    folder = design_folder(tmp_path, "evil", evil_protocol_text())
    outputs = {}
    for fmt, out in (("qsf", "s.qsf"), ("qualtrics-txt", "s.txt"), ("jspsych", "js")):
        export_survey(folder, fmt, tmp_path / out, "https://x.org")
        path = tmp_path / out
        outputs[fmt] = (path / "config.js").read_text() + (path / "index.html").read_text() if path.is_dir() \
            else path.read_text()
    qsf = json.loads(outputs["qsf"])
    html_fields = json.dumps([e["Payload"] for e in qsf["SurveyElements"] if e["Element"] == "SQ"])
    raw = read_config(tmp_path / "js")
    assert raw["response"]["labels"][0] == "<b>Very</b> Inconsistent"   # data only, never shown as HTML
    config = json.dumps([raw["text"], raw["response"]["labels_html"]])
    for fmt, text in (("qsf", html_fields), ("qualtrics-txt", outputs["qualtrics-txt"]), ("jspsych", config)):
        assert "<script" not in text and "<img" not in text and "<b>Very" not in text, fmt
        assert "&lt;script&gt;alert(1)&lt;/script&gt;" in text, fmt
        assert "&lt;img src=x onerror=&quot;window.__xss=1&quot;&gt;" in text, fmt
    assert "&lt;b&gt;Very&lt;/b&gt; Inconsistent" in html_fields
    assert "<title>&lt;script&gt;alert(1)&lt;/script&gt; study</title>" in outputs["jspsych"]
    assert "<script>alert" not in (tmp_path / "js" / "config.js").read_text()


# -- command line and errors --------------------------------------------------------------------------

def test_base_url_that_repeats_the_clips_folder_is_noted(tmp_path, run_cli):
    """Clip files start with clips/: a base URL ending in clips/ would address …/clips/clips/<id>.mp4."""
    folder = design_folder(tmp_path, "exp1_shape_motion")
    code, _, err = run_cli("survey", folder, "--format", "qsf", "--out", tmp_path / "s.qsf",
                           "--video-base-url", "https://x.org/clips/")
    assert code == 0 and "ends in clips/" in err and "https://x.org/clips/clips/" in (tmp_path / "s.qsf").read_text()
    assert "addressed as https://x.org/clips/clips/" in " ".join(err.split())


@pytest.mark.parametrize("url, message", [("https://x.org/exp1?a=1", "cannot carry a query"),
                                          ("https://x.org/e#f", "or fragment"), ("http://", "with a host")])
def test_base_url_that_cannot_take_clip_paths_is_refused(tmp_path, run_cli, url, message):
    """The clip's path is appended to the base: a query or fragment (…?a=1/clips/x.mp4) or a host-less
    http:// (http:/clips/…) made broken addresses without a word."""
    folder = design_folder(tmp_path, "exp1_shape_motion")
    for fmt, out in (("qsf", tmp_path / "s.qsf"), ("jspsych", tmp_path / "js")):
        code, _, err = run_cli("survey", folder, "--format", fmt, "--out", out, "--video-base-url", url)
        assert code == 2 and message in " ".join(err.split()) and not out.exists()


def test_practice_longer_than_its_pool_is_noted_for_qualtrics(tmp_path, run_cli):
    """6 practice trials from 4 clips: Qualtrics draws them from copies and may repeat one back to back."""
    text = (ROOT / "protocols" / "exp1_shape_motion.yaml").read_text().replace("per_block: 4", "per_block: 6", 1)
    folder = design_folder(tmp_path, "exp1_shape_motion", text)
    code, _, err = run_cli("survey", folder, "--format", "qsf", "--out", tmp_path / "s.qsf",
                           "--video-base-url", "https://x.org")
    flat_err = " ".join(err.split())
    assert code == 0 and "6 trials from 4 clip(s)" in flat_err and "may show one twice in a row" in flat_err


def test_cli_writes_each_format(tmp_path, run_cli):
    folder = design_folder(tmp_path, "exp1_shape_motion")
    code, out, err = run_cli("survey", folder, "--format", "qsf", "--out", tmp_path / "s.qsf",
                             "--video-base-url", "https://x.org")
    assert code == 0 and out.strip() == str(tmp_path / "s.qsf") and not err
    code, out, err = run_cli("survey", folder, "--format", "qualtrics-txt", "--out", tmp_path / "s.txt")
    assert code == 0 and "Set these by hand" in out and "--video-base-url" in err
    code, out, _ = run_cli("survey", folder, "--format", "psychopy", "--out", tmp_path / "pp")
    assert code == 0 and (tmp_path / "pp" / "blocks.csv").exists()


@pytest.mark.parametrize("case, expected", [
    ("no_design", "design.json: not found"),
    ("bad_manifest", "manifest.csv: no row for stimulus"),
    ("manifest_outside", "must be a path inside the folder"),
    ("unknown_trial", "trials.csv: row 2: stimulus_id 'nope'"),
    ("out_not_empty", "not an empty folder"),
])
def test_user_errors_exit_2_without_output(tmp_path, run_cli, case, expected):
    folder = design_folder(tmp_path, "thesis_validation")
    out = tmp_path / "out"
    fmt = "qsf"
    if case == "no_design":
        (folder / "design.json").unlink()
    elif case == "bad_manifest":
        (folder / "manifest.csv").write_text("stimulus_id,file\nother,clips/other.mp4\n")
    elif case == "manifest_outside":
        (folder / "manifest.csv").write_text(
            "stimulus_id,file\nall-lean_mocap_keyframed_modifier_obese_mocap,../x.mp4\n")
    elif case == "unknown_trial":
        text = (folder / "trials.csv").read_text().splitlines()
        text[1] = text[1].replace("all-lean_mocap_keyframed_modifier_obese_mocap", "nope")
        (folder / "trials.csv").write_text("\n".join(text) + "\n")
    else:
        fmt = "jspsych"
        out.mkdir()
        (out / "keep.txt").write_text("x")
    code, _, err = run_cli("survey", folder, "--format", fmt, "--out", out)
    assert code == 2 and expected in " ".join(err.split()), err
    assert not out.exists() or [p.name for p in out.iterdir()] == ["keep.txt"]


def test_export_api_rejects_unknown_format(tmp_path):
    with pytest.raises(StimuliError, match="--format"):
        export_survey(design_folder(tmp_path, "thesis_validation"), "word", tmp_path / "x")


def test_export_all_writes_every_format_for_render_and_demo(tmp_path):
    from stimuli.survey import export_all

    folder = design_folder(tmp_path, "exp2_com_vs_average")
    results = export_all(folder, video_base_url="https://x.org")
    assert [r.format for r in results] == ["qsf", "qualtrics-txt", "jspsych", "psychopy"]
    survey = folder / "survey"
    assert {p.name for p in survey.iterdir()} == {"survey.qsf", "survey_qualtrics.txt", "jspsych", "psychopy",
                                                  "qualtrics_manual_steps.txt"}
    steps = (survey / "qualtrics_manual_steps.txt").read_text()
    assert steps.startswith("After importing survey_qualtrics.txt")
    assert "Randomizer presenting all 2 main-block Groups" in steps   # Exp. 2's nested SEX > GAIT blocks
    again = export_all(folder, video_base_url="https://x.org")      # a second run keeps the jsPsych folder
    assert "left as it is" in again[2].notes[0]


def test_missing_jspsych_install_is_a_user_error(tmp_path, run_cli, monkeypatch):
    from stimuli.survey import export_all

    folder = design_folder(tmp_path, "thesis_validation")
    monkeypatch.setenv("SHAPEMOTION_NODE_MODULES", str(tmp_path / "nowhere"))
    code, _, err = run_cli("survey", folder, "--format", "jspsych", "--out", tmp_path / "js")
    assert code == 2 and "npm ci" in err and not (tmp_path / "js").exists()
    results = export_all(folder, tmp_path / "all")
    assert "jsPsych is not installed" in results[2].notes[0] and (tmp_path / "all" / "survey.qsf").exists()


def test_survey_plan_rotations_show_what_the_design_deals(tmp_path):
    """Qualtrics/PsychoPy rotations follow the design's arrangement rule; with `arrangements: all` the
    design deals Latin-square runs (stimuli.orders.arrangement_index), which the plan used to ignore."""
    from stimuli.survey.plan import build_plan

    text = (ROOT / "protocols" / "thesis_pointlight.yaml").read_text()
    for old, new in (('levels: ["0.5", "12", "23.5", "35", "46.5", "58"]', 'levels: ["0.5", "12", "23.5"]'),
                     ("labels: [A, B, C, D, E, F]", "labels: [A, B, C]"),
                     ("arrangements: latin_square", "arrangements: all"), ("participants: 60", "participants: 12")):
        assert old in text
        text = text.replace(old, new)
    folder = design_folder(tmp_path, "three", text)
    design = json.loads((folder / "design.json").read_text())
    rotations = build_plan(load_source(folder))[0].rotations
    assert len(rotations) == 6
    with open(folder / "trials.csv", newline="") as handle:
        trials = list(csv.DictReader(handle))
    for participant in range(1, design["participants"] + 1):
        dealt = {t["stimulus_id"] for t in trials if int(t["participant"]) == participant and t["kind"] == "test"}
        planned = {s.stimulus_id for block in rotations[(participant - 1) % 6].blocks for s, _ in block.tests}
        assert dealt == planned, participant
