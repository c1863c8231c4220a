"""``shapemotion survey``: export the survey of a design or render folder."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from stimuli.commands.checks import base_url
from stimuli.fileio import output_path

FORMATS = ("qsf", "qualtrics-txt", "jspsych", "psychopy")
FILE_FORMATS = ("qsf", "qualtrics-txt")  # the others write a folder


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "survey", help="export the survey: Qualtrics QSF or TXT, a jsPsych folder, PsychoPy conditions",
        description="Export the survey of a design folder (shapemotion design) or a render folder with "
                    "manifest.csv. Without a manifest, clips are clips/<stimulus_id>.mp4.")
    p.add_argument("folder", type=Path, help="design or render output folder")
    p.add_argument("--format", required=True, choices=FORMATS)
    p.add_argument("--out", type=output_path, required=True,
                   help="output file (qsf, qualtrics-txt) or new folder (jspsych, psychopy)")
    p.add_argument("--video-base-url", default=None, help="URL the clips are served from (Qualtrics; jspsych: instead of copying the clips)")
    p.add_argument("--post-url", default="", help="jspsych: also POST each participant's CSV to this URL")
    p.set_defaults(func=run_survey)


def run_survey(args: argparse.Namespace) -> int:
    from stimuli.fileio import check_output_dir, check_output_file
    from stimuli.survey import export_survey

    check_options(args)
    if args.format in FILE_FORMATS:
        check_output_file(args.out)
    else:
        check_output_dir(args.out)
    result = export_survey(args.folder, args.format, args.out, args.video_base_url, args.post_url)
    print(result.path)
    for note in result.notes:
        print(f"note: {note}", file=sys.stderr)
    if result.manual_steps:
        print("\nSet these by hand after importing the TXT into Qualtrics:")
        for number, step in enumerate(result.manual_steps, start=1):
            print(f"{number}. {step}")
    return 0


def check_options(args: argparse.Namespace) -> None:
    """Options a format does not use are errors, not silently dropped; URLs must fit the format.

    Qualtrics hosts the survey itself, so its clips need absolute http(s) addresses; a jsPsych folder
    may also name them relative to its own index.html.
    """
    from stimuli.errors import StimuliError

    if args.post_url and args.format != "jspsych":
        raise StimuliError(f"--post-url: only the jspsych format posts responses; --format {args.format} "
                           "does not use it")
    if any(c.isspace() for c in args.post_url):
        raise StimuliError(f"--post-url {args.post_url!r}: expected an address without spaces")
    url = args.video_base_url
    if url is None:
        return
    if args.format == "psychopy":
        raise StimuliError("--video-base-url: the psychopy format plays the clips from the folder; it does not "
                           "use a URL")
    base_url("--video-base-url", url, absolute=args.format in FILE_FORMATS)
