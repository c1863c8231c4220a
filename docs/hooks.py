"""MkDocs hook: writes the generated parts of the reference from the code at build time.

A page holds a marker comment and the hook replaces it, so the published reference is always the
one of the code it was built from:

- ``<!-- generated: cli -->`` — every command's ``--help``, from ``stimuli.cli.build_parser``;
- ``<!-- generated: protocol-fields -->`` — the protocol field reference, from the pydantic models.
"""

from __future__ import annotations

import argparse
import os

CLI_MARKER = "<!-- generated: cli -->"
FIELDS_MARKER = "<!-- generated: protocol-fields -->"


def _subparsers(parser: argparse.ArgumentParser) -> argparse._SubParsersAction | None:
    return next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)


def _subcommands(parser: argparse.ArgumentParser) -> list[tuple[str, argparse.ArgumentParser]]:
    """The parser's sub-commands in the order they were added."""
    action = _subparsers(parser)
    return list(action.choices.items()) if action else []


def _help_block(parser: argparse.ArgumentParser) -> list[str]:
    return ["```text", parser.format_help().rstrip(), "```", ""]


def cli_reference_markdown() -> str:
    """``shapemotion --help`` (the commands by stage of the data flow, each with an example), then one
    section per stage and command (and sub-command) with the command's own ``--help`` text."""
    from stimuli.cli import STAGES, build_parser

    os.environ["COLUMNS"] = "88"   # argparse wraps at the terminal width; fix it so builds are reproducible
    parser = build_parser()
    commands = dict(_subcommands(parser))
    placed = {name for examples in STAGES.values() for name in examples}
    stages = {**STAGES, "other commands": {name: "" for name in commands if name not in placed}}
    parts = ["## `shapemotion --help`", "", *_help_block(parser)]
    for stage, examples in stages.items():
        if examples:
            parts += [f"## {stage[0].upper()}{stage[1:]}", ""]
        for name, example in examples.items():
            parts += [f"### `shapemotion {name}`", ""]
            parts += [f"Example: `{example}`", ""] if example else []
            parts += _help_block(commands[name])
            for child, sub in _subcommands(commands[name]):
                parts += [f"#### `shapemotion {name} {child}`", "", *_help_block(sub)]
    return "\n".join(parts)


def protocol_fields_markdown() -> str:
    """The protocol field reference generated from the pydantic models (shapemotion's schema module)."""
    from stimuli.protocol_schema import field_reference_markdown

    return field_reference_markdown(heading_level=2)


def on_page_markdown(markdown: str, page, config, files) -> str:  # noqa: ARG001 (MkDocs' hook signature)
    if CLI_MARKER in markdown:
        markdown = markdown.replace(CLI_MARKER, cli_reference_markdown())
    if FIELDS_MARKER in markdown:
        markdown = markdown.replace(FIELDS_MARKER, protocol_fields_markdown())
    return markdown
