"""What each stimulus shows: its bodies and their motions, as :class:`~stimuli.render.clip.Figure` s.

The protocol's ``maps_to`` fields decide: ``body`` → whose body (``Stimulus.body_actor``),
``motion`` → whose motion (``Stimulus.motion_actor``), ``gait`` → walk/jog, ``method`` → NoCOM
(the sex × gait average motion) or COM (that motion retargeted by physics onto the body),
``strength`` → the thesis modifier at a body-fat level, ``source`` → the thesis validation walks.
Where a motion source is not available yet, :class:`MissingSource` (a ``StimuliError``) names it.

Every motion is a seamless loop; :func:`fit_loop` resamples it so that a whole number of loops
fills the clip exactly (duration × fps frames), scaling time — and the belt speed — slightly when
the loop length does not divide the clip.
"""

from __future__ import annotations

import functools

import numpy as np

from stimuli.errors import StimuliError
from stimuli.render.clip import Figure, Look


class MissingSource(StimuliError):
    """A stimulus needs a motion source that shapemotion does not provide (yet)."""


def fit_loop(rotations: np.ndarray, root: np.ndarray, fps: float, n_frames: int, clip_fps: float):
    """Resample a looping pose sequence to ``n_frames`` at ``clip_fps`` holding whole loops.

    Returns (rotations (N, J, 4), root (N, 3), time_scale) where time_scale > 1 means the motion
    plays faster than recorded (multiply its speed by it).

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
    scale = loops * loop_s / clip_s
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
    factor = protocol.factor_mapped_to("gait")
    if factor is None:
        return "walk"
    return stimulus.levels[factor.name]


def protocol_figures(protocol, stimulus, look: Look) -> list[Figure]:
    """The figures of one stimulus from the protocol's real motion sources."""
    layout = protocol.display.layout
    alternatives = protocol.factors_with_role("alternatives")
    if alternatives:
        kind = alternatives[0].maps_to
        return [_alternative_figure(protocol, stimulus, look, kind, level, label)
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


def _alternative_figure(protocol, stimulus, look, kind: str, level: str, label: str) -> Figure:
    body = body_of(protocol, stimulus.body_actor)
    gait = gait_of(protocol, stimulus)
    if kind == "method":
        rot, root, speed = method_motion(protocol, level, stimulus, gait, body, look)
    else:
        raise MissingSource(
            f"{protocol.name}: stimulus {stimulus.stimulus_id} needs motions for {kind} = {level!r} "
            f"(the thesis modifier / validation walks of stimuli.motion), which are not available yet")
    return Figure(body, rot, root, speed, label)


def actor_motion(protocol, actor_id: str, gait: str, body, look: Look):
    """An actor's walk or jog on ``body``'s rig: (rotations, root, belt speed) for the clip's frames."""
    raise MissingSource(
        f"{protocol.name}: the motion of actor {actor_id} ({gait}) on body {body.body_id} needs the motion "
        "generator's output retargeted onto the Anny rig (stimuli.motion), which is not available yet")


def method_motion(protocol, method: str, stimulus, gait: str, body, look: Look):
    """NoCOM: the sex × gait average motion; COM: that motion retargeted by physics onto the body."""
    what = "the sex × gait DTW average motion (stimuli.motion)" if method == "NoCOM" else \
        "the physics-retargeted COM motion (stimuli.physics) of the average motion"
    raise MissingSource(f"{protocol.name}: stimulus {stimulus.stimulus_id} needs {what} on the Anny rig, "
                        "which is not available to the renderer yet")
