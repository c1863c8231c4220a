"""The protocol's JSON Schema (``shapemotion schema``): committed, complete, and in agreement with the
pydantic models on what the bundled protocols hold and on misspelt fields."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
import yaml

from stimuli.errors import StimuliError
from stimuli.protocol import parse_protocol
from stimuli.protocol_schema import SCHEMA_LINE, field_reference_markdown, protocol_schema, schema_text

PROTOCOLS = Path(__file__).resolve().parents[1] / "protocols"
BUNDLED = sorted(PROTOCOLS.glob("*.yaml"))
COMMITTED = PROTOCOLS / "protocol.schema.json"
EXP1 = (PROTOCOLS / "exp1_shape_motion.yaml").read_text()


def committed_validator() -> jsonschema.Draft7Validator:
    schema = json.loads(COMMITTED.read_text())
    assert jsonschema.validators.validator_for(schema) is jsonschema.Draft7Validator   # what editors implement
    jsonschema.Draft7Validator.check_schema(schema)
    return jsonschema.Draft7Validator(schema)


def test_committed_schema_is_the_generated_one(run_cli):
    code, out, _ = run_cli("schema")
    assert code == 0 and out == schema_text()
    assert COMMITTED.read_text() == out, (
        "protocols/protocol.schema.json is out of date with stimuli/protocol.py; regenerate it with "
        "`shapemotion schema > protocols/protocol.schema.json`")


@pytest.mark.parametrize("path", BUNDLED, ids=lambda p: p.stem)
def test_bundled_protocols_validate_against_the_committed_schema(path):
    text = path.read_text()
    assert text.splitlines()[0] == SCHEMA_LINE   # editors find the schema next to the protocol
    errors = list(committed_validator().iter_errors(yaml.safe_load(text)))
    assert not errors, [f"{'.'.join(map(str, e.path))}: {e.message}" for e in errors]


@pytest.mark.parametrize("old, new, where", [
    ("title:", "titel:", []),
    ("cycles:", "cyclez:", ["clip"]),
    ("group:", "grup:", ["actors", 0]),
    ("abbreviations: {walk", "abbreviation: {walk", ["factors", 1]),
])
def test_a_misspelt_field_is_refused_by_the_model_and_the_schema(old, new, where):
    assert old in EXP1
    text = EXP1.replace(old, new, 1)
    with pytest.raises(StimuliError, match="unknown field"):
        parse_protocol(text)
    errors = list(committed_validator().iter_errors(yaml.safe_load(text)))
    assert [(list(e.path), e.validator) for e in errors] == [(where, "additionalProperties")]
    assert f"'{new.split(':')[0]}' was unexpected" in errors[0].message


@pytest.mark.parametrize("old, new", [
    ("levels: [F, M]", "levels: [F, M, F]"),          # the model's rule: no repeats (the schema: items alone)
    ("duration_s: 4 ", "duration_s: 1 "),             # a rule across fields (shorter than a gait cycle)
])
def test_rules_across_fields_are_validates_not_the_schemas(old, new):
    """The schema checks each field alone; ``validate`` also checks the design as a whole."""
    text = EXP1.replace(old, new, 1)
    assert text != EXP1
    with pytest.raises(StimuliError):
        parse_protocol(text)
    assert not list(committed_validator().iter_errors(yaml.safe_load(text)))


def test_wrong_types_and_ranges_are_refused_by_both():
    for old, new in [("bmi: 28.1", "bmi: 281"), ("cycles: 2", "cycles: true"), ("layout: treadmill", "layout: tv"),
                     ("seed: 2023", "seed: -1"), ("levels: [F, M]", "levels: [F]")]:
        text = EXP1.replace(old, new, 1)
        with pytest.raises(StimuliError):
            parse_protocol(text)
        assert list(committed_validator().iter_errors(yaml.safe_load(text))), (old, new)


def test_shorthands_the_model_accepts_are_in_the_schema():
    """A capture given as its file name alone and levels YAML reads as numbers pass both."""
    text = EXP1.replace("bmi: 22.7, group: lower}", "bmi: 22.7, group: lower, motions: {walk: captures/w.bvh}}", 1)
    data = yaml.safe_load(text)
    data["factors"].append({"name": "DOSE", "role": "between", "levels": [1, 2.5], "maps_to": "none"})
    data["participants"] = 16
    parse_protocol(yaml.safe_dump(data, sort_keys=False))
    assert not list(committed_validator().iter_errors(data))


def walk_properties(schema: dict):
    yield "Protocol", schema
    yield from schema["definitions"].items()


def test_every_field_has_a_description():
    schema = protocol_schema()
    missing = [f"{model}.{field}" for model, node in walk_properties(schema)
               for field, spec in node["properties"].items() if not spec.get("description", "").strip()]
    assert not missing
    assert all(node.get("additionalProperties") is False for _, node in walk_properties(schema))
    assert not [text for text in descriptions(schema) if "\n" in text.replace("\n\n", "")]   # a line a paragraph


def descriptions(node):
    if isinstance(node, dict):
        yield from ([node["description"]] if isinstance(node.get("description"), str) else [])
        for value in node.values():
            yield from descriptions(value)
    elif isinstance(node, list):
        for item in node:
            yield from descriptions(item)


def test_markdown_reference_lists_every_field_with_its_description(run_cli):
    code, out, _ = run_cli("schema", "--markdown")
    assert code == 0 and out == field_reference_markdown()
    for model, node in walk_properties(protocol_schema()):
        for field, spec in node["properties"].items():
            row = next((line for line in out.splitlines() if line.startswith(f"| `{field}` |")
                        and spec["description"].replace("|", "\\|") in line), None)
            assert row, f"{model}.{field} has no row in the field reference"
    assert "## `clip.camera` (Camera)" in out and "## `actors[].motions.<name>` (Capture)" in out
