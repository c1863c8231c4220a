"""From a protocol (plus command-line overrides) to a clip's :class:`~stimuli.render.clip.Look`,
and the hash that decides whether a finished clip can be kept when rendering again."""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import re
from pathlib import Path

from stimuli.errors import StimuliError
from stimuli.fileio import source_digest
from stimuli.render.clip import Look

# Bump to render every clip again for a reason the code does not show (e.g. another pyrender or
# ffmpeg); a change to the renderer's own code does it by itself (upstream_digest).
RENDER_VERSION = "4"
QUICK_WIDTH, QUICK_FPS = 320, 15


def parse_resolution(text: str | None) -> tuple[int, int] | None:
    """'1280x720' → (1280, 720); None stays None. Even sizes within the bounds a protocol's
    ``clip.width``/``clip.height`` have (``stimuli.protocol.CLIP_WIDTH_RANGE``/``CLIP_HEIGHT_RANGE``).

    >>> parse_resolution("640x360")
    (640, 360)
    """
    if text is None:
        return None
    if isinstance(text, tuple):
        return text
    match = re.fullmatch(r"\s*(\d+)\s*[xX×]\s*(\d+)\s*", str(text))
    if not match:
        raise StimuliError(f"--resolution: expected WIDTHxHEIGHT such as 1280x720, got {text!r}")
    from stimuli.protocol import CLIP_HEIGHT_RANGE, CLIP_WIDTH_RANGE

    width, height = int(match.group(1)), int(match.group(2))
    if width % 2 or height % 2:
        raise StimuliError(f"--resolution: width and height must be even (H.264 yuv420p), got {text!r}")
    for what, value, (low, high) in (("width", width, CLIP_WIDTH_RANGE), ("height", height, CLIP_HEIGHT_RANGE)):
        if not low <= value <= high:
            raise StimuliError(f"--resolution: {what} {value} is outside {low}–{high} pixels (the bounds of a "
                               f"protocol's clip.{what}), got {text!r}")
    return width, height


def check_fps(fps) -> None:
    """``--fps`` within the bounds of a protocol's ``clip.fps`` (None: not given, passes)."""
    from stimuli.protocol import CLIP_FPS_RANGE

    low, high = CLIP_FPS_RANGE
    if fps is not None and not low <= fps <= high:
        raise StimuliError(f"--fps: expected a whole number of frames per second from {low} to {high} (the bounds "
                           f"of a protocol's clip.fps), got {fps}")


def _even(x: float) -> int:
    return max(16, int(round(x / 2)) * 2)


def look_for(protocol, stimulus, resolution=None, fps=None, quick: bool = False) -> Look:
    """The appearance of one stimulus: protocol clip settings, per-level view, overrides."""
    clip, camera = protocol.clip, protocol.clip.camera
    width, height = parse_resolution(resolution) or (clip.width, clip.height)
    if quick and resolution is None:
        width, height = QUICK_WIDTH, _even(QUICK_WIDTH * clip.height / clip.width)
    rate = int(fps or (QUICK_FPS if quick else clip.fps))
    check_fps(fps)
    azimuth = camera.azimuth_deg
    for factor in protocol.factors:  # e.g. thesis_pointlight: each PARAMETER level has its own view angle
        level = stimulus.levels.get(factor.name)
        view = factor.level_settings.get(level, {}).get("view_deg") if level is not None else None
        if view is not None:
            azimuth = float(view)
    labels = tuple(protocol.display.labels or ())
    return Look(layout=protocol.display.layout, width=width, height=height, fps=rate,
                duration_s=float(clip.duration_s), azimuth_deg=azimuth, elevation_deg=camera.elevation_deg,
                distance_m=camera.distance_m, fov_deg=camera.fov_deg, background=clip.background, labels=labels,
                loop=clip.loop, floor=protocol.display.floor is not False,
                labels_below=protocol.display.label_position == "below", label_colour=protocol.display.label_colour or "")


def camera_distance_warnings(protocol, design) -> list[str]:
    """``validate``'s warning when ``clip.camera.distance_m`` is given for a layout whose framing rule
    sets the distance instead (a treadmill or side-by-side layout on a floor:
    ``clip.placements``): the distance the rule gives for the protocol's shortest and tallest actor.

    >>> from stimuli.protocol import load_protocol
    >>> from stimuli.design import build_design
    >>> exp1 = load_protocol("protocols/exp1_shape_motion.yaml")
    >>> camera_distance_warnings(exp1, build_design(exp1))   # distance_m not given: nothing to say
    []
    """
    import numpy as np

    from stimuli.render.clip import placements

    camera = protocol.clip.camera
    if "distance_m" not in camera.model_fields_set or not design.stimuli:
        return []
    look = look_for(protocol, design.stimuli[0])
    if not (look.floor and look.layout in ("treadmill", "side_by_side")):
        return []
    figures = max(len(s.arrangement) or 1 for s in design.stimuli) if look.layout == "side_by_side" else 1
    heights = [a.height_m for a in protocol.actors] or [1.75]
    used = []
    for height in (min(heights), max(heights)):   # a clip is framed on its tallest figure
        _, view = placements(look, figures, height)
        used.append(float(np.linalg.norm(view.pose[:3, 3] - [0.0, 0.5 * height, 0.0])))
    span = f"{used[0]:.2f} m" if abs(used[1] - used[0]) < 0.005 else f"{used[0]:.2f}–{used[1]:.2f} m"
    return [f"clip.camera.distance_m: {camera.distance_m:g} m is not used on the {look.layout} layout: its framing "
            f"rule puts the camera as near as the treadmill{'s' if figures > 1 else ''} and the bod{'ies' if figures > 1 else 'y'} allow, "
            f"{span} from the body's middle for this protocol's actors (at azimuth_deg, elevation_deg and fov_deg "
            f"as given); leave distance_m out"]


@functools.lru_cache(maxsize=1)
def upstream_digest() -> str:
    """SHA-256 of the code and bundled data that make bodies, motions and pixels (the renderer and its shaders).

    A change to the generator, the retargeting, the body fitter or the renderer changes clips, so a
    resumed render does not keep clips made by the old code. The renderer's own modules are part of
    it: with only :data:`RENDER_VERSION` to bump by hand, a new body colour kept every clip of the
    old one.
    """
    return source_digest("bodies", "motion", "physics", "data", "render", "render/shaders")


def files_digest(paths) -> str:
    """SHA-256 over the bytes of motion files a clip reads ('' entries for missing files)."""
    digest = hashlib.sha256()
    for path in paths:
        path = Path(path)
        digest.update(path.name.encode() + (path.read_bytes() if path.is_file() else b""))
    return digest.hexdigest()


def inputs_hash(protocol, stimulus, look: Look, motion_files=(), poses: str = "protocol") -> str:
    """SHA-256 over everything a clip depends on: the stimulus, its actors, gaits, the gait it shows,
    look, versions, the upstream code (:func:`upstream_digest`), any motion files it reads, the
    protocol's seed when it shows generated motions, and the pose source (only when it is not the
    protocol's, so that the hashes of protocol renders stay as they were)."""
    from stimuli.render.sources import gait_of, generator_seed

    actor_ids = {stimulus.body_actor, stimulus.motion_actor, protocol.display.body} - {"", None}
    payload = {
        "render_version": RENDER_VERSION,
        "stimulus": dataclasses.asdict(stimulus),
        "actors": [a.model_dump() for a in protocol.actors if a.id in actor_ids or a.sex in stimulus.levels.values()],
        "gaits": {k: v.model_dump() for k, v in protocol.gaits.items()},
        "factors": [f.model_dump() for f in protocol.factors],
        "look": dataclasses.asdict(look),
        "loop": protocol.clip.loop,
        "cycles": protocol.clip.cycles,
        "upstream": upstream_digest(),
        "motion_files": files_digest(motion_files),
        # A stimulus without a gait level (familiarization) shows the first declared gait, which the
        # sorted "gaits" above does not tell: reordering the gaits kept a walk where a jog was due.
        "gait": gait_of(protocol, stimulus),
    }
    if poses != "protocol":  # a stepping-pose clip must not pass for the real one on the next render
        payload["poses"] = poses
    elif (seed := generator_seed(protocol, stimulus)) is not None:
        payload["seed"] = seed   # it draws each actor's style: another seed, another walk
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode()).hexdigest()
