"""``shapemotion init``: a new study's folder that ``validate`` accepts as written, or nothing at all."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
import yaml

from stimuli.protocol import load_protocol
from stimuli.protocol_schema import SCHEMA_LINE, schema_text

PROTOCOLS = Path(__file__).resolve().parents[1] / "protocols"


def leftovers(folder: Path) -> list[str]:
    """What init left in ``folder`` besides what the test made (a staging folder would show here)."""
    return sorted(p.name for p in folder.iterdir())


def test_the_template_validates_as_written(tmp_path, run_cli):
    code, out, _ = run_cli("init", tmp_path / "mystudy")
    assert code == 0 and "next: edit" in out
    study = tmp_path / "mystudy"
    assert leftovers(tmp_path) == ["mystudy"]
    assert sorted(str(p.relative_to(study)) for p in study.rglob("*")) == [
        "captures", "captures/README.md", "protocol.schema.json", "protocol.yaml"]
    text = (study / "protocol.yaml").read_text()
    assert text.splitlines()[0] == SCHEMA_LINE and text.count("\n#") > 10   # commented for the lab that edits it
    assert (study / "protocol.schema.json").read_text() == schema_text()
    jsonschema.validate(yaml.safe_load(text), json.loads(schema_text()))
    code, out, err = run_cli("validate", study / "protocol.yaml")
    assert code == 0 and "valid protocol 'mystudy'" in out and "warning" not in out, err
    assert "motions:" in (study / "captures" / "README.md").read_text()


def test_from_a_bundled_protocol_keeps_its_comments_and_design(tmp_path, run_cli):
    code, _, _ = run_cli("init", tmp_path / "replication", "--from", "exp1_shape_motion")
    assert code == 0
    original = (PROTOCOLS / "exp1_shape_motion.yaml").read_text()
    copy = (tmp_path / "replication" / "protocol.yaml").read_text()
    assert copy == original.replace("name: exp1_shape_motion\n", "name: replication\n")
    first = load_protocol(PROTOCOLS / "exp1_shape_motion.yaml")
    second = load_protocol(tmp_path / "replication" / "protocol.yaml")
    assert second.name == "replication"
    assert second.to_json_dict() | {"name": first.name} == first.to_json_dict()


def test_from_a_protocol_with_captures_copies_them_and_their_terms(tmp_path, run_cli):
    code, _, _ = run_cli("init", tmp_path / "own", "--from", "exp1_own_captures")
    assert code == 0
    captures = tmp_path / "own" / "captures"
    for name in ("cmu_35_01_walk.bvh", "cmu_35_17_run.bvh", "cmu_02_01_walk_mb2names_120fps.bvh"):
        assert (captures / name).read_bytes() == (PROTOCOLS / "captures" / name).read_bytes()
    assert (captures / "SOURCES.md").read_text() == (PROTOCOLS / "captures" / "README.md").read_text()
    code, out, _ = run_cli("validate", tmp_path / "own" / "protocol.yaml")
    assert code == 0 and out.count("  capture ") == 3


def test_from_a_file_gets_the_schema_line(tmp_path, run_cli):
    lines = (PROTOCOLS / "exp2_com_vs_average.yaml").read_text().splitlines(keepends=True)
    (tmp_path / "mine.yaml").write_text("".join(lines[1:]))   # a protocol written before the schema line existed
    code, _, _ = run_cli("init", tmp_path / "exp2b", "--from", tmp_path / "mine.yaml")
    text = (tmp_path / "exp2b" / "protocol.yaml").read_text()
    assert code == 0 and text.startswith(SCHEMA_LINE + "\n# Experiment 2") and "\nname: exp2b\n" in text


def test_an_existing_folder_is_refused_unless_empty_or_forced(tmp_path, run_cli):
    study = tmp_path / "study"
    study.mkdir()
    assert run_cli("init", study)[0] == 0   # an empty folder is used
    (study / "protocol.yaml").write_text("mine")
    (study / "notes.txt").write_text("keep me")
    code, _, err = run_cli("init", study)
    assert code == 2 and "exists and is not empty" in " ".join(err.split()) and "--force" in err
    assert (study / "protocol.yaml").read_text() == "mine"
    code, _, _ = run_cli("init", study, "--force")
    assert code == 0 and (study / "notes.txt").read_text() == "keep me"
    assert (study / "protocol.yaml").read_text().startswith(SCHEMA_LINE)
    assert leftovers(tmp_path) == ["study"]


@pytest.mark.parametrize("name, extra, says", [
    ("my study", [], "'my study' is not a usable study name"),
    ("x" * 41, [], "longer than 40 characters"),
    ("study", ["--from", "exp3_nothing"], "is neither a bundled protocol"),
    ("study", ["--from", "BAD"], "init: cannot copy"),
])
def test_refusals_write_nothing(tmp_path, run_cli, name, extra, says):
    (tmp_path / "BAD").write_text("name: bad\nseed: 1\n")   # missing required fields
    extra = [str(tmp_path / e) if e == "BAD" else e for e in extra]
    code, _, err = run_cli("init", tmp_path / name, *extra)
    assert code == 2 and says in " ".join(err.split()) and "Traceback" not in err
    assert leftovers(tmp_path) == ["BAD"]


def test_a_file_in_the_way_is_refused(tmp_path, run_cli):
    (tmp_path / "study").write_text("")
    code, _, err = run_cli("init", tmp_path / "study")
    assert code == 2 and "is not a folder" in err
