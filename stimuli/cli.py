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
import sys
import textwrap

from analysis.errors import AnalysisError
from stimuli.errors import StimuliError

# Modules that add commands, in the order `--help` lists them.
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


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="shapemotion",
        description="Stimulus generator and analysis suite for perception experiments on body shape and motion.",
    )
    parser.add_argument("--version", action="version", version="shapemotion 0.1.0")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    return parser


def print_user_error(exc: Exception) -> None:
    """One readable paragraph on stderr; no traceback for a user error."""
    print(textwrap.fill(f"shapemotion: error: {exc}", width=100, subsequent_indent="  "), file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except (StimuliError, AnalysisError) as exc:
        print_user_error(exc)
        return 2
    except BrokenPipeError:  # output piped into `head` and the like: stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as exc:
        # A safety net: commands check their output paths up front, but a path the system refuses
        # (a file where a folder should be, no permission, a full disk) is the user's to fix too.
        if exc.filename is None:
            raise
        print_user_error(f"{exc.filename}: {exc.strerror or exc}")
        return 2
    except KeyboardInterrupt:
        print("shapemotion: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
