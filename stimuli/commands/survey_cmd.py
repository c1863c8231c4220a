"""``shapemotion survey``: export the survey of a design or render folder."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

FORMATS = ("qsf", "qualtrics-txt", "jspsych", "psychopy")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "survey", help="export the survey: Qualtrics QSF or TXT, a jsPsych folder, PsychoPy conditions",
        description="Export the survey of a design folder (shapemotion design) or a render folder with "
                    "manifest.csv. Without a manifest, clips are clips/<stimulus_id>.mp4.")
    p.add_argument("folder", type=Path, help="design or render output folder")
    p.add_argument("--format", required=True, choices=FORMATS)
    p.add_argument("--out", type=Path, required=True,
                   help="output file (qsf, qualtrics-txt) or new folder (jspsych, psychopy)")
    p.add_argument("--video-base-url", default=None, help="URL the clips are served from (Qualtrics; jspsych: instead of copying the clips)")
    p.add_argument("--post-url", default="", help="jspsych: also POST each participant's CSV to this URL")
    p.set_defaults(func=run_survey)


def run_survey(args: argparse.Namespace) -> int:
    from stimuli.survey import export_survey

    result = export_survey(args.folder, args.format, args.out, args.video_base_url, args.post_url)
    print(result.path)
    for note in result.notes:
        print(f"note: {note}", file=sys.stderr)
    if result.manual_steps:
        print("\nSet these by hand after importing the TXT into Qualtrics:")
        for number, step in enumerate(result.manual_steps, start=1):
            print(f"{number}. {step}")
    return 0
