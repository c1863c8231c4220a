"""The thesis protocols' motions (Shewhorak 2017): survey strengths and validation walks A–D.

Both start from the **lean base walk**: the real CMU capture ``stimuli/data/cmu_35_01_walk.bvh``
(its one whole cycle, looped on a treadmill), retargeted onto the shown body. The thesis reused its lean
motion capture (MP) as the base; a real capture keeps the natural variation the modifier is meant
to act on, whereas the generator's walk already carries anthropometric trends and a drawn style.

- ``strength`` (thesis_pointlight, thesis_mesh): the base walk on the shown body (MP's for the
  point lights, MP's obese deformation for the meshes), modified by Table 4-1 or 5-2 at the
  STRENGTH level's body-fat %, restricted to the rows named by the PARAMETER level's
  ``level_settings.modifies`` (e.g. ``"arm_abduction+arm_bob"``; ``stimuli.motion.modifier.STRENGTH_ROWS``).
- ``source`` (thesis_validation): each SOURCE level's ``level_settings.motion`` says what drives
  the body: ``lean_walk`` (the base walk), ``modifier`` (the base walk through the five-parameter
  modifier with the body actor's height, body fat, chest and waist/hip), ``generator`` (the motion
  generator's walk for the body actor, ``actor_gait``: the stand-in for a hand-keyframed walk) or
  ``bvh:<path>`` (a capture of your own; relative paths start from the protocol file's folder).
"""

from __future__ import annotations

import functools
from pathlib import Path

from stimuli.errors import StimuliError
from stimuli.protocol import SOURCE_MOTIONS, capture_file
from stimuli.render.clip import Look
from stimuli.render.sources import MissingSource, fit_loop, on_rig

BASE_WALK = Path(__file__).resolve().parents[1] / "data" / "cmu_35_01_walk.bvh"
BASE_CYCLES = 1  # the capture holds one whole cycle; one-cycle loops let fit_loop keep speed ratios
MOTION_KINDS = (*SOURCE_MOTIONS, "bvh:<path>")


_ON_BODY: dict = {}  # (body id, body targets, file) -> the walk on that body, per process


def _fitted(motion, look: Look, fallback_speed: float):
    """(rotations, root, belt speed) of a looping motion resampled to the clip's frames."""
    rot, root, scale = fit_loop(motion.rotations, motion.root_translation, motion.fps, look.n_frames, look.fps, look.loop)
    return rot, root, float(motion.metadata.get("belt_speed_mps", fallback_speed)) * scale


@functools.lru_cache(maxsize=8)
def _looped_bvh(path: str):
    """A BVH walk trimmed to whole cycles, on a treadmill, looped (cached per process)."""
    from stimuli.motion.bvh import read_bvh
    from stimuli.motion.loop import make_loop

    return make_loop(read_bvh(path), cycles=BASE_CYCLES)


def walk_on(body, path: Path = BASE_WALK):
    """A captured walk (default: the lean base walk) retargeted onto ``body``'s rig (cached)."""
    key = (body.body_id, repr(sorted(body.targets.items())), str(path))
    if key not in _ON_BODY:
        _ON_BODY[key] = on_rig(_looped_bvh(str(path)), body)
    return _ON_BODY[key]


def _setting(factor, level: str, key: str):
    return factor.level_settings.get(level, {}).get(key)


# -- thesis_pointlight, thesis_mesh: STRENGTH × PARAMETER ----------------------------------------

def strength_motion(protocol, stimulus, strength: str, body, look: Look):
    """The base walk on ``body`` modified by Tables 4-1/5-2 at body fat ``strength`` (%), restricted
    to the rows the stimulus's PARAMETER level names in ``level_settings.modifies``."""
    from stimuli.motion.modifier import modify_strengths, table_strengths

    factor = protocol.factor_mapped_to("parameter")
    level = stimulus.levels.get(factor.name) if factor else None
    modifies = _setting(factor, level, "modifies") if level is not None else None
    if not modifies:
        where = f"factors.{factor.name}.level_settings.{level}" if level is not None else "a factor with maps_to: parameter"
        raise StimuliError(f"{protocol.name}: {where} needs 'modifies': Table 4-1/5-2 rows joined by '+' "
                           "(e.g. \"arm_abduction+arm_bob\"), the gait parameters this level exaggerates")
    try:
        body_fat = float(strength)
    except ValueError:
        raise StimuliError(f"{protocol.name}: STRENGTH level {strength!r} must be a body-fat % (a number)") from None
    try:
        strengths = table_strengths(modifies, body_fat)
    except StimuliError as exc:
        raise StimuliError(f"{protocol.name}: factors.{factor.name}.level_settings.{level}.modifies: {exc}") from None
    motion = modify_strengths(walk_on(body), strengths)
    return _fitted(motion, look, 0.0)


# -- thesis_validation: SOURCE ---------------------------------------------------------------------

def source_motion(protocol, stimulus, level: str, body, look: Look):
    """What the SOURCE level's ``level_settings.motion`` names, on ``body`` (see the module doc)."""
    factor = protocol.factor_mapped_to("source")
    spec = str(_setting(factor, level, "motion") or "")
    actor = next(a for a in protocol.actors if a.id == stimulus.body_actor)
    if not spec:
        raise MissingSource(
            f"{protocol.name}: SOURCE = {level!r} has no motion source: add the setting "
            f"factors.{factor.name}.level_settings.{level}.motion to the protocol, e.g. "
            f"{level}: {{motion: \"bvh:<path to a capture>\"}} (shapemotion ships no capture of an obese "
            f"walker) or one of {', '.join(MOTION_KINDS[:3])}")
    if spec == "lean_walk":
        return _fitted(walk_on(body), look, 0.0)
    if spec == "modifier":
        scale = _setting(factor, level, "base_scale")
        if scale is not None and not isinstance(scale, (int, float)):
            raise StimuliError(f"{protocol.name}: factors.{factor.name}.level_settings.{level}.base_scale: "
                               f"expected a number, got {scale!r}")
        return _fitted(modified_walk(actor, body, 1.0 if scale is None else float(scale)), look, 0.0)
    if spec == "generator":
        return _fitted(on_rig(generated_walk(protocol, actor, look), body), look, 0.0)
    if spec.startswith("bvh:"):
        return _fitted(walk_on(body, captured_path(protocol, factor, level, spec)), look, 0.0)
    raise StimuliError(f"{protocol.name}: factors.{factor.name}.level_settings.{level}.motion = {spec!r}: "
                       f"expected one of {', '.join(MOTION_KINDS)}")


def captured_path(protocol, factor, level: str, spec: str) -> Path:
    """The file of a ``bvh:<path>`` motion setting; it must exist."""
    path = capture_file(protocol, spec)
    if not path.is_file():
        raise MissingSource(f"{protocol.name}: factors.{factor.name}.level_settings.{level}.motion: "
                            f"{path} not found (a BVH capture; relative paths start from the protocol's "
                            f"folder {protocol.folder})")
    return path


def modified_walk(actor, body, base_scale: float = 1.0):
    """The base walk on ``body`` through the five-parameter modifier with the actor's measures.

    The body already has the actor's height, so the modifier's height scaling is left out.
    ``base_scale`` multiplies the walking-base offset (level setting ``base_scale``; 1 = the
    thesis script's centimetres per foot).
    """
    from stimuli.motion.modifier import modify

    wthr = actor.waist_m / actor.hip_m if actor.waist_m and actor.hip_m else None
    if actor.body_fat_pct is None:
        raise StimuliError(f"actor {actor.id}: body_fat_pct is needed by the thesis modifier")
    return modify(walk_on(body), actor.height_m, actor.body_fat_pct, chest_m=actor.chest_m, wthr=wthr,
                  scale_height=False, base_scale=base_scale)


def generated_walk(protocol, actor, look: Look):
    """The generator's walk for the actor (its anthropometric trends: wider base, abducted arms …),
    at the protocol's walk cadence or, without one, the base walk's; speed from the trends."""
    from stimuli.motion.loop import cycles_for_clip
    from stimuli.motion.style import actor_gait

    spec = protocol.gaits.get("walk")
    cadence = spec.cadence_spm if spec else float(_looped_bvh(str(BASE_WALK)).metadata["cadence_spm"])
    speed = spec.speed_mps if spec else None
    cycles = cycles_for_clip(look.duration_s, cadence)
    return actor_gait(actor, "walk", cadence, speed, protocol.seed, float(look.fps), cycles)


def source_files(protocol, stimulus) -> list[Path]:
    """The capture files a SOURCE stimulus reads (part of its inputs hash)."""
    factor = protocol.factor_mapped_to("source")
    if factor is None:
        return []
    levels = stimulus.arrangement or factor.levels[:1]
    specs = [str(_setting(factor, level, "motion") or "") for level in levels]
    return [capture_file(protocol, s) for s in specs if s.startswith("bvh:")]
