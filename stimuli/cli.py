"""The ``shapemotion`` command: a thin layer over the stimuli and analysis packages.

Each command lives in its own module exposing ``register(subparsers)``; the module adds a sub-parser
and sets ``func`` to a handler taking the parsed ``args`` and returning an exit code. Handlers import
heavy libraries (torch, pyrender, mujoco) inside themselves so that ``shapemotion --help`` stays fast.
User errors (``StimuliError``, ``AnalysisError``) are printed as one paragraph with exit code 2.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import textwrap

from analysis.errors import AnalysisError
from stimuli.errors import StimuliError
from stimuli.interrupts import install_interrupt_handler, was_interrupted

# Modules that add commands (`--help` lists the commands by STAGES below).
COMMAND_MODULES = [
    "stimuli.commands.init_cmd",
    "stimuli.commands.schema_cmd",
    "stimuli.commands.protocol_cmds",
    "analysis.commands",
    "analysis.commands_report",
    "stimuli.commands.bodies_cmd",
    "stimuli.commands.motion_cmd",
    "stimuli.commands.survey_cmd",
    "stimuli.commands.physics_cmd",
    "stimuli.commands.render_cmd",
    "stimuli.commands.serve_cmd",
]


# What `shapemotion --help` lists: the commands in the order of the data flow, by stage, each with a
# one-line example (tests/test_cli.py parses every example and checks that every command is here).
STAGES = {
    "design the study": {
        "init": "shapemotion init mystudy",
        "schema": "shapemotion schema > protocol.schema.json",
        "validate": "shapemotion validate mystudy/protocol.yaml",
        "design": "shapemotion design mystudy/protocol.yaml --out mystudy/design",
    },
    "make the stimuli": {
        "bodies": "shapemotion bodies mystudy/protocol.yaml --out mystudy/bodies",
        "motion": "shapemotion motion import captures/walk.bvh --loop --gait walk --out walk.npz",
        "physics": "shapemotion physics protocol protocols/exp2_com_vs_average.yaml --out physics",
        "render": "shapemotion render mystudy/protocol.yaml --out mystudy/out --quick",
        "preview": "shapemotion preview --gait walk --body sex=F,height=1.65,bmi=21 --out clip.mp4",
    },
    "run the study": {
        "survey": "shapemotion survey mystudy/out --format jspsych --out mystudy/site",
        "serve": "shapemotion serve mystudy/out --port 8000",
    },
    "analyse the answers": {
        "simulate": "shapemotion simulate mystudy/out --participants 8 --seed 1 --out responses.csv",
        "power": "shapemotion power mystudy/out --participants 8 16 24 --sims 200",
        "responses": "shapemotion responses inspect export.csv --design mystudy/out",
        "analyze": "shapemotion analyze mystudy/out --responses responses.csv --out mystudy/report",
        "anova": "shapemotion anova data.csv --dv rating --subject participant --within BODY MOTION --between SEX",
    },
    "all at once": {
        "demo": "shapemotion demo --quick",
    },
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="shapemotion",
        description="Stimulus generator and analysis suite for perception experiments on body shape and motion.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version="shapemotion 0.1.0")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND",
                                       help="one of the commands below; shapemotion COMMAND --help for its options")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    parser.epilog = command_overview(subparsers)
    # argparse would list the commands again, in the order the modules added them: the overview replaces it
    subparsers._choices_actions.clear()
    return parser


def command_overview(subparsers) -> str:
    """The commands by stage of the data flow, each with its help line and an example; a command no
    stage names comes last, so that none is hidden."""
    helps = {action.dest: action.help or "" for action in subparsers._choices_actions}
    placed = {name for commands in STAGES.values() for name in commands}
    stages = {**STAGES, "other": {name: "" for name in helps if name not in placed}}
    lines = ["commands, in the order of the data flow:"]
    for stage, commands in stages.items():
        present = [name for name in commands if name in helps]
        if present:
            lines += ["", f"{stage}:"]
        for name in present:
            lines += textwrap.wrap(helps[name], width=98, initial_indent=f"  {name:<10} ", subsequent_indent=" " * 13)
            if commands[name]:
                lines.append(f"{'':13}e.g. {commands[name]}")
    return "\n".join(lines)


def print_user_error(exc: Exception) -> None:
    """One readable paragraph on stderr; no traceback for a user error.

    On a terminal it is wrapped at 100 columns, between words only, so a long path stays whole. In a
    log or a pipe it stays on one line: the breaks moved with the length of the paths in it, and a
    phrase or a path split over two lines could not be searched for.
    """
    text = f"shapemotion: error: {exc}"
    if sys.stderr.isatty():
        text = textwrap.fill(text, width=100, subsequent_indent="  ", break_long_words=False, break_on_hyphens=False)
    print(text, file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    previous_handler = install_interrupt_handler()
    try:
        return int(args.func(args) or 0)
    except BaseException as exc:
        # Once Ctrl-C has come, whatever ends the command is the interrupt (see stimuli.interrupts).
        if isinstance(exc, KeyboardInterrupt) or (previous_handler is not None and was_interrupted()
                                                  and not isinstance(exc, SystemExit)):
            print("shapemotion: interrupted", file=sys.stderr)
            return 130
        return _exit_code_for(exc)
    finally:
        if previous_handler is not None:
            signal.signal(signal.SIGINT, previous_handler)


def _exit_code_for(exc: BaseException) -> int:
    """The exit code of a command that raised ``exc``, its message printed; raises what is a bug."""
    if isinstance(exc, (StimuliError, AnalysisError)):
        print_user_error(exc)
        return 2
    if isinstance(exc, BrokenPipeError):  # output piped into `head` and the like: stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    if isinstance(exc, OSError) and exc.filename is not None:
        # A safety net: commands check their output paths up front, but a path the system refuses
        # (a file where a folder should be, no permission, a full disk) is the user's to fix too.
        print_user_error(f"{exc.filename}: {exc.strerror or exc}")
        return 2
    raise exc


if __name__ == "__main__":
    sys.exit(main())
