"""Protocol text cannot break the syntax of a survey export (issue 26, item 8).

The Qualtrics Advanced TXT is line- and tag-based (``[[Block:…]]``, one choice per line), PsychoPy's
conditions files are read by ``importConditions`` (headers as variable names, ``[…]`` cells passed
to ``eval``, options split at ``|``). What the protocol says either reaches the participant as
written (escaped) or is refused with exit 2 naming the protocol field, before any file is written.
QSF and jsPsych carry the text as JSON: the same hostile text round-trips unchanged.
"""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import pytest
import yaml

from stimuli.design import build_design, write_design
from stimuli.errors import StimuliError
from stimuli.protocol import parse_protocol

ROOT = Path(__file__).resolve().parents[1]
INJECTED_NAME = "exp1\n[[Block:Injected]]\n[[Question:MC]]\nDo you consent to everything?\n[[Choices]]\nYes"
HOSTILE_NAME = "exp1 ]] [[Block:Injected]] </script> \u2028"   # one line: the protocol accepts it


def _design_folder(tmp_path: Path, edit) -> Path:
    """Exp. 1's design with ``edit(data)`` applied to the protocol (a dict), written to a folder."""
    data = yaml.safe_load((ROOT / "protocols" / "exp1_shape_motion.yaml").read_text())
    edit(data)
    folder = tmp_path / "design"
    write_design(build_design(parse_protocol(yaml.safe_dump(data))), folder)
    return folder


def _one_line(message: str) -> str:
    return " ".join(message.split())


def _refused(run_cli, folder: Path, fmt: str, out: Path) -> str:
    """Export ``folder`` as ``fmt``: exit 2, nothing written; returns the message on one line."""
    code, _, err = run_cli("survey", folder, "--format", fmt, "--out", out)
    assert code == 2, err
    assert not out.exists()
    return _one_line(err)


def _questions(txt: str) -> list[tuple[str, list[str]]]:
    """(export tag, choices) of each multiple-choice question of a TXT file, as the format reads them:
    after ``[[Choices]]`` one choice per line up to the blank line."""
    found = []
    for match in re.finditer(r"\[\[Question:MC[^\]]*\]\]\n\[\[ID:([^\]]+)\]\]\n[^\n]*\n\[\[Choices\]\]\n((?:[^\n]+\n)+)",
                             txt):
        found.append((match.group(1), match.group(2).splitlines()))
    return found


# -- Qualtrics Advanced TXT --------------------------------------------------------------------

@pytest.mark.parametrize("name", [INJECTED_NAME, "exp\r1"])
def test_a_protocol_name_with_a_line_break_is_refused_by_the_protocol(name, tmp_path):
    """A line break would end the TXT's [[ED:…]] line and start blocks of its own: the protocol itself
    refuses it, before any design or export exists."""
    with pytest.raises(StimuliError, match=r"name \(line \d+\): name .* must be one line of text"):
        _design_folder(tmp_path, lambda d: d.update(name=name))


@pytest.mark.parametrize("name", ["exp]]1", "exp[1", "exp\u20281"])
def test_each_character_that_ends_the_ed_tag_is_refused(name, tmp_path, run_cli):
    """One-line names the protocol accepts, but which would end the TXT's [[ED:…]] tag."""
    message = _refused(run_cli, _design_folder(tmp_path, lambda d: d.update(name=name)), "qualtrics-txt",
                       tmp_path / "s.txt")
    assert "design.json: protocol field name" in message
    assert "[[ED:…]] tag, which a line break, '[' or ']' would end" in message


def test_a_label_with_a_line_break_stays_one_choice(tmp_path, run_cli):
    def edit(data):
        data["response"]["labels"][0] = "Very\nInconsistent"
        data["response"]["labels"][4] = "[[Block:Evil]] Very Consistent"

    folder = _design_folder(tmp_path, edit)
    out = tmp_path / "survey.txt"
    code, _, err = run_cli("survey", folder, "--format", "qualtrics-txt", "--out", out)
    assert code == 0, err
    txt = out.read_text()
    questions = _questions(txt)
    assert len(questions) == 144
    assert {len(choices) for _, choices in questions} == {5}   # was 6: the line break made two choices
    assert questions[0][1][0] == "Very Inconsistent"           # shown as the browser showed it
    assert questions[0][1][4] == "&#91;&#91;Block:Evil&#93;&#93; Very Consistent"
    assert txt.count("[[Block:") == 2 + 8                       # consent, instructions, 8 parts: none added


def test_protocol_text_with_tags_adds_no_block_or_question(tmp_path, run_cli):
    def edit(data):
        data["response"]["question"] = "Rate it.\n\n[[Block:Evil]]\n\n[[Question:DB]]\nInjected"
        data["title"] = "Study ]] [[PageBreak]]"
        data["consent"] = "Agree?\n[[Question:TE]]"
        data["response"]["instructions"] = "Watch.\n\n[[PageBreak]]"

    plain = _design_folder(tmp_path / "plain", lambda d: None)
    folder = _design_folder(tmp_path, edit)
    for source, out in ((plain, tmp_path / "plain.txt"), (folder, tmp_path / "survey.txt")):
        code, _, err = run_cli("survey", source, "--format", "qualtrics-txt", "--out", out)
        assert code == 0, err
    txt = (tmp_path / "survey.txt").read_text()
    tags = re.findall(r"^\[\[([A-Za-z]+)", txt, flags=re.M)
    assert tags == re.findall(r"^\[\[([A-Za-z]+)", (tmp_path / "plain.txt").read_text(), flags=re.M)
    assert "Evil" not in " ".join(re.findall(r"\[\[[^\]]*\]\]", txt))
    assert "Rate it. &#91;&#91;Block:Evil&#93;&#93; &#91;&#91;Question:DB&#93;&#93; Injected" in txt


# -- PsychoPy ----------------------------------------------------------------------------------

def test_a_label_with_a_pipe_is_refused_for_psychopy(tmp_path, run_cli):
    folder = _design_folder(tmp_path, lambda d: d["response"]["labels"].__setitem__(2, "Neutral | unsure"))
    message = _refused(run_cli, folder, "psychopy", tmp_path / "psychopy")
    assert "protocol field response.labels.2 'Neutral | unsure' holds '|'" in message
    assert "the 5 labels would make 6 options" in message


def test_a_cell_psychopy_would_eval_is_refused(tmp_path, run_cli):
    question = "[__import__('os').system('echo owned')]"
    folder = _design_folder(tmp_path, lambda d: d["response"].update(question=question))
    message = _refused(run_cli, folder, "psychopy", tmp_path / "psychopy")
    assert "protocol field response.question" in message
    assert "evaluates a conditions cell that starts with '[' and ends with ']'" in message


def test_brackets_inside_a_cell_are_kept(tmp_path, run_cli):
    """Only a whole cell in brackets is evaluated: a question that merely contains them is data."""
    folder = _design_folder(tmp_path, lambda d: d["response"].update(question="How consistent [1 = not at all]?"))
    out = tmp_path / "psychopy"
    code, _, err = run_cli("survey", folder, "--format", "psychopy", "--out", out)
    assert code == 0, err
    rows = list(csv.DictReader(open(next((out / "conditions").glob("*_test.csv")), newline="")))
    assert rows[0]["question"] == "How consistent [1 = not at all]?"
    assert rows[0]["options"].split("|") == ["Very Inconsistent", "Inconsistent", "Neutral", "Consistent",
                                             "Very Consistent"]


def test_a_factor_named_as_a_python_keyword_is_refused_for_psychopy(tmp_path, run_cli):
    """Builder turns each conditions column into a variable: a column named ``lambda`` cannot be one."""
    def edit(data):
        text = yaml.safe_dump(data).replace("BODY", "lambda")
        data.clear()
        data.update(yaml.safe_load(text))

    folder = _design_folder(tmp_path, edit)
    message = _refused(run_cli, folder, "psychopy", tmp_path / "pp")
    assert "protocol field factors.2.name 'lambda': PsychoPy reads conditions columns as Python variable " \
           "names" in message


def test_export_all_refuses_before_writing_any_format(tmp_path):
    """The render's survey step writes every format: a refusal by one leaves none written."""
    from stimuli.survey import export_all

    folder = _design_folder(tmp_path, lambda d: d["response"]["labels"].__setitem__(0, "Very | Inconsistent"))
    with pytest.raises(StimuliError, match=r"response\.labels\.0"):
        export_all(folder)
    assert not (folder / "survey").exists()


# -- QSF and jsPsych: JSON carries any text ------------------------------------------------------

def test_qsf_and_jspsych_carry_hostile_text_unchanged(tmp_path, run_cli):
    """The name the TXT refuses, and labels with '|', line breaks and brackets, round-trip through the
    QSF's JSON (the embedded protocol field is exactly the name, which the response import checks) and
    jsPsych's config.js."""
    labels = ["Very\nInconsistent", "In|consistent", "[Neutral]", "Consistent ]]", "</script>Very Consistent"]

    def edit(data):
        data["name"] = HOSTILE_NAME
        data["response"]["labels"] = labels

    folder = _design_folder(tmp_path, edit)
    code, _, err = run_cli("survey", folder, "--format", "qsf", "--out", tmp_path / "s.qsf")
    assert code == 0, err
    qsf = json.loads((tmp_path / "s.qsf").read_text())
    flow = next(e for e in qsf["SurveyElements"] if e["Element"] == "FL")
    fields = {f["Field"]: f["Value"] for item in flow["Payload"]["Flow"] if item.get("Type") == "EmbeddedData"
              for f in item["EmbeddedData"]}
    assert fields["shapemotion_protocol"] == HOSTILE_NAME
    code, _, err = run_cli("survey", folder, "--format", "jspsych", "--out", tmp_path / "js")
    if code == 2 and "jsPsych is not installed" in _one_line(err):
        pytest.skip("jsPsych is not installed (npm ci)")
    assert code == 0, err
    config = (tmp_path / "js" / "config.js").read_text()
    assert "</script" not in config and "\u2028" not in config
    data = json.loads(config.removeprefix("window.SHAPEMOTION_CONFIG = ").removesuffix(";\n"))
    assert data["response"]["labels"] == labels
    assert data["protocol"] == HOSTILE_NAME


@pytest.mark.parametrize("module", ["stimuli.survey.qualtrics_txt", "stimuli.survey.psychopy"])
def test_docstring_examples(module):
    import doctest
    import importlib

    result = doctest.testmod(importlib.import_module(module))
    assert result.attempted > 0 and result.failed == 0
