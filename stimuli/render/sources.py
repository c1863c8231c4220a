"""What each stimulus shows: its bodies and their motions, as :class:`~stimuli.render.clip.Figure` s.

The protocol's ``maps_to`` fields decide: ``body`` → whose body (``Stimulus.body_actor``),
``motion`` → whose motion (``Stimulus.motion_actor``), ``gait`` → walk/jog, ``method`` → the
level's ``level_settings.motion``: ``average`` (NoCOM, the sex × gait average motion) or ``physics``
(COM, that motion retargeted by physics onto the body); a level without the setting goes by its
name (NoCOM = average, any other = physics: ``stimuli.protocol.method_motion_of``),
``strength`` → the thesis modifier at a body-fat level, ``source`` → the thesis validation walks
(both in :mod:`stimuli.render.thesis_sources`).
Where a motion source is not available yet, :class:`MissingSource` (a ``StimuliError``) names it.

Every motion is a seamless loop; :func:`fit_loop` resamples it so that a whole number of loops
fills the clip exactly (duration × fps frames), scaling time — and the belt speed — slightly when
the loop length does not divide the clip.
"""

from __future__ import annotations

import functools

import numpy as np

from stimuli.errors import StimuliError
from stimuli.motion.loop import cycles_for_clip
from stimuli.render.clip import Figure, Look
from stimuli.render.timing import belt_matched_speed


class MissingSource(StimuliError):
    """A stimulus needs a motion source that shapemotion does not provide (yet)."""


def fit_loop(rotations: np.ndarray, root: np.ndarray, fps: float, n_frames: int, clip_fps: float,
             loop: bool = True):
    """Resample a looping pose sequence to ``n_frames`` at ``clip_fps`` holding whole loops.

    Returns (rotations (N, J, 4), root (N, 3), time_scale) where time_scale > 1 means the motion
    plays faster than recorded (multiply its speed by it). With ``loop`` False the motion plays at
    its own pace (time_scale 1) and the clip ends wherever its last frame falls (``clip.loop: false``).

    >>> import numpy as np
    >>> rot = np.tile([1.0, 0, 0, 0], (30, 2, 1)); root = np.zeros((30, 3)); root[:, 1] = np.arange(30)
    >>> r, p, s = fit_loop(rot, root, 30.0, 60, 30.0)   # a 1 s loop played twice in 2 s
    >>> r.shape, float(s), bool(p[30, 1] == p[0, 1])
    ((60, 2, 4), 1.0, True)
    """
    from stimuli.motion import quat

    loop_s = len(rotations) / fps
    clip_s = n_frames / clip_fps
    loops = max(1, int(round(clip_s / loop_s)))
    scale = loops * loop_s / clip_s if loop else 1.0
    src = (np.arange(n_frames) / clip_fps * scale * fps) % len(rotations)
    i0 = np.floor(src).astype(int) % len(rotations)
    i1 = (i0 + 1) % len(rotations)
    a = src - np.floor(src)
    rot = quat.slerp(rotations[i0], rotations[i1], np.repeat(a[:, None], rotations.shape[1], axis=1))
    pos = root[i0] * (1 - a[:, None]) + root[i1] * a[:, None]
    return rot, pos, scale


@functools.lru_cache(maxsize=32)
def _body(actor_json: str):
    from stimuli.bodies import body_for_actor
    from stimuli.protocol import Actor

    return body_for_actor(Actor.model_validate_json(actor_json))


def body_of(protocol, actor_id: str):
    """The fitted body of an actor (cached per process; bodies are also cached on disk)."""
    actor = next((a for a in protocol.actors if a.id == actor_id), None)
    if actor is None:
        raise StimuliError(f"{protocol.name}: no actor with id {actor_id!r}")
    return _body(actor.model_dump_json())


def gait_of(protocol, stimulus) -> str:
    """The stimulus's gait level; stimuli without one (familiarization) use the first declared gait."""
    factor = protocol.factor_mapped_to("gait")
    level = stimulus.levels.get(factor.name) if factor else None
    return level or next(iter(protocol.gaits), "walk")


def protocol_figures(protocol, stimulus, look: Look, motions_dir=None) -> list[Figure]:
    """The figures of one stimulus from the protocol's real motion sources."""
    layout = protocol.display.layout
    alternatives = protocol.factors_with_role("alternatives")
    if alternatives:
        kind = alternatives[0].maps_to
        if not stimulus.arrangement:  # familiarization: the body alone, moving with the first alternative
            return [_alternative_figure(protocol, stimulus, look, kind, alternatives[0].levels[0], "", motions_dir)]
        return [_alternative_figure(protocol, stimulus, look, kind, level, label, motions_dir)
                for level, label in zip(stimulus.arrangement, _labels(protocol, len(stimulus.arrangement)))]
    if layout not in ("treadmill", "point_light"):
        raise StimuliError(f"display.layout: {layout} needs a factor with role 'alternatives'")
    body = body_of(protocol, stimulus.body_actor)
    motion_actor = stimulus.motion_actor or stimulus.body_actor
    rot, root, speed = actor_motion(protocol, motion_actor, gait_of(protocol, stimulus), body, look)
    return [Figure(body, rot, root, speed)]


def _labels(protocol, n: int) -> list[str]:
    labels = list(protocol.display.labels or [])
    return labels + [""] * (n - len(labels))


def _alternative_figure(protocol, stimulus, look, kind: str, level: str, label: str, motions_dir=None) -> Figure:
    """One of the figures shown side by side; ``kind`` is one of ``protocol.ALTERNATIVE_MOTIONS``
    (validation refuses any other mapping of an alternatives factor)."""
    body = body_of(protocol, stimulus.body_actor)
    gait = gait_of(protocol, stimulus)
    if kind == "method":
        rot, root, speed = method_motion(protocol, level, stimulus, gait, body, look, motions_dir)
    elif kind == "strength":  # thesis point-light: Table 4-1 at this body fat, per PARAMETER level
        from stimuli.render.thesis_sources import strength_motion

        rot, root, speed = strength_motion(protocol, stimulus, level, body, look)
    else:  # "source", thesis validation: the walk the SOURCE level's settings name
        from stimuli.render.thesis_sources import source_motion

        rot, root, speed = source_motion(protocol, stimulus, level, body, look)
    return Figure(body, rot, root, speed, label)


def actor_motion(protocol, actor_id: str, gait: str, body, look: Look):
    """An actor's walk or jog on ``body``'s rig: (rotations, root, belt speed) for the clip's frames.

    An actor that names a capture of the gait (``motions:``) shows that capture, looped from its
    steady straight range (its own cadence and speed: the belt runs at the capture's speed scaled
    to the body's legs). Otherwise the motion generator makes the actor's own gait (``params_for_actor``: protocol cadence and
    speed, the actor's anthropometric trends and individual style, seeded by the protocol), with
    the whole number of gait cycles closest to the clip's duration; it is then retargeted onto
    the shown body (Exp 1: swap shape, keep motion) and resampled to the clip's frames.
    """
    actor = next(a for a in protocol.actors if a.id == actor_id)
    if gait not in protocol.gaits:
        raise StimuliError(f"{protocol.name}: gaits.{gait} is not declared (cadence and speed are needed)")
    spec = protocol.gaits[gait]
    if gait in actor.motions:   # the actor's own capture of this gait, looped (stimuli.motion.captures)
        from stimuli.motion.captures import looped_capture

        motion = looped_capture(protocol, actor_id, gait)
    else:
        cycles = cycles_for_clip(look.duration_s, spec.cadence_spm)
        # Same belt speed for every body: the protocol's, whatever the legs and the loop's fit (timing.py)
        matched = belt_matched_speed(spec.speed_mps, spec.cadence_spm, cycles, float(look.fps), actor.height_m, body,
                                     look.n_frames / look.fps, look.loop)
        motion = _generated(actor.model_dump_json(), gait, spec.cadence_spm, matched, protocol.seed,
                            float(look.fps), cycles)
    on_body = on_rig(motion, body)
    rot, root, scale = fit_loop(on_body.rotations, on_body.root_translation, on_body.fps, look.n_frames, look.fps,
                                 look.loop)
    speed = float(on_body.metadata.get("belt_speed_mps", spec.speed_mps)) * scale
    return rot, root, speed


@functools.lru_cache(maxsize=16)
def _generated(actor_json: str, gait: str, cadence: float, speed: float, seed: int, fps: float, cycles: int):
    """The generator's looped treadmill gait for an actor (cached per process)."""
    from stimuli.motion.style import actor_gait
    from stimuli.protocol import Actor

    return actor_gait(Actor.model_validate_json(actor_json), gait, cadence, speed, seed, fps, cycles)


def on_rig(motion, body):
    """``motion`` on ``body``'s own Anny rig (unchanged when it is on that rig already; a motion on
    another body's rig, with the same joint names, is retargeted too)."""
    from stimuli.motion.retarget import is_on_rig, retarget

    if is_on_rig(motion, body):
        return motion

    return retarget(motion, body)


def _method_file(protocol, method: str, stimulus, gait: str, sex: str) -> str:
    """Where the physics step keeps the motion of METHOD level ``method``, relative to its output
    folder: the average (NoCOM) or the physics (COM) motion, as the level's setting says."""
    from stimuli.protocol import method_motion_of

    kind = method_motion_of(protocol.factor_mapped_to("method"), method)
    return f"nocom/{sex}_{gait}.npz" if kind == "average" else f"motions/COM_{stimulus.body_actor}_{gait}.npz"


def motion_files(protocol, stimulus, motions_dir=None) -> list:
    """The motion files a stimulus reads (part of its inputs hash): an actor's own capture, Exp 2's
    NoCOM/COM files, the thesis validation's ``bvh:`` captures."""
    from pathlib import Path

    alternatives = protocol.factors_with_role("alternatives")
    if alternatives and alternatives[0].maps_to == "source":
        from stimuli.render.thesis_sources import source_files

        return source_files(protocol, stimulus)
    if not alternatives:   # an actor's own capture (Exp 1 on captures): a changed file renders again
        from stimuli.motion.captures import capture_files

        return capture_files(protocol, stimulus.motion_actor or stimulus.body_actor, gait_of(protocol, stimulus))
    if motions_dir is None or not alternatives or alternatives[0].maps_to != "method":
        return []
    sex = next((a.sex for a in protocol.actors if a.id == stimulus.body_actor), "")
    gait = gait_of(protocol, stimulus)
    levels = stimulus.arrangement or alternatives[0].levels[:1]
    return [Path(motions_dir) / _method_file(protocol, m, stimulus, gait, sex) for m in levels]


def generator_seed(protocol, stimulus) -> int | None:
    """The protocol's seed when the stimulus shows the motion generator's gaits (part of its inputs
    hash: the seed draws each actor's individual style), else None (NoCOM/COM files, captures and
    the lean base walk do not depend on it, so another seed keeps those clips).

    >>> from stimuli.protocol import load_protocol
    >>> from stimuli.design import build_design
    >>> exp1 = load_protocol("protocols/exp1_shape_motion.yaml")
    >>> generator_seed(exp1, build_design(exp1).stimuli[0])
    2023
    """
    alternatives = protocol.factors_with_role("alternatives")
    if not alternatives:
        return protocol.seed   # actor_motion: the motion actor's generated walk or jog
    factor = protocol.factor_mapped_to("source")
    if alternatives[0].maps_to != "source" or factor is None:
        return None
    levels = stimulus.arrangement or factor.levels[:1]
    generated = any(str(factor.level_settings.get(level, {}).get("motion") or "") == "generator" for level in levels)
    return protocol.seed if generated else None


def method_motion(protocol, method: str, stimulus, gait: str, body, look: Look, motions_dir=None):
    """NoCOM: the sex × gait average motion; COM: that motion retargeted by physics onto the body.

    Both are read from the folder ``shapemotion physics protocol PROTOCOL --out DIR`` writes:
    ``DIR/nocom/<sex>_<gait>.npz`` and ``DIR/motions/COM_<actor>_<gait>.npz``.
    """
    from pathlib import Path

    sex = body.sex
    if motions_dir is None:
        # One message for every level: each clip fails on the same missing folder.
        raise MissingSource("the NoCOM/COM motions (maps_to: method) come from the physics step: run "
                            f"'shapemotion physics protocol {protocol.name}.yaml --out DIR' and render with "
                            "--motions DIR")
    name = _method_file(protocol, method, stimulus, gait, sex)
    path = Path(motions_dir) / name
    if not path.is_file():
        raise MissingSource(f"--motions {motions_dir}: {name} not found (METHOD = {method}, body "
                            f"{stimulus.body_actor}, {gait}); run 'shapemotion physics protocol' into that folder")
    actor = next(a for a in protocol.actors if a.id == stimulus.body_actor)
    stat = path.stat()
    on_body = _loaded_on_body(str(path.resolve()), stat.st_mtime_ns, stat.st_size, actor.model_dump_json())
    rot, root, scale = fit_loop(on_body.rotations, on_body.root_translation, on_body.fps, look.n_frames, look.fps,
                                 look.loop)
    spec = protocol.gaits.get(gait)
    speed = float(on_body.metadata.get("belt_speed_mps", spec.speed_mps if spec else 0.0)) * scale
    return rot, root, speed


@functools.lru_cache(maxsize=32)
def _loaded_on_body(path: str, mtime_ns: int, size: int, actor_json: str):
    """A motion file retargeted onto an actor's body (cached per process: Exp 2's NoCOM_COM and
    COM_NoCOM clips of a condition show the same two; the file's time and size key a rewritten file)."""
    from stimuli.motion import Motion

    return on_rig(Motion.load(path), _body(actor_json))
