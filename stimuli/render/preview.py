"""One clip from a motion (or a generated gait, or the stepping pose) on a body given by numbers:
the library side of ``shapemotion preview``.

>>> preview_gait("jog", duration_s=4.0)     # cadence, speed and cycles of a generated preview gait
(138.0, 2.2, 5)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from stimuli.errors import StimuliError
from stimuli.render.clip import Figure, Look, render_frames
from stimuli.render.sources import fit_loop, on_rig
from stimuli.render.video import write_video


def preview_gait(gait: str, duration_s: float) -> tuple[float, float, int]:
    """Cadence (steps/min), speed (m/s) and whole cycles of a generated ``gait`` in a clip of ``duration_s``."""
    from stimuli.motion.generate import DEFAULT_PACE
    from stimuli.motion.loop import cycles_for_clip

    cadence, speed = DEFAULT_PACE[gait]
    return cadence, speed, cycles_for_clip(duration_s, cadence)


def preview(out, sex: str, height_m: float, bmi: float, layout: str = "treadmill", size=(1280, 720), fps: int = 30,
            duration_s: float = 4.0, camera=(35.0, 10.0, 4.0, 40.0), belt_speed: float | None = None,
            motion=None, gait: str | None = None) -> Path:
    """Render one clip of a body (``sex``, ``height_m``, ``bmi``) to ``out`` (.mp4, poster .png beside it).

    The figure moves with ``motion`` (a Motion or an .npz file; retargeted onto the body unless on
    its rig), else the generated ``gait`` ("walk"/"jog"), else the stepping pose. ``camera`` is
    (azimuth, elevation, distance, vertical field of view) in degrees and metres; ``belt_speed``
    (m/s) overrides the motion's.
    """
    from stimuli.bodies import fit_body

    check_preview(out, fps, duration_s, belt_speed)
    width, height = size
    look = Look(layout, width, height, int(fps), float(duration_s), *camera,
                "#000000" if layout == "point_light" else "#ffffff")
    body = fit_body(sex, height_m, bmi)
    rot, root, speed = _poses(body, look, motion, gait, belt_speed)
    out = Path(out)
    write_video(render_frames(look, [Figure(body, rot, root, speed)]), out, look.fps, width, height, look.n_frames,
                poster=out.with_suffix(".png"))
    return out


def check_preview(out, fps: float, duration_s: float, belt_speed: float | None) -> None:
    """Every setting of :func:`preview` in range and the output writable, before a body is fitted or a
    frame drawn (errors name the ``render preview`` options)."""
    import math

    from stimuli.fileio import check_output_file

    out = Path(out)
    if out.suffix.lower() != ".mp4":
        raise StimuliError(f"--out: expected a .mp4 file name, got {out}")
    check_output_file(out)
    check_output_file(out.with_suffix(".png"), "--out (its poster)")
    for option, value, what in (("--duration", duration_s, "a duration > 0 seconds"), ("--fps", fps, "a frame rate > 0")):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise StimuliError(f"{option}: expected {what}, got {value}")
    if belt_speed is not None and not (math.isfinite(belt_speed) and belt_speed >= 0):
        raise StimuliError(f"--speed: expected a belt speed >= 0 m/s, got {belt_speed}")
    if duration_s * fps < 1:
        raise StimuliError(f"--duration {duration_s:g} s at --fps {fps} gives no frame")


def _poses(body, look: Look, motion, gait, belt_speed):
    if motion is None and gait is None:
        from stimuli.render.procedural import stepping_pose

        rot, root = stepping_pose(body, look.n_frames, cycles=max(1, int(round(look.duration_s))))
        return rot, root, float(belt_speed or 0.0)
    from stimuli.motion import Motion

    if motion is None:
        from stimuli.motion.generate import GaitParams, generate

        cadence, speed, cycles = preview_gait(gait, look.duration_s)
        motion = generate(GaitParams(gait=gait, cadence_spm=cadence, speed_mps=speed),
                          height_m=body.anthropometry.height_m, fps=float(look.fps), cycles=cycles)
    elif not isinstance(motion, Motion):
        motion = Motion.load(motion)
    motion = on_rig(motion, body)
    rot, root, scale = fit_loop(motion.rotations, motion.root_translation, motion.fps, look.n_frames, look.fps)
    speed = belt_speed if belt_speed is not None else float(motion.metadata.get("belt_speed_mps", 0.0)) * scale
    return rot, root, float(np.asarray(speed))
