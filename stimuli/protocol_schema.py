"""The protocol's JSON Schema and its field reference, both generated from the pydantic models of
:mod:`stimuli.protocol`, so that editors, the docs and ``validate`` never disagree.

The schema is what ``shapemotion schema`` prints and ``protocols/protocol.schema.json`` holds; a
protocol's first line ``# yaml-language-server: $schema=protocol.schema.json`` lets editors that
use yaml-language-server (VS Code's YAML extension, and others) complete and check fields as they
are typed. The schema checks each field alone; rules across fields (a level that names no actor, a
clip shorter than a gait cycle, …) are ``validate``'s.

>>> schema = protocol_schema()
>>> schema["additionalProperties"], "description" in schema["properties"]["seed"]
(False, True)
>>> field_reference_markdown().splitlines()[0]
'# Protocol field reference'
"""

from __future__ import annotations

import json
import re

from stimuli.protocol import Protocol

# Draft-07: what editors' YAML support (yaml-language-server, on vscode-json-languageservice) implements;
# the schema uses nothing newer, and its parts sit under draft-07's "definitions".
SCHEMA_DIALECT = "http://json-schema.org/draft-07/schema#"
SCHEMA_FILE = "protocol.schema.json"   # the name protocols refer to, next to them
SCHEMA_LINE = f"# yaml-language-server: $schema={SCHEMA_FILE}"


def protocol_schema() -> dict:
    """The protocol's JSON Schema (draft-07) with one-line descriptions.

    >>> sorted(protocol_schema()["definitions"])[:3]
    ['Actor', 'Alternatives', 'Analysis']
    """
    schema = Protocol.model_json_schema(ref_template="#/definitions/{model}")
    schema["definitions"] = schema.pop("$defs")
    _plain_descriptions(schema)
    for model in [schema, *schema["definitions"].values()]:
        for spec in model["properties"].values():
            spec.pop("title", None)   # pydantic's "Height M" from height_m: the field's name says it better
    return {"$schema": SCHEMA_DIALECT, "title": "shapemotion protocol",
            **{k: v for k, v in schema.items() if k != "title"}}


def schema_text() -> str:
    """The schema as ``shapemotion schema`` prints it and ``protocols/protocol.schema.json`` holds it.

    >>> schema_text().startswith('{\\n  "$schema"')
    True
    """
    return json.dumps(protocol_schema(), indent=2, ensure_ascii=False) + "\n"


def _plain_descriptions(node) -> None:
    """Docstrings as editors show them: paragraphs on one line each, ``code`` as `code`, no Sphinx roles."""
    if isinstance(node, dict):
        for key, value in node.items():
            if key == "description" and isinstance(value, str):
                node[key] = plain_text(value)
            else:
                _plain_descriptions(value)
    elif isinstance(node, list):
        for item in node:
            _plain_descriptions(item)


def plain_text(docstring: str) -> str:
    """A docstring as plain Markdown: lines of a paragraph joined, RST literals and roles simplified,
    examples (``>>>``) left out.

    >>> plain_text("A ``by`` factor\\nmakes blocks (:mod:`stimuli.design`).\\n\\n>>> 1 + 1\\n2")
    'A `by` factor makes blocks (`stimuli.design`).'
    """
    paragraphs = [p for p in re.split(r"\n\s*\n", docstring.strip()) if not p.lstrip().startswith(">>>")]
    text = "\n\n".join(" ".join(p.split()) for p in paragraphs)
    text = re.sub(r":\w+:`~?([^`]+)`", r"`\1`", text)
    return text.replace("``", "`")


# -- the markdown field reference -----------------------------------------------------------------

def field_reference_markdown(heading_level: int = 1) -> str:
    """The protocol field reference as Markdown: one table per part of the protocol (top level first,
    then each part in the order it is first met), from the same schema as :func:`protocol_schema`.
    ``shapemotion schema --markdown`` prints it; the docs build calls it.

    >>> text = field_reference_markdown()
    >>> "| `height_m` | number, 1.2–2.3 | required | standing height in metres |" in text
    True
    """
    schema = protocol_schema()
    defs = schema["definitions"]
    hashes = "#" * heading_level
    lines = [f"{hashes} Protocol field reference", "",
             "Generated from the protocol's models (`shapemotion schema --markdown`); the JSON Schema "
             "(`shapemotion schema`, `protocols/protocol.schema.json`) holds the same descriptions. "
             "`validate` also checks the rules across fields.", ""]
    done, queue = set(), [("Protocol", "", schema)]
    while queue:
        name, where, model = queue.pop(0)
        if name in done:
            continue
        done.add(name)
        lines += _model_table(name, where, model, hashes + "#")
        for field, spec in model["properties"].items():
            path = f"{where}.{field}" if where else field
            queue += [(ref, path + _nesting(spec), defs[ref]) for ref in _refs(spec) if ref not in done]
    return "\n".join(lines).rstrip() + "\n"


def _nesting(spec: dict) -> str:
    """How a field holds the part it refers to: ``[]`` for a list of them, ``.<name>`` for a mapping."""
    for option in spec.get("anyOf", [spec]):
        if option.get("type") == "array":
            return "[]"
        if option.get("type") == "object" and "additionalProperties" in option:
            return ".<name>"
    return ""


def _model_table(name: str, where: str, model: dict, hashes: str) -> list[str]:
    title = "The top level" if name == "Protocol" else f"`{where}` ({name})"
    lines = [f"{hashes} {title}", ""]
    if name != "Protocol" and model.get("description"):
        lines += [model["description"], ""]
    lines += ["| field | type | default | description |", "|---|---|---|---|"]
    required = set(model.get("required", []))
    for field, spec in model["properties"].items():
        default = "required" if field in required else _default_text(spec.get("default"))
        lines.append(f"| `{field}` | {_cell(type_text(spec))} | {_cell(default)} | "
                     f"{_cell(spec.get('description', ''))} |")
    return lines + [""]


def type_text(spec: dict) -> str:
    """A field's type in words, with its bounds: ``number, 1.2–2.3``, ``list of Factor``, …

    >>> type_text({"anyOf": [{"type": "integer", "minimum": 1}, {"type": "null"}]})
    'integer, ≥ 1 or null'
    >>> type_text({"type": "object", "additionalProperties": {"$ref": "#/definitions/GaitSpec"}})
    'mapping of name → GaitSpec'
    """
    if "$ref" in spec:
        return spec["$ref"].rsplit("/", 1)[-1]
    if "anyOf" in spec:
        return " or ".join(type_text(s) for s in spec["anyOf"])
    if "enum" in spec:
        return ", ".join(f"`{v}`" for v in spec["enum"])
    if "const" in spec:
        return f"`{spec['const']}`"
    kind = spec.get("type", "any")
    kind = " or ".join(kind) if isinstance(kind, list) else kind
    if kind == "array":
        return f"list of {type_text(spec.get('items', {}))}" + _count_text(spec, "Items")
    if kind == "object":
        return f"mapping of name → {type_text(spec.get('additionalProperties', {}))}"
    return kind + _bounds_text(spec)


def _bounds_text(spec: dict) -> str:
    low = spec.get("minimum", spec.get("exclusiveMinimum"))
    high = spec.get("maximum", spec.get("exclusiveMaximum"))
    if "minimum" in spec and "maximum" in spec:
        return f", {low:g}–{high:g}"
    parts = []
    if low is not None:
        parts.append(f"{'≥' if 'minimum' in spec else '>'} {low:g}")
    if high is not None:
        parts.append(f"{'≤' if 'maximum' in spec else '<'} {high:g}")
    if "pattern" in spec:
        parts.append(f"matching `{spec['pattern']}`")
    if "maxLength" in spec:
        parts.append(f"at most {spec['maxLength']} characters")
    return (", " + ", ".join(parts)) if parts else ""


def _count_text(spec: dict, what: str) -> str:
    low, high = spec.get(f"min{what}"), spec.get(f"max{what}")
    if low is not None and high is not None:
        return f" ({low}–{high})"
    return f" (at least {low})" if low is not None else ""


def _default_text(value) -> str:
    if value is None:
        return "none"
    if value in ({}, [], ""):
        return "empty"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, dict):   # a part's defaults: shown in the part's own table
        return "see below"
    return f"`{value}`"


def _cell(text: str) -> str:
    """Table cells keep one line; a '|' inside would end the cell."""
    return " ".join(text.split()).replace("|", "\\|")


def _refs(node) -> list[str]:
    """The ``definitions`` a schema node refers to, in the order they appear."""
    found: list[str] = []
    if isinstance(node, dict):
        for key, value in node.items():
            if key == "definitions":   # the top level's parts: followed through the refs instead
                continue
            if key == "$ref":
                found.append(value.rsplit("/", 1)[-1])
            else:
                found += [r for r in _refs(value) if r not in found]
    elif isinstance(node, list):
        for item in node:
            found += [r for r in _refs(item) if r not in found]
    return found
