"""Every YAML file a user gives is read with the same limits (issue 26, item 3): protocols (see
test_protocol_integrity.py), generative-model files and joint-mapping files."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
import yaml

from analysis.errors import AnalysisError
from analysis.io_design import load_design
from analysis.io_yaml import MAX_NESTING, MAX_NODES, load_bounded, yaml_problem
from analysis.model_spec import load_model
from stimuli.errors import StimuliError
from stimuli.motion.skeleton import load_mapping

MINI_LIKERT = Path(__file__).parent / "data" / "responses" / "mini_likert"
# nine anchors, each listing the one before nine times: 9**9 strings from ten short lines
LAUGHS = "a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n" + "".join(
    f"{c}: &{c} [*{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}]\n" for p, c in zip("abcdefgh", "bcdefghi"))


def refusal(text: str) -> str:
    with pytest.raises(yaml.YAMLError) as info:
        load_bounded(text)
    return yaml_problem(info.value, text)


def test_alias_bomb_is_refused_at_once():
    start = time.perf_counter()
    assert "aliases expand this value" in refusal(LAUGHS)
    assert time.perf_counter() - start < 1.0


def test_self_reference_nesting_nodes_and_duplicate_keys():
    assert "refers to itself" in refusal("a: &a [*a]\n")
    assert f"deeper than {MAX_NESTING}" in refusal("[" * (MAX_NESTING + 5) + "]" * (MAX_NESTING + 5))
    assert f"more than {MAX_NODES:,}" in refusal("[" + ", ".join("x" * 1 for _ in range(MAX_NODES + 10)) + "]")
    assert refusal("a: 1\nb: 2\na: 3\n") == " line 3, column 1: key 'a' appears twice in one mapping (first on line 1)"


def test_long_values_are_named_by_size_not_echoed():
    message = refusal("a: *" + "x" * 100_000 + "\n")
    assert len(message) < 400


def test_model_file_alias_bomb_exits_with_the_file_and_line(tmp_path):
    path = tmp_path / "bomb.yaml"
    path.write_text(LAUGHS)
    start = time.perf_counter()
    with pytest.raises(AnalysisError, match=r"bomb\.yaml: line \d+, column \d+: aliases expand"):
        load_model(path, load_design(MINI_LIKERT))
    assert time.perf_counter() - start < 1.0


def test_mapping_file_alias_bomb_and_duplicate_role(tmp_path):
    names = ["root", "thigh_l", "shin_l", "foot_l", "thigh_r", "shin_r", "foot_r"]
    path = tmp_path / "map.yaml"
    path.write_text(LAUGHS)
    with pytest.raises(StimuliError, match=r"map\.yaml: line \d+, column \d+: aliases expand"):
        load_mapping(path, names)
    path.write_text("pelvis: root\nl_knee: shin_l\nl_knee: thigh_l\n")
    with pytest.raises(StimuliError, match=r"map\.yaml: line 3, column 1: key 'l_knee' appears twice"):
        load_mapping(path, names)
