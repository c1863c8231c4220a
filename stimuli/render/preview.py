"""``shapemotion preview``: one clip from a motion (or a generated gait) on a body given by numbers."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from stimuli.errors import StimuliError
from stimuli.render.clip import Figure, Look, render_frames
from stimuli.render.settings import parse_resolution
from stimuli.render.sources import MissingSource, fit_loop
from stimuli.render.video import write_video


def parse_body(text: str) -> dict:
    """'sex=M,height=1.8,bmi=25' → {'sex': 'M', 'height_m': 1.8, 'bmi': 25.0}.

    >>> parse_body("sex=F,height=1.6,bmi=28.1")
    {'sex': 'F', 'height_m': 1.6, 'bmi': 28.1}
    """
    fields = {}
    for part in text.split(","):
        key, _, value = part.partition("=")
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
    return az, el, dist, fov


def preview(args) -> Path:
    from stimuli.bodies import fit_body

    width, height = parse_resolution(args.resolution)
    az, el, dist, fov = parse_camera(args.camera)
    spec = parse_body(args.body)
    look = Look(args.layout, width, height, int(args.fps), float(args.duration), az, el, dist, fov,
                "#000000" if args.layout == "point_light" else "#ffffff")
    body = fit_body(spec["sex"], spec["height_m"], spec["bmi"])
    rot, root, speed = _poses(args, body, look)
    out = Path(args.out)
    if out.suffix.lower() != ".mp4":
        raise StimuliError(f"--out: expected a .mp4 file name, got {out}")
    write_video(render_frames(look, [Figure(body, rot, root, speed)]), out, look.fps, width, height, look.n_frames,
                poster=out.with_suffix(".png"))
    return out


def _poses(args, body, look: Look):
    if args.stepping:
        from stimuli.render.procedural import stepping_pose

        rot, root = stepping_pose(body, look.n_frames, cycles=max(1, int(round(look.duration_s))))
        return rot, root, float(args.speed or 0.0)
    if args.gait:
        raise MissingSource(f"--gait {args.gait}: generated gaits need retargeting onto the Anny rig "
                            "(stimuli.motion), which is not available to the renderer yet; use --motion or --stepping")
    from stimuli.motion import Motion

    motion = Motion.load(args.motion)
    if motion.joint_names != list(body.rig.names):
        raise StimuliError(f"{args.motion}: the motion's skeleton ({len(motion.joint_names)} joints, e.g. "
                           f"{motion.joint_names[:3]}) is not the Anny rig ({body.rig.n_bones} bones); "
                           "retarget it onto the body first")
    rot, root, scale = fit_loop(motion.rotations, motion.root_translation, motion.fps, look.n_frames, look.fps)
    speed = args.speed if args.speed is not None else float(motion.metadata.get("belt_speed_mps", 0.0)) * scale
    return rot, root, float(np.asarray(speed))
