"""Protocols that could silently go wrong (issue 26, items 2, 3, 5 and 9): refused at load with exit 2,
a short message naming the field and its line, and nothing written."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from stimuli.errors import StimuliError
from analysis.io_yaml import MAX_EXPANDED_SIZE
from stimuli.protocol import MAX_PROTOCOL_BYTES, load_protocol, parse_protocol, shown

PROTOCOLS = Path(__file__).resolve().parents[1] / "protocols"
EXP1 = (PROTOCOLS / "exp1_shape_motion.yaml").read_text()
EXP2 = (PROTOCOLS / "exp2_com_vs_average.yaml").read_text()
LIKERT = "[Very Inconsistent, Inconsistent, Neutral, Consistent, Very Consistent]"


def replace(text: str, old: str, new: str) -> str:
    assert old in text, old
    return text.replace(old, new, 1)


def refused(run_cli, tmp_path, text: str, command: str = "design") -> str:
    """Run ``validate`` or ``design`` on ``text``: exit 2, one paragraph naming the file, nothing written;
    return the message with its line breaks undone."""
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    out = tmp_path / "out"
    args = ("design", path, "--out", out) if command == "design" else ("validate", path)
    code, _, stderr = run_cli(*args)
    assert code == 2, stderr
    assert stderr.startswith("shapemotion: error:") and "Traceback" not in stderr
    assert not out.exists()
    message = " ".join(stderr.split())
    assert str(path) in message
    return message


# -- item 2: labels and abbreviations that make answers or post-hoc labels ambiguous ------------------

LABEL_CASES = {
    "repeated Likert labels": (
        replace(EXP1, LIKERT, "[Disagree, Disagree, Neutral, Agree, Agree]"),
        ["response.labels.1 (line 77)", "label 2 'Disagree' repeats label 1", "ignoring case and spacing"]),
    "five equal labels": (
        replace(EXP1, LIKERT, "[Same, Same, Same, Same, Same]"),
        ["response.labels.1", "label 2 'Same' repeats label 1 ('Same')"]),
    "labels equal but for case and spacing": (
        replace(EXP1, LIKERT, "[Disagree, Neutral, 'agree ', Agree]"),
        ["response.labels.3", "label 4 'Agree' repeats label 3 ('agree ')"]),
    "an empty label": (
        replace(EXP1, LIKERT, '[Disagree, "", Agree]'),
        ["response.labels.1 (line 77)", "label 2 is blank", "every point of the scale needs a label"]),
    "a label of spaces": (
        replace(EXP1, LIKERT, '[Disagree, Neutral, "  ", Agree]'),
        ["response.labels.2", "label 3 is blank"]),
    "repeated position labels": (
        replace((PROTOCOLS / "thesis_validation.yaml").read_text(), "labels: [A, B, C, D]", "labels: [A, B, b, D]"),
        ["display.labels.2", "label 3 'b' repeats label 2 ('B')"]),
    "repeated abbreviations": (
        replace(EXP1, "{walk: W, jog: J}", "{walk: W, jog: W}"),
        ["factors.1.abbreviations (line 36)", "GAIT levels 'walk' and 'jog' are both shown as 'W'"]),
    "an abbreviation that another level shows unabbreviated": (
        replace(EXP1, "{walk: W, jog: J}", "{walk: jog}"),
        ["factors.1.abbreviations", "'walk' is abbreviated 'jog', the name of another GAIT level"]),
    "abbreviations that swap two levels' names": (
        replace(EXP1, "{walk: W, jog: J}", "{walk: jog, jog: walk}"),
        ["factors.1.abbreviations", "'walk' is abbreviated 'jog', the name of another GAIT level"]),
    "a blank abbreviation": (
        replace(EXP1, "{walk: W, jog: J}", "{walk: ' ', jog: J}"),
        ["factors.1.abbreviations", "the abbreviation of 'walk' is blank"]),
}


@pytest.mark.parametrize("case", sorted(LABEL_CASES))
def test_ambiguous_labels_are_refused(case, tmp_path, run_cli):
    text, expected = LABEL_CASES[case]
    message = refused(run_cli, tmp_path, text)
    for fragment in expected:
        assert fragment in message, (fragment, message)


def test_distinct_labels_with_numbers_and_case_still_load():
    """Labels that differ (even ``1``…``5`` or ``Agree``/``Strongly agree``) are fine."""
    assert parse_protocol(replace(EXP1, LIKERT, "['1', '2', '3', '4', '5']")).response.labels[0] == "1"
    p = parse_protocol(replace(EXP1, LIKERT, "[Strongly disagree, Disagree, Agree, Strongly agree]"))
    assert len(p.response.labels) == 4


def test_design_json_with_repeated_labels_is_refused(tmp_path, run_cli):
    """A design.json written by another tool may carry a scale the protocol loader would refuse."""
    import json

    from analysis.errors import AnalysisError
    from analysis.io_design import load_design

    out = tmp_path / "design"
    assert run_cli("design", PROTOCOLS / "exp1_shape_motion.yaml", "--out", out)[0] == 0
    meta = json.loads((out / "design.json").read_text())
    meta["response"]["labels"] = ["Disagree", "Disagree", "Neutral", "Agree", "Agree"]
    (out / "design.json").write_text(json.dumps(meta))
    with pytest.raises(AnalysisError, match=r"response.labels.1: label 2 'Disagree' repeats label 1"):
        load_design(out)
    meta["response"]["labels"] = ["Disagree", " ", "Neutral"]
    (out / "design.json").write_text(json.dumps(meta))
    with pytest.raises(AnalysisError, match=r"response.labels.1: label 2 is blank"):
        load_design(out)


# -- item 3: size, aliases, nesting, long values ---------------------------------------------------

def bomb(levels: int = 9) -> str:
    """A 'billion laughs' value: anchors defined inside the value itself, each a list of 9 aliases of the
    one before, so that ``levels`` 9 expands to ~10⁹ strings from under 2 KB of text."""
    inner = "[lol, lol, lol, lol, lol, lol, lol, lol, lol]"
    value = f"&a0 {inner}"
    for i in range(1, levels):
        value = f"[{value}, &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]]"
    return value


@pytest.mark.parametrize("field", ["title", "levels"])
def test_alias_bomb_is_refused_fast(field, tmp_path, run_cli):
    """Issue 26 item 3: 120 s and 5.7 GB in ``title``, a MemoryError at 7.5 GB in ``levels``."""
    value = bomb()
    text = (replace(EXP1, "title: Shape and motion consistency (Experiment 1)", f"title: {value}") if field == "title"
            else replace(EXP1, "levels: [walk, jog]", f"levels: {value}"))
    assert len(text) < 8_000
    start = time.perf_counter()
    message = refused(run_cli, tmp_path, text, "validate")
    elapsed = time.perf_counter() - start
    assert elapsed < 1.0, elapsed
    assert "aliases expand" in message and f"{MAX_EXPANDED_SIZE:,}" in message
    assert len(message) < 600


def test_recursive_alias_is_refused(tmp_path, run_cli):
    message = refused(run_cli, tmp_path, replace(EXP1, "title: Shape", "title: &me [*me]\nx: Shape"), "validate")
    assert "line 6" in message and "refers to itself" in message


def test_anchors_within_the_limits_still_load():
    """An alias that shares a block (one camera for two settings) is ordinary YAML and stays allowed."""
    text = replace(EXP1, "  camera: {azimuth_deg: 35, elevation_deg: 10, fov_deg: 40}",
                   "  camera: &cam {azimuth_deg: 35, elevation_deg: 10, fov_deg: 40}")
    text = replace(text, "title: Shape and motion consistency (Experiment 1)", "title: &t Shape and motion")
    text = replace(text, "source: Vyas", "consent: *t\nsource: Vyas")
    text = replace(text, "consent: >-\n  This study is about the perception of animated virtual characters. It takes "
                         "about 20 minutes.\n  Your answers are anonymous and you may stop at any time.\n", "")
    p = parse_protocol(text)
    assert p.consent == p.title == "Shape and motion"


def test_deep_nesting_is_refused_not_a_recursion_error(tmp_path, run_cli):
    message = refused(run_cli, tmp_path, replace(EXP1, "title: Shape", "title: " + "[" * 5000 + "]" * 5000 + "\nx: Shape"),
                      "validate")
    assert "nested deeper than" in message and "line 6" in message


def test_file_over_the_size_limit_is_refused_before_reading(tmp_path, run_cli):
    text = replace(EXP1, "title: Shape", f"title: {'x' * MAX_PROTOCOL_BYTES} Shape")
    message = refused(run_cli, tmp_path, text, "validate")
    assert f"{len(text.encode()):,} bytes" in message and "1 MiB" in message and len(message) < 400


def test_not_a_regular_file_is_refused(tmp_path, run_cli):
    """A FIFO would hang the reader and /dev/zero fill memory: only regular files are read."""
    code, _, stderr = run_cli("validate", "/dev/zero")
    assert code == 2 and "not a regular file" in stderr
    fifo = tmp_path / "protocol.yaml"
    os.mkfifo(fifo)
    code, _, stderr = run_cli("validate", fifo)
    assert code == 2 and "not a regular file" in stderr


LONG = "x" * 1_000_000   # under the size limit: the loader reads it and the message must cut it

LONG_VALUE_CASES = {
    "a 1 MB string in an integer field": (replace(EXP1, "seed: 2023", f"seed: {LONG}"),
                                          ["seed (line 8)", "(got 1,000,000 characters)"]),
    "a 1 MB actor label": (replace(EXP1, "label: Hi1, sex: F", f"label: {LONG}, sex: F"),
                           ["actors.0.label", "1,000,000 characters"]),
    "a 1 MB level": (replace(EXP1, "levels: [walk, jog]", f"levels: [walk, {LONG}]"), ["factors.1", "1,000,000 characters"]),
    # '? key' is YAML's explicit key: a plain key of over 1,024 characters is a syntax error
    "a 1 MB key": (replace(EXP1, "seed: 2023", f"? {LONG}\n: 1\nseed: 2023"),
                   ["<a key of 1,000,000 characters> (line 8): unknown field"]),
    "a 1 MB repeated key": (replace(EXP1, "seed: 2023", f"? {LONG[:500_000]}\n: 1\n? {LONG[:500_000]}\n: 1\nseed: 2023"),
                            ["appears twice", "500,000 characters"]),
}


@pytest.mark.parametrize("case", sorted(LONG_VALUE_CASES))
def test_error_messages_cut_long_values(case):
    text, expected = LONG_VALUE_CASES[case]
    with pytest.raises(StimuliError) as info:
        parse_protocol(text, source="big.yaml")
    message = str(info.value)
    assert len(message) < 1_000, message[:300]
    for fragment in expected:
        assert fragment in message, (fragment, message)


def test_many_problems_make_a_short_message():
    """1,000 wrong actors give a paragraph listing the first few problems and a count of the others."""
    actors = "\n".join(f"  - {{id: A{i}, label: L{i}, sex: X, height_m: 9, bmi: 99}}" for i in range(1_000))
    text = replace(EXP1, "actors:\n", f"actors:\n{actors}\n")
    with pytest.raises(StimuliError) as info:
        parse_protocol(text)
    message = str(info.value)
    assert len(message) < 2_500 and "and 2,990 more problems" in message


def test_shown_values():
    assert shown("Hi1") == "'Hi1'"
    assert shown("x" * 1_048_576) == "1,048,576 characters"
    assert shown(list(range(1_000))) == "a list of 1,000 items"
    assert shown({str(i): i for i in range(100)}) == "a mapping of 100 keys"


def test_bad_scalar_constructions_are_yaml_errors(tmp_path, run_cli):
    """Values PyYAML's constructor raises ValueError on (a date that does not exist, an integer of
    5,000 digits, over Python's limit for decimal text) are errors with a line, not tracebacks."""
    for value in ("!!timestamp 2001-13-45", "1" * 5_000):
        message = refused(run_cli, tmp_path, replace(EXP1, "title: Shape and motion consistency (Experiment 1)",
                                                     f"title: {value}"), "validate")
        assert "line 6" in message and "cannot read the value" in message and len(message) < 400


# -- item 5: actors a level cannot tell apart ------------------------------------------------------

def test_two_actors_of_one_sex_sharing_a_label(tmp_path, run_cli):
    text = replace(EXP1, "  - {id: F_P1,", "  - {id: F_Hi1b, label: Hi1, sex: F, height_m: 1.60, bmi: 28.1}\n  - {id: F_P1,")
    message = refused(run_cli, tmp_path, text)
    assert "actors.8.label (line 22)" in message
    assert "F_Hi1 and F_Hi1b are both sex F with label 'Hi1'" in message


def test_actors_sharing_a_label_without_a_sex_factor(tmp_path, run_cli):
    """Without a factor mapped to sex a label alone names the actor: an F and an M actor may not share it."""
    message = refused(run_cli, tmp_path, replace(EXP1, "maps_to: sex", "maps_to: none"), "validate")
    assert "actors.4.label (line 18)" in message
    assert "F_Hi1 and M_Hi1 share label 'Hi1' and no factor maps to sex" in message


def test_labels_unused_by_any_level_may_repeat():
    """With no factor mapped to body or motion (display.body names the actor by id) labels name nothing."""
    text = replace((PROTOCOLS / "thesis_validation.yaml").read_text(), "{id: MP, label: MP,", "{id: MP, label: AE,")
    assert parse_protocol(text).actors[1].label == "AE"


def test_levels_that_make_one_stimulus_id(tmp_path, run_cli):
    """``a-b`` and ``a_b`` become the same stimulus id (file names keep letters, digits, _ . +)."""
    text = replace(EXP1, "levels: [walk, jog]\n    maps_to: gait\n    abbreviations: {walk: W, jog: J}",
                   "levels: [walk, jog]\n    maps_to: gait\n    abbreviations: {walk: W, jog: J}\n"
                   "  - name: X\n    role: within\n    levels: [a-b, a_b]")
    message = refused(run_cli, tmp_path, text)
    assert "factors.2.levels" in message and "'a-b' and 'a_b' make the same stimulus id 'a_b'" in message


# -- item 9: line numbers point at the item; --out "" ---------------------------------------------

def test_factor_named_in_a_message_points_at_its_own_line(tmp_path, run_cli):
    message = refused(run_cli, tmp_path, replace(EXP1, "{id: F_Lo2, label: Lo2,", "{id: F_Lo2, label: Lo9,"))
    assert "factors.BODY (line 37)" in message


def test_nested_field_named_in_a_message_gets_its_line(tmp_path, run_cli):
    message = refused(run_cli, tmp_path, replace(EXP2, "NoCOM: {motion: average}", "NoCOM: {view_deg: 999}"))
    assert "factors.3.level_settings.NoCOM.view_deg (line 48)" in message


@pytest.mark.parametrize("command", [("design", "protocols/exp1_shape_motion.yaml"), ("demo", "--quick")])
def test_empty_out_is_refused(command, run_cli, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    from stimuli.cli import main

    with pytest.raises(SystemExit) as info:
        main([command[0], str(Path(__file__).resolve().parents[1] / command[1]) if command[0] == "design"
              else command[1], "--out", ""])
    assert info.value.code == 2
    assert "argument --out: an empty path" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_too_many_nodes_are_refused_early():
    """Pure-Python YAML reads ~25,000 nodes a second: a 1 MiB list of one-letter items took 20 s to be
    refused; the loader stops counting at the limit instead."""
    from analysis.io_yaml import MAX_NODES

    text = replace(EXP1, "levels: [walk, jog]", "levels: [" + ", ".join(["a"] * 300_000) + "]")
    start = time.perf_counter()
    with pytest.raises(StimuliError, match=f"more than {MAX_NODES:,} values") as info:
        parse_protocol(text, source="big.yaml")
    assert time.perf_counter() - start < 3.0
    assert "big.yaml: line 34" in str(info.value)


def test_control_character_is_a_message_with_its_line(tmp_path, run_cli):
    """PyYAML's reader refuses control characters before any line is known (the fuzz suite found a
    traceback here): the message counts the line itself."""
    message = refused(run_cli, tmp_path, replace(EXP1, "seed: 2023", "seed: 20\x1f23"), "validate")
    assert "line 8, column 9" in message and "#x001f is not allowed" in message


@pytest.mark.parametrize("args", [["bodies", "--protocol", "protocols/exp1_shape_motion.yaml"],
                                  ["motion", "generate"], ["physics", "retarget"],
                                  ["survey", "protocols", "--format", "jspsych"],
                                  ["render", "protocols/exp1_shape_motion.yaml"],
                                  ["preview", "--gait", "walk", "--body", "sex=M,height=1.8,bmi=25"]])
def test_empty_out_is_refused_by_other_commands(args, capsys):
    """The same argparse type guards every --out of the stimuli commands."""
    from stimuli.cli import main

    with pytest.raises(SystemExit) as info:
        main([*args, "--out", ""])
    assert info.value.code == 2 and "argument --out: an empty path" in capsys.readouterr().err


LEVEL_TYPE_CASES = {
    "practice levels given as a number": ("levels: {BODY: 5, MOTION: [P1, P2]}", "practice.levels.BODY (line 72)",
                                          "valid list (got 5)"),
    "practice levels given as one word": ("levels: {BODY: P1, MOTION: [P1, P2]}", "practice.levels.BODY (line 72)",
                                          "valid list (got 'P1')"),
    "practice levels left empty": ("levels: {BODY: , MOTION: [P1, P2]}", "practice.levels.BODY", "(got None)"),
    "a level YAML reads as true": ("levels: {BODY: [P1, on], MOTION: [P1, P2]}", "practice.levels (line 72)",
                                   "level True: YAML reads yes, no, on, off, true and false as true or false"),
}


@pytest.mark.parametrize("case", sorted(LEVEL_TYPE_CASES))
def test_levels_of_the_wrong_type(case, tmp_path, run_cli):
    """``BODY: 5`` was a TypeError traceback, ``BODY: P1`` the levels 'P' and '1', ``on`` a level 'True'."""
    new, *expected = LEVEL_TYPE_CASES[case]
    message = refused(run_cli, tmp_path, replace(EXP1, "levels: {BODY: [P1, P2], MOTION: [P1, P2]}", new))
    for fragment in expected:
        assert fragment in message, (fragment, message)


def test_numbers_still_name_levels():
    """The point-light protocol's strengths 3, 12, 35 … are numbers to YAML and levels as text."""
    p = load_protocol(PROTOCOLS / "thesis_pointlight.yaml")
    assert all(isinstance(level, str) for f in p.factors for level in f.levels)


@pytest.mark.parametrize("name", ["block", "trial", "rating", "participant"])
def test_factor_named_like_a_design_column_is_refused(name, tmp_path, run_cli):
    """A between factor called ``block`` had its F/M column overwritten by block numbers in trials.csv."""
    message = refused(run_cli, tmp_path, replace(EXP1, "name: SEX", f"name: {name}"))
    assert f"factors.0.name (line 28): factor name '{name}' is a column of the design or answer files" in message


def test_alternatives_with_every_order_that_no_design_could_hold(tmp_path, run_cli):
    """Ten alternatives with 'arrangements: all' (10! orders) ran validate past a minute and gigabytes."""
    text = (PROTOCOLS / "thesis_mesh.yaml").read_text()
    text = replace(text, 'levels: ["0.5", "12", "23.5", "35", "46.5", "58"]',
                   'levels: ["0.5", "5", "12", "20", "23.5", "30", "35", "40", "46.5", "58"]')
    text = replace(text, "arrangements: latin_square", "arrangements: all")
    text = replace(text, "labels: [A, B, C, D, E, F]", "labels: [A, B, C, D, E, F, G, H, I, J]")
    start = time.perf_counter()
    message = refused(run_cli, tmp_path, text, "validate")
    assert time.perf_counter() - start < 2.0
    assert "the design makes 36,288,000 test clips (PARAMETER 10 × 3,628,800 screen orders of STRENGTH)" in message
    assert "at most 100,000" in message and "latin_square" in message


def test_participants_beyond_the_trial_limit(tmp_path, run_cli):
    message = refused(run_cli, tmp_path, replace(EXP1, "participants: 16 ", "participants: 20000 "), "validate")
    assert "participants (line 9): 20,000 participants × 64 test trials each make 1,280,000 rows" in message
    out = tmp_path / "out"
    code, _, stderr = run_cli("design", PROTOCOLS / "exp1_shape_motion.yaml", "--participants", "1000000", "--out", out)
    assert code == 2 and "--participants: 1,000,000 participants × 64 test trials" in " ".join(stderr.split())
    assert not out.exists()


@pytest.mark.parametrize("old, new", [("name: exp1_shape_motion", "name: \"exp1_shape_motion\\n\""),
                                      ("- name: GAIT", "- name: \"GAIT\\n\"")])
def test_a_trailing_newline_is_not_a_safe_name(tmp_path, run_cli, old, new):
    """Names go into file names, ids and survey syntax; a regex anchored with "$" let "walk\\n" through."""
    assert old in EXP1
    message = refused(run_cli, tmp_path, replace(EXP1, old, new), "validate")
    assert "line" in message
