"""``shapemotion init``: the folder of a new study (:mod:`stimuli.scaffold`)."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "init", help="start a new study: a commented protocol, its schema and a captures/ folder",
        description="Create the folder NAME with NAME/protocol.yaml (a commented, small Exp. 1-like design that "
                    "validate accepts as written; with --from, a copy of another protocol, comments kept), "
                    "NAME/protocol.schema.json (editors check the protocol as it is typed) and "
                    "NAME/captures/README.md (what motion captures to put there). The protocol's name is NAME.",
        epilog="example: shapemotion init mystudy && shapemotion validate mystudy/protocol.yaml")
    p.add_argument("name", type=Path, metavar="NAME", help="the study's folder; its last part is the protocol's name")
    p.add_argument("--from", dest="source", metavar="PROTOCOL", default=None,
                   help="copy this protocol instead of the template: a bundled one's name (exp1_shape_motion, "
                        "exp1_own_captures, …) or a protocol file; capture files it names are copied along")
    p.add_argument("--force", action="store_true",
                   help="write into NAME even if it holds files (files of the same names are replaced)")
    p.set_defaults(func=run_init)


def run_init(args: argparse.Namespace) -> int:
    from stimuli.scaffold import init_study

    for path in init_study(args.name, args.source, args.force):
        print(path)
    print(f"next: edit {args.name / 'protocol.yaml'}, then shapemotion validate {args.name / 'protocol.yaml'}")
    return 0
