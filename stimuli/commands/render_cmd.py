"""``shapemotion render`` (every stimulus of a protocol) and ``shapemotion preview`` (one clip)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from shapemotion.execution import SCHEDULER_HELP, SCHEDULER_METAVAR
from stimuli.fileio import output_path


def register(subparsers) -> None:
    p = subparsers.add_parser("render", help="render every stimulus clip of a protocol (resumable)",
                              description="Render every test, practice and familiarization stimulus of a protocol "
                                          "into clips/*.mp4, posters/*.png, manifest.csv and contact_sheet.png. "
                                          "Clips already rendered with the same inputs are kept.")
    p.add_argument("protocol", type=Path, nargs="?", help="protocol YAML (not needed with --verify)")
    p.add_argument("--out", type=output_path, required=True, help="output folder")
    p.add_argument("--resolution", default=None, help="WIDTHxHEIGHT (default: the protocol's clip size)")
    p.add_argument("--fps", type=int, default=None, help="frames per second (default: the protocol's)")
    p.add_argument("--workers", type=int, default=None, help="parallel processes (default: 2, or fewer cores)")
    p.add_argument("--limit", type=int, default=None, help="render only the first K selected stimuli")
    p.add_argument("--only", default=None, help="comma-separated parts of stimulus ids to render")
    p.add_argument("--quick", action="store_true", help="small, low-frame-rate clips for a fast look")
    p.add_argument("--poses", choices=["protocol", "procedural"], default="protocol",
                   help="'procedural': real bodies with a simple stepping pose (checks layout and framing "
                        "before motions exist)")
    p.add_argument("--motions", type=Path, default=None,
                   help="folder written by 'shapemotion physics protocol' (Exp 2's NoCOM and COM motions)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--scheduler", metavar=SCHEDULER_METAVAR, help=SCHEDULER_HELP)
    p.add_argument("--verify", action="store_true",
                   help="only check the clips of an existing manifest: re-hash and decode every one")
    p.add_argument("--no-survey", action="store_true",
                   help="don't write the design files and survey exports into --out after a complete render")
    p.add_argument("--video-base-url", default=None, help="base URL of the clips in the survey exports")
    p.set_defaults(func=run_render)

    p = subparsers.add_parser("preview", help="render one clip from a motion file and a body spec",
                              description="Render one clip: a motion (.npz on the Anny rig) or a generated gait "
                                          "on a body given as --body sex=M,height=1.80,bmi=25.")
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--motion", type=Path, help="motion .npz (DESIGN.md contract) on the Anny rig")
    source.add_argument("--gait", choices=["walk", "jog"], help="generate this gait for the body")
    source.add_argument("--stepping", action="store_true", help="a simple procedural stepping pose")
    p.add_argument("--body", required=True, help="sex=M,height=1.80,bmi=25")
    p.add_argument("--layout", choices=["treadmill", "point_light"], default="treadmill")
    p.add_argument("--out", type=output_path, required=True, help="output .mp4 (a poster .png is written next to it)")
    p.add_argument("--resolution", default="1280x720")
    p.add_argument("--fps", type=int, default=30)
    p.add_argument("--duration", type=float, default=4.0, help="seconds")
    p.add_argument("--camera", default="35,10,4,40", help="azimuth,elevation,distance,fov (degrees, metres)")
    p.add_argument("--speed", type=float, default=None, help="belt speed in m/s (default: the motion's)")
    p.set_defaults(func=run_preview)


def run_render(args: argparse.Namespace) -> int:
    from shapemotion.execution import errors_as, scheduler_option, unused_workers_warning
    from stimuli.errors import StimuliError
    from stimuli.render.manifest import verify_manifest
    from stimuli.render.pipeline import disk_full_is_a_user_error, render_protocol, survey_for_render

    if args.verify:
        _check_manifest_present(args.out)
        problems = verify_manifest(args.out)
        for line in problems:
            print(line)
        if problems:
            raise StimuliError(f"{args.out}/manifest.csv: {len(problems)} clip(s) do not verify")
        print(f"{args.out}/manifest.csv: every clip verifies")
        return 0
    if args.protocol is None:
        raise StimuliError("render: a PROTOCOL file is needed (only --verify works without one)")
    _check_render_options(args)
    scheduler = scheduler_option(args.scheduler, StimuliError)
    unused = unused_workers_warning(scheduler, args.workers)
    if unused:
        print(f"warning: {unused}", file=sys.stderr)
    with errors_as(StimuliError):
        report = render_protocol(args.protocol, args.out, resolution=args.resolution, fps=args.fps,
                                 limit=args.limit, only=args.only, workers=args.workers, quick=args.quick,
                                 progress=not args.no_progress,
                                 source=args.poses, motions_dir=args.motions, scheduler=scheduler,
                                 warn=lambda line: print(f"warning: {line}"))
    print(report.summary())
    if not args.no_survey:
        with disk_full_is_a_user_error(args.out):
            missing, exports = survey_for_render(report, args.video_base_url)
        if exports is None:
            print(f"survey: not exported, {len(missing)} stimuli have no clip yet (render them all first)")
        for r in exports or ():
            print(f"survey: {r.format} → {r.path}")
    return 0


def _check_manifest_present(out_dir: Path) -> None:
    """--verify checks a finished render: a folder without clips in its manifest is not one."""
    from stimuli.errors import StimuliError
    from stimuli.render.manifest import MANIFEST, read_manifest

    if not (out_dir / MANIFEST).is_file():
        raise StimuliError(f"{out_dir}/{MANIFEST}: not found; --verify checks the clips of a folder written by "
                           "'shapemotion render'")
    if not read_manifest(out_dir):
        raise StimuliError(f"{out_dir}/{MANIFEST}: lists no clips, so there is nothing to verify")


def _check_render_options(args: argparse.Namespace) -> None:
    """Numbers in range and the output folder usable, before the protocol is read (``render_protocol``
    checks --limit and --motions against it before the first clip)."""
    from stimuli.commands.checks import at_least
    from stimuli.fileio import check_output_dir
    from stimuli.render.settings import check_fps, parse_resolution

    check_fps(args.fps)
    parse_resolution(args.resolution)
    at_least("--workers", args.workers, 1)
    check_video_base_url(args.video_base_url)
    check_output_dir(args.out)


def check_video_base_url(url: str | None) -> None:
    """The survey exports include Qualtrics files, whose clips need absolute http(s) addresses."""
    from stimuli.commands.checks import base_url

    base_url("--video-base-url", url, absolute=True)


def parse_camera(text: str) -> tuple[float, float, float, float]:
    """--camera 'azimuth,elevation,distance,fov' within a protocol's clip.camera limits.

    >>> parse_camera("35,10,4,40")
    (35.0, 10.0, 4.0, 40.0)
    """
    import math

    from stimuli.errors import StimuliError

    try:
        az, el, dist, fov = (float(x) for x in text.split(","))
    except ValueError:
        raise StimuliError(f"--camera: expected azimuth,elevation,distance,fov such as 35,10,4,40, got {text!r}") from None
    if not all(math.isfinite(x) for x in (az, el, dist, fov)):
        raise StimuliError(f"--camera: expected finite numbers, got {text!r}")
    if not 0.5 < dist <= 50:
        raise StimuliError(f"--camera {text}: distance {dist:g} m must lie in (0.5, 50] metres")
    if not 5 < fov < 150:
        raise StimuliError(f"--camera {text}: field of view {fov:g}° must lie between 5 and 150 degrees")
    return az, el, dist, fov


def run_preview(args: argparse.Namespace) -> int:
    from stimuli.commands.checks import parse_body
    from stimuli.render.preview import preview
    from stimuli.render.settings import parse_resolution

    body = parse_body(args.body)
    size, camera = parse_resolution(args.resolution), parse_camera(args.camera)
    print(preview(args.out, body["sex"], body["height_m"], body["bmi"], layout=args.layout, size=size, fps=args.fps,
                  duration_s=args.duration, camera=camera, belt_speed=args.speed, motion=args.motion, gait=args.gait))
    return 0
