"""``shapemotion schema``: the protocol's JSON Schema, or its field reference as Markdown."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "schema", help="print the protocol's JSON Schema (for editors) or its field reference",
        description="Print the JSON Schema of protocol files, generated from the models validate uses: "
                    "protocols/protocol.schema.json holds it, and a protocol whose first line is "
                    "'# yaml-language-server: $schema=protocol.schema.json' is completed and checked by "
                    "editors using yaml-language-server. --markdown prints the field reference instead.",
        epilog="example: shapemotion schema > protocol.schema.json")
    p.add_argument("--markdown", action="store_true", help="the field reference as Markdown tables instead")
    p.set_defaults(func=run_schema)


def run_schema(args: argparse.Namespace) -> int:
    from stimuli.protocol_schema import field_reference_markdown, schema_text

    print(field_reference_markdown() if args.markdown else schema_text(), end="")
    return 0
