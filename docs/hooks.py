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


def _subcommands(parser: argparse.ArgumentParser) -> list[tuple[str, argparse.ArgumentParser]]:
    """The parser's sub-commands in the order its ``--help`` lists them."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return list(action.choices.items())
    return []


def cli_reference_markdown() -> str:
    """One section per command (and per sub-command) holding its ``--help`` text."""
    from stimuli.cli import build_parser

    os.environ["COLUMNS"] = "100"   # argparse wraps at the terminal width; fix it so builds are reproducible
    parser = build_parser()
    parts = ["```text", parser.format_help().rstrip(), "```"]
    for name, sub in _subcommands(parser):
        parts += [f"## `shapemotion {name}`", "", "```text", sub.format_help().rstrip(), "```", ""]
        for child, subsub in _subcommands(sub):
            parts += [f"### `shapemotion {name} {child}`", "", "```text", subsub.format_help().rstrip(), "```", ""]
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
