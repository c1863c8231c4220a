"""``shapemotion validate``, ``design`` and ``demo``."""

from __future__ import annotations

import argparse
from pathlib import Path

from stimuli.fileio import output_path


def register(subparsers) -> None:
    p = subparsers.add_parser("validate", help="check a protocol file and summarise it",
                              description="Validate a protocol YAML file and print a summary of its design.")
    p.add_argument("protocol", type=Path)
    p.set_defaults(func=run_validate)

    p = subparsers.add_parser("design", help="expand a protocol into conditions, stimuli and trial lists",
                              description="Write conditions.csv, trials.csv and design.json for a protocol.")
    p.add_argument("protocol", type=Path)
    p.add_argument("--participants", type=int, default=None, help="number of participants (default: the protocol's)")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: the protocol's)")
    p.add_argument("--out", type=output_path, required=True, help="output folder")
    p.set_defaults(func=run_design)

    p = subparsers.add_parser("demo", help="run the whole chain on the bundled protocols",
                              description="Run every step of shapemotion on the bundled protocols.")
    p.add_argument("--out", type=output_path, default=Path("demo_output"))
    p.add_argument("--quick", action="store_true", help="smaller sizes everywhere (for tests)")
    p.set_defaults(func=run_demo)


def run_validate(args: argparse.Namespace) -> int:
    from stimuli.design import build_design
    from stimuli.motion.captures import check_captures
    from stimuli.protocol import check_capture_files, load_protocol
    from stimuli.render.settings import camera_distance_warnings
    from stimuli.render.timing import cadence_warnings, fits_summary

    protocol = load_protocol(args.protocol)
    check_capture_files(protocol, args.protocol)
    design = build_design(protocol)
    # Every actor's capture is imported and looped now (< 0.3 s each), not found wanting mid-render.
    captures = check_captures(protocol, args.protocol)
    print(f"{args.protocol}: valid protocol '{protocol.name}'")
    for f in protocol.factors:
        print(f"  {f.name:<10} {f.role:<12} {', '.join(f.levels)}")
    kinds = {k: sum(s.kind == k for s in design.stimuli) for k in ("test", "practice", "familiarization")}
    per_participant = sum(t.participant == 1 and t.kind == "test" for t in design.trials)
    print(f"  stimuli: {kinds['test']} test, {kinds['practice']} practice, {kinds['familiarization']} familiarization")
    nesting = (f" ({protocol.blocks.by[0]} blocks holding {' × '.join(protocol.blocks.by[1:])} sub-blocks)"
               if protocol.blocks.nested else "")
    print(f"  {protocol.participants} participants, {len(design.blocks)} block(s){nesting}, "
          f"{per_participant} test trials per participant")
    if protocol.gaits:
        print(f"  {fits_summary(protocol)}")
    for line in captures:
        print(f"  capture {line}")
    print_notes(cadence_warnings(protocol) + camera_distance_warnings(protocol, design), "warning")
    print_notes(design.notes, "note")
    return 0


def print_notes(lines: list[str], kind: str) -> None:
    """Warnings and notes: things the user should know that do not stop the command."""
    for line in lines:
        print(f"{kind}: {line}")


def run_design(args: argparse.Namespace) -> int:
    from stimuli.design import build_design, write_design
    from stimuli.fileio import check_output_dir
    from stimuli.errors import StimuliError
    from stimuli.protocol import check_trial_count, load_protocol

    check_output_dir(args.out)
    protocol = load_protocol(args.protocol)
    if args.participants is not None:
        try:
            check_trial_count(protocol, args.participants, "--participants")
        except ValueError as exc:
            raise StimuliError(str(exc)) from None
    design = build_design(protocol, args.participants, args.seed)
    for path in write_design(design, args.out):
        print(path)
    print_notes(design.notes, "note")
    return 0


def run_demo(args: argparse.Namespace) -> int:
    from stimuli.demo import run_demo as demo

    demo(args.out, quick=args.quick)
    return 0
