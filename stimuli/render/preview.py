"""``shapemotion preview``: one clip from a motion (or a generated gait) on a body given by numbers."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from stimuli.errors import StimuliError
from stimuli.render.clip import Figure, Look, render_frames
from stimuli.render.settings import parse_resolution
from stimuli.render.sources import fit_loop, on_rig
from stimuli.render.video import write_video


def parse_body(text: str) -> dict:
    """'sex=M,height=1.8,bmi=25' → {'sex': 'M', 'height_m': 1.8, 'bmi': 25.0}.

    >>> parse_body("sex=F,height=1.6,bmi=28.1")
    {'sex': 'F', 'height_m': 1.6, 'bmi': 28.1}
    """
    fields = {}
    for part in text.split(","):
        key, _, value = part.partition("=")
        if key.strip().lower() in fields:  # the last would silently win
            raise StimuliError(f"--body {text!r}: {key.strip()} is given twice")
        fields[key.strip().lower()] = value.strip()
    try:
        return {"sex": fields["sex"].upper(), "height_m": float(fields["height"]), "bmi": float(fields["bmi"])}
    except (KeyError, ValueError):
        raise StimuliError(f"--body: expected sex=M|F,height=METRES,bmi=KG/M2, got {text!r}") from None


def parse_camera(text: str) -> tuple[float, float, float, float]:
    try:
        az, el, dist, fov = (float(x) for x in text.split(","))
    except ValueError:
        raise StimuliError(f"--camera: expected azimuth,elevation,distance,fov such as 35,10,4,40, got {text!r}") from None
    if not all(np.isfinite((az, el, dist, fov))):
        raise StimuliError(f"--camera: expected finite numbers, got {text!r}")
    # The same limits as a protocol's clip.camera.
    if not 0.5 < dist <= 50:
        raise StimuliError(f"--camera {text}: distance {dist:g} m must lie in (0.5, 50] metres")
    if not 5 < fov < 150:
        raise StimuliError(f"--camera {text}: field of view {fov:g}° must lie between 5 and 150 degrees")
    return az, el, dist, fov


def check_options(args) -> None:
    """Every option in range and the output writable, before a body is fitted or a frame drawn."""
    from stimuli.commands.checks import human_body, positive
    from stimuli.fileio import check_output_file

    out = Path(args.out)
    if out.suffix.lower() != ".mp4":
        raise StimuliError(f"--out: expected a .mp4 file name, got {out}")
    check_output_file(out)
    check_output_file(out.with_suffix(".png"), "--out (its poster)")
    positive("--duration", args.duration, "a duration > 0 seconds")
    positive("--fps", args.fps, "a frame rate > 0")
    if args.speed is not None and not (np.isfinite(args.speed) and args.speed >= 0):
        raise StimuliError(f"--speed: expected a belt speed >= 0 m/s, got {args.speed}")
    if args.duration * args.fps < 1:
        raise StimuliError(f"--duration {args.duration:g} s at --fps {args.fps} gives no frame")
    spec = parse_body(args.body)
    human_body(spec["height_m"], spec["bmi"], "--body height", "--body bmi")


def preview(args) -> Path:
    from stimuli.bodies import fit_body

    check_options(args)
    width, height = parse_resolution(args.resolution)
    az, el, dist, fov = parse_camera(args.camera)
    spec = parse_body(args.body)
    look = Look(args.layout, width, height, int(args.fps), float(args.duration), az, el, dist, fov,
                "#000000" if args.layout == "point_light" else "#ffffff")
    body = fit_body(spec["sex"], spec["height_m"], spec["bmi"])
    rot, root, speed = _poses(args, body, look)
    out = Path(args.out)
    write_video(render_frames(look, [Figure(body, rot, root, speed)]), out, look.fps, width, height, look.n_frames,
                poster=out.with_suffix(".png"))
    return out


def _poses(args, body, look: Look):
    if args.stepping:
        from stimuli.render.procedural import stepping_pose

        rot, root = stepping_pose(body, look.n_frames, cycles=max(1, int(round(look.duration_s))))
        return rot, root, float(args.speed or 0.0)
    from stimuli.motion import Motion

    if args.gait:
        from stimuli.motion.generate import GaitParams, generate

        cadence = 112.0 if args.gait == "walk" else 138.0
        cycles = max(1, int(round(look.duration_s * cadence / 120.0)))
        params = GaitParams(gait=args.gait, cadence_spm=cadence, speed_mps=1.2 if args.gait == "walk" else 2.2)
        motion = generate(params, height_m=body.anthropometry.height_m, fps=float(look.fps), cycles=cycles)
    else:
        motion = Motion.load(args.motion)
    motion = on_rig(motion, body)    # MissingSource until retargeting onto the Anny rig exists
    rot, root, scale = fit_loop(motion.rotations, motion.root_translation, motion.fps, look.n_frames, look.fps)
    speed = args.speed if args.speed is not None else float(motion.metadata.get("belt_speed_mps", 0.0)) * scale
    return rot, root, float(np.asarray(speed))
