"""A simple stepping-in-place pose sequence computed from joint rotations on a body's own rig.

Not a stimulus motion (stimuli come from :mod:`stimuli.motion`): it exercises the renderer —
tests and the benchmark use it so that they do not depend on motion capture or retargeting.
Hips, knees, shoulders and elbows swing sinusoidally about the body's lateral axis (+x), the
root bobs, and the whole pose repeats ``cycles`` times over ``n_frames`` (a seamless loop).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

# (bone, amplitude°, phase in cycles, offset°): about +x, negative = swing forward (+z).
SWINGS = (
    ("upperleg01.L", 22.0, 0.0, -8.0), ("upperleg01.R", 22.0, 0.5, -8.0),
    ("lowerleg01.L", 25.0, 0.2, 30.0), ("lowerleg01.R", 25.0, 0.7, 30.0),
    ("upperarm01.L", 18.0, 0.5, 0.0), ("upperarm01.R", 18.0, 0.0, 0.0),
    ("lowerarm01.L", 10.0, 0.45, -15.0), ("lowerarm01.R", 10.0, 0.95, -15.0),
)


def stepping_pose(body, n_frames: int, cycles: int = 2, amplitude: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations (T, J, 4) w-first and root translation (T, 3) for ``body.rig``.

    ``amplitude`` scales every swing (0 = standing still in a relaxed pose).
    """
    rig = body.rig
    phase = np.arange(n_frames) / n_frames * cycles
    rotations = np.zeros((n_frames, rig.n_bones, 4))
    rotations[..., 0] = 1.0
    for bone, swing, shift, offset in SWINGS:
        angle = np.radians(offset + amplitude * swing * np.sin(2 * np.pi * (phase + shift)))
        xyzw = Rotation.from_rotvec(np.outer(angle, [1.0, 0.0, 0.0])).as_quat()
        rotations[:, rig.index(bone)] = xyzw[:, [3, 0, 1, 2]]
    root = np.repeat(rig.rest_heads[:1], n_frames, axis=0)
    # Bent knees shorten the legs; lower the pelvis so the feet stay near the ground.
    root[:, 1] += -0.04 + 0.015 * amplitude * np.cos(4 * np.pi * phase)
    return rotations, root


def procedural_figures(protocol, stimulus, look):
    """Figures for a stimulus with the protocol's real bodies and :func:`stepping_pose` motion.

    For checking layout, framing and the pipeline before motions exist: alternative k (screen
    order of ``stimulus.arrangement`` mapped back to the factor's declared levels) steps with
    amplitude 1 / (1 + k), so the first declared level moves most.
    """
    from stimuli.render.clip import Figure
    from stimuli.render.sources import _labels, body_of

    body = body_of(protocol, stimulus.body_actor)
    alternatives = protocol.factors_with_role("alternatives")
    levels = alternatives[0].levels if alternatives else []
    slots = stimulus.arrangement or ("",)
    labels = _labels(protocol, len(slots)) if alternatives else [""]
    figures = []
    for level, label in zip(slots, labels):
        amplitude = 1.0 / (1 + levels.index(level)) if level else 1.0
        rot, root = stepping_pose(body, look.n_frames, cycles=max(1, int(round(look.duration_s))), amplitude=amplitude)
        figures.append(Figure(body, rot, root, belt_speed_mps=0.0, label=label))
    return figures
