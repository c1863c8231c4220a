"""Malformed protocols: exit code 2, one paragraph naming the field (and line), nothing written."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from stimuli.errors import StimuliError
from stimuli.protocol import load_protocol, parse_protocol

EXP1 = (Path(__file__).resolve().parents[1] / "protocols" / "exp1_shape_motion.yaml").read_text()
EXP2 = (Path(__file__).resolve().parents[1] / "protocols" / "exp2_com_vs_average.yaml").read_text()


def edited(text: str, change) -> str:
    data = yaml.safe_load(text)
    change(data)
    return yaml.safe_dump(data, sort_keys=False)


def replace(text: str, old: str, new: str) -> str:
    assert old in text, old
    return text.replace(old, new, 1)


CASES = {
    "misspelt top-level field": (replace(EXP1, "participants: 16", "partcipants: 16"), ["partcipants", "unknown field", "line 9"]),
    "YAML syntax error": (replace(EXP1, "levels: [F, M]", "levels: [F, M"), ["YAML syntax error", "line"]),
    "BMI out of human range": (replace(EXP1, "bmi: 28.1", "bmi: 281"), ["actors.0.bmi", "line 14", "less than or equal to 60"]),
    "height out of human range": (replace(EXP1, "height_m: 1.64", "height_m: 16.4"), ["actors.1.height_m", "line 15"]),
    "mis-typed number": (replace(EXP1, "repetitions: 2 ", "repetitions: twice "), ["repetitions", "valid integer", "'twice'"]),
    "unbalanced between groups": (replace(EXP1, "participants: 16", "participants: 15"), ["participants", "cannot be balanced", "multiple of 2", "line 9"]),
    "block factor not declared": (replace(EXP1, "by: [GAIT]", "by: [GAITS]"), ["blocks.by", "unknown factor 'GAITS'"]),
    "level names no actor": (replace(EXP1, "{id: F_Lo2, label: Lo2,", "{id: F_Lo2, label: Lo9,"),
                             ["factors.BODY", "'Lo2'", "names no actor", "sex F"]),
    "gait level not declared": (replace(EXP1, "levels: [walk, jog]\n    maps_to: gait\n    abbreviations: {walk: W, jog: J}",
                                        "levels: [walk, run]\n    maps_to: gait\n    abbreviations: {walk: W, run: R}"),
                                ["factors.GAIT", "['run']", "gaits"]),
    "practice uses a test level": (replace(EXP1, "levels: {BODY: [P1, P2], MOTION: [P1, P2]}", "levels: {BODY: [P1, Hi1], MOTION: [P1, P2]}"),
                                   ["practice.levels.BODY", "['Hi1']", "test levels"]),
    "unknown role": (replace(EXP1, "role: between", "role: sometimes"), ["factors.0.role", "'between'", "'within'"]),
    "required field missing": (edited(EXP1, lambda d: d.pop("response")), ["response", "required field is missing"]),
    "duplicate actor ids": (edited(EXP1, lambda d: d["actors"].append(dict(d["actors"][0]))), ["actors", "ids repeat", "F_Hi1"]),
    "likert without labels": (edited(EXP1, lambda d: d["response"].update(labels=[])), ["response", "at least 2 labels"]),
    "forced choice without alternatives": (edited(EXP1, lambda d: d["response"].update(type="afc")), ["response.type", "alternatives"]),
    "three alternatives side by side": (edited(EXP2, lambda d: d["factors"][3].update(levels=["NoCOM", "COM", "X"])),
                                        ["display.layout", "side_by_side shows 2 clips"]),
    "repeated levels": (replace(EXP1, "levels: [F, M]", "levels: [F, F]"), ["factors.0", "levels of SEX repeat"]),
    "abbreviation for an unknown level": (replace(EXP1, "{walk: W, jog: J}", "{walk: W, run: R}"), ["factors.1", "['run']", "not levels of GAIT"]),
    "not a mapping": ("- just\n- a list\n", ["must be a YAML mapping"]),
    # What the renderer would refuse later must fail here (walkthrough, issue "validate passes things render
    # then rejects").
    "alternatives the renderer makes no motion for": (
        edited(EXP2, lambda d: d["factors"][3].update(maps_to="gait", level_settings={})),
        ["factors.3.maps_to", "METHOD is an alternatives factor", "method, strength, source only", "'gait'"]),
    "odd clip width": (replace(EXP1, "width: 1280", "width: 321"), ["clip.width", "line 60", "even", "320 or 322"]),
    "odd clip height": (replace(EXP1, "height: 720", "height: 181"), ["clip.height", "line 61", "even", "180 or 182"]),
    "measure that does not fit the response": (
        replace(EXP1, "dependent_measure: mean_rating", "dependent_measure: percent_chosen"),
        ["analysis.dependent_measure", "line 89", "percent_chosen does not fit response.type likert", "mean_rating"]),
    "forced choice analysed as ratings": (
        replace(EXP2, "dependent_measure: percent_chosen", "dependent_measure: mean_rating"),
        ["analysis.dependent_measure", "response.type afc", "percent_chosen or votes"]),
    "clip shorter than one gait cycle": (
        replace(EXP1, "duration_s: 4 ", "duration_s: 0.1 "),
        ["clip.duration_s", "line 57", "shorter than one gait cycle of walk (112 steps/min: 1.07 s",
         "duration_s >= 1.07 s"]),
    "fewer gait cycles than clip.cycles": (
        replace(EXP1, "cycles: 2", "cycles: 5"),
        ["clip.cycles", "line 58", "at least 5 whole cycles", "walk (112 steps/min) 4", "duration_s >= 5.36 s"]),
    "one practice clip repeated back to back": (
        replace(EXP1, "levels: {BODY: [P1, P2], MOTION: [P1, P2]}", "levels: {BODY: [P1], MOTION: [P1]}"),
        ["practice.per_block", "line 71", "4 practice trials per block", "only 1 distinct practice clip",
         "BODY: P1, MOTION: P1"]),
    "practice levels for the block factor": (
        replace(EXP1, "levels: {BODY: [P1, P2], MOTION: [P1, P2]}", "levels: {GAIT: [run]}"),
        ["practice.levels.GAIT", "line 72", "GAIT defines the blocks", "within factors that do not define blocks"]),
    # Bad-input audit: practice levels are checked whatever per_block is, and never crash.
    "practice levels for the between factor": (
        replace(EXP1, "levels: {BODY: [P1, P2], MOTION: [P1, P2]}", "levels: {SEX: [X], BODY: [P1, P2]}"),
        ["practice.levels.SEX", "line 72", "SEX is a between factor", "within factors that do not define blocks"]),
    "practice levels for the between factor, per_block 0": (
        replace(replace(EXP1, "levels: {BODY: [P1, P2], MOTION: [P1, P2]}", "levels: {SEX: [X]}"),
                "per_block: 4 ", "per_block: 0 "),
        ["practice.levels.SEX", "SEX is a between factor"]),
    "practice levels for the block factor, per_block 0": (
        replace(replace(EXP1, "levels: {BODY: [P1, P2], MOTION: [P1, P2]}", "levels: {GAIT: [run]}"),
                "per_block: 4 ", "per_block: 0 "),
        ["practice.levels.GAIT", "GAIT defines the blocks"]),
    "practice level naming no actor, per_block 0": (
        replace(replace(EXP1, "levels: {BODY: [P1, P2], MOTION: [P1, P2]}", "levels: {BODY: [P9]}"),
                "per_block: 4 ", "per_block: 0 "),
        ["factors.BODY", "'P9'", "names no actor"]),
    "practice levels for the alternatives factor": (
        replace(EXP2, "levels: {BODY: [P1, P2]}", "levels: {BODY: [P1, P2], METHOD: [X]}"),
        ["practice.levels.METHOD", "METHOD is an alternatives factor"]),
    "repeated practice levels": (
        replace(EXP1, "levels: {BODY: [P1, P2], MOTION: [P1, P2]}", "levels: {BODY: [P1, P1], MOTION: [P1, P2]}"),
        ["practice.levels.BODY", "line 72", "levels repeat: ['P1']"]),
    "empty practice level list": (
        replace(EXP1, "levels: {BODY: [P1, P2], MOTION: [P1, P2]}", "levels: {BODY: []}"),
        ["practice.levels.BODY", "line 72", "the list is empty"]),
    "two METHOD levels set to the same motion": (
        replace(EXP2, "COM: {motion: physics}", "COM: {motion: average}"),
        ["factors.3.level_settings.COM.motion", "line 49", "'NoCOM' and 'COM' both show the average motion"]),
    "two METHOD levels without settings, named alike by the fallback": (
        edited(EXP2, lambda d: d["factors"][3].update(levels=["A", "B"], abbreviations={}, level_settings={})),
        ["factors.3.levels", "'A' and 'B' both show the physics motion", "NoCOM = average"]),
    "two SOURCE levels with the same motion": (
        replace((Path(__file__).resolve().parents[1] / "protocols" / "thesis_validation.yaml").read_text(),
                "keyframed: {motion: generator}", "keyframed: {motion: lean_walk}"),
        ["level_settings.keyframed.motion", "'lean_mocap' and 'keyframed' both show the lean_walk motion"]),
    "clip.cycles given as true": (replace(EXP1, "cycles: 2", "cycles: true"),
                                  ["clip.cycles", "line 58", "valid integer", "(got True)", "without quotes"]),
    "clip.cycles given as text": (replace(EXP1, "cycles: 2", 'cycles: "2"'), ["clip.cycles", "line 58", "(got '2')"]),
    "clip.loop given as a number": (replace(EXP1, "cycles: 2", "cycles: 2\n  loop: 0"),
                                    ["clip.loop", "line 59", "valid boolean", "(got 0)", "true or false"]),
    "clip.loop given as text": (replace(EXP1, "cycles: 2", 'cycles: 2\n  loop: "false"'),
                                ["clip.loop", "valid boolean", "(got 'false')"]),
    "unknown clip field": (replace(EXP1, "cycles: 2", "cyclez: 2"),
                           ["clip.cyclez", "line 58", "unknown field", "duration_s, cycles, fps, width, height"]),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_malformed_protocol_exit_2_names_field(case, tmp_path, run_cli):
    text, expected = CASES[case]
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    out = tmp_path / "out"
    code, stdout, stderr = run_cli("design", path, "--out", out)
    assert code == 2
    assert "Traceback" not in stderr and stderr.startswith("shapemotion: error:")
    message = " ".join(stderr.split())
    assert str(path) in message
    for fragment in expected:
        assert fragment in message, (fragment, message)
    assert not out.exists()  # nothing written


def test_missing_file_and_api_exception(tmp_path, run_cli):
    code, _, stderr = run_cli("validate", tmp_path / "nope.yaml")
    assert code == 2 and "not found" in stderr
    with pytest.raises(StimuliError, match="participants"):
        parse_protocol(replace(EXP1, "participants: 16", "participants: 15"))


def test_cli_participants_override_must_balance(tmp_path, run_cli):
    code, _, stderr = run_cli("design", "protocols/exp1_shape_motion.yaml", "--participants", "9", "--out", tmp_path / "o")
    assert code == 2 and "--participants" in stderr and not (tmp_path / "o").exists()


@pytest.mark.parametrize("name", ["exp1_shape_motion", "exp2_com_vs_average", "thesis_pointlight", "thesis_mesh", "thesis_validation"])
def test_bundled_protocols_valid(name, protocol_path, run_cli):
    assert load_protocol(protocol_path(name)).name == name
    code, out, _ = run_cli("validate", protocol_path(name))
    assert code == 0 and "valid protocol" in out


def test_exp1_protocol_matches_table2():
    p = load_protocol("protocols/exp1_shape_motion.yaml")
    table2 = {("F", "Hi1"): (1.60, 28.1), ("F", "Hi2"): (1.64, 25.3), ("F", "Lo1"): (1.60, 24.8), ("F", "Lo2"): (1.60, 19.5),
              ("M", "Hi1"): (1.79, 32.1), ("M", "Hi2"): (1.83, 35.8), ("M", "Lo1"): (1.81, 22.7), ("M", "Lo2"): (1.82, 21.7)}
    for (sex, label), (height, bmi) in table2.items():
        actor = p.actor(sex, label)
        assert (actor.height_m, actor.bmi) == (height, bmi)
    assert [(f.name, f.role) for f in p.factors] == [("SEX", "between"), ("GAIT", "within"), ("BODY", "within"), ("MOTION", "within")]
    assert p.participants == 16 and p.repetitions == 2 and p.clip.duration_s == 4
    assert p.response.labels[0] == "Very Inconsistent" and p.response.labels[-1] == "Very Consistent"


def test_unlooped_clip_too_short_for_one_cycle_suggests_no_impossible_fix(tmp_path, run_cli):
    """cycles is already 1 (the fewest): only a longer clip helps, so 'lower clip.cycles' is not offered."""
    text = replace(replace(EXP1, "cycles: 2", "cycles: 1\n  loop: false"), "duration_s: 4 ", "duration_s: 0.5 ")
    path = tmp_path / "short.yaml"
    path.write_text(text)
    code, _, stderr = run_cli("validate", path)
    message = " ".join(stderr.split())
    assert code == 2 and "Traceback" not in stderr
    assert "clip.duration_s (line 57)" in message and "duration_s >= 1.07 s" in message
    assert "lower clip.cycles" not in message
