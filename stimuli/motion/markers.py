"""The 15-marker point-light set (SPEC §1.3; Johansson-style, as in the thesis's surveys): the one
definition, used for the CSV of ``shapemotion motion markers`` and the dots the clips draw
(:mod:`stimuli.render.pointlight`).

Markers: hips (pelvis), left/right upper leg (mid-thigh, halfway from hip to knee), knees, heels
(the back of the heel 3 cm above the sole, carried by the foot), shoulders, elbows, wrists, torso
(chest) and head (the middle of the head). On a body's Anny rig (:func:`body_markers`) the head is
the middle of the head bone and the heel the back of the body's rest mesh — the dots a clip of that
body shows; on any other skeleton the head is halfway to the head's end joint and the heel is the
heel sole point of :func:`~stimuli.motion.footfix.sole_points`.

Examples
--------
>>> len(MARKERS)
15
"""

from __future__ import annotations

import numpy as np

from stimuli.errors import StimuliError
from stimuli.motion import quat
from stimuli.motion.footfix import sole_points
from stimuli.motion.skeleton import NAMINGS, role_indices

MARKERS = ["hips", "l_upper_leg", "r_upper_leg", "l_knee", "r_knee", "l_heel", "r_heel", "l_shoulder",
           "r_shoulder", "l_elbow", "r_elbow", "l_wrist", "r_wrist", "torso", "head"]
HEEL_HEIGHT_M = 0.03  # a heel marker sits on the back of the shoe, above the sole
_ROLES = ("pelvis", "chest", "head") + tuple(f"{s}_{r}" for s in "lr"
                                             for r in ("hip", "knee", "ankle", "shoulder", "elbow", "wrist"))


def _place(carry, idx: dict, head_half: np.ndarray, heel: dict) -> np.ndarray:
    """T×15×3 markers in the order of MARKERS. ``carry(j, v)``: world positions (T×3) of joint
    ``j`` plus its rest-frame vector ``v`` turned with it (``v`` None: the joint itself); ``idx``:
    role → joint; ``head_half``: the head joint to the middle of the head; ``heel``: per side, the
    ankle to the heel marker (rest)."""
    at = {role: carry(idx[role], None) for role in _ROLES if role != "head"}
    out = {"hips": at["pelvis"], "torso": at["chest"], "head": carry(idx["head"], head_half)}
    for s in "lr":
        for part in ("knee", "shoulder", "elbow", "wrist"):
            out[f"{s}_{part}"] = at[f"{s}_{part}"]
        out[f"{s}_upper_leg"] = 0.5 * (at[f"{s}_hip"] + at[f"{s}_knee"])
        out[f"{s}_heel"] = carry(idx[f"{s}_ankle"], heel[s])
    return np.stack([out[name] for name in MARKERS], axis=1)


def _heel_offset(body, side: str) -> np.ndarray:
    """Rest vector from the ankle (foot bone head) to the back of the heel, 3 cm above the sole."""
    rig = body.rig
    ankle = rig.rest_heads[rig.index(f"foot.{side}")]
    v = body.vertices
    near = (np.abs(v[:, 0] - ankle[0]) < 0.035) & (v[:, 1] < ankle[1])
    back = v[near][np.argmin(v[near][:, 2])]
    return np.array([back[0], HEEL_HEIGHT_M, back[2]]) - ankle


def body_markers(body, rotations: np.ndarray, root_translation: np.ndarray) -> np.ndarray:
    """T×15×3 markers of poses on ``body``'s own Anny rig (``Body.skin`` semantics)."""
    rig = body.rig
    glob, heads = rig.forward_kinematics(rotations, root_translation)
    idx = {role: rig.index(NAMINGS["anny"][role][0]) for role in _ROLES}
    head = idx["head"]

    def carry(j, v):
        return heads[:, j] if v is None else heads[:, j] + glob[:, j] @ v

    return _place(carry, idx, 0.5 * (rig.rest_tails[head] - rig.rest_heads[head]),
                  {s: _heel_offset(body, s.upper()) for s in "lr"})


def skeleton_markers(motion) -> np.ndarray:
    """T×15×3 markers of a motion on any skeleton with joint roles (no body)."""
    idx = role_indices(motion)
    if "chest" not in idx and "spine" in idx:
        idx["chest"] = idx["spine"]
    missing = [r for r in _ROLES if r not in idx]
    if missing:
        raise StimuliError(f"markers: the skeleton has no joint for {', '.join(missing)} (name them in a mapping file)")
    rest = motion.rest_positions()
    head = idx["head"]
    ends = motion.children(head)
    # Without a joint above the head (AMASS's SMPL tree), one neck-to-head length above it.
    top = rest[ends[0]] if ends else 2 * rest[head] - rest[motion.parents[head]]
    feet = sole_points(motion)
    grot, gpos = motion.global_transforms()

    def carry(j, v):
        return gpos[:, j] if v is None else gpos[:, j] + quat.rotate(grot[:, j], v)

    return _place(carry, idx, 0.5 * (top - rest[head]),
                  {s: feet[s][0][1] + np.array([0.0, HEEL_HEIGHT_M, 0.0]) for s in "lr"})


def marker_trajectories(motion, body=None) -> np.ndarray:
    """T×15×3 marker positions (metres, project frame), in the order of MARKERS: with ``body``, the
    motion must be on that body's rig and the markers are the dots its clips draw."""
    if body is None:
        return skeleton_markers(motion)
    from stimuli.motion.retarget import is_on_rig

    if not is_on_rig(motion, body):
        raise StimuliError("markers: the motion is not on the body's rig; retarget it onto the body first")
    return body_markers(body, motion.rotations, motion.root_translation)


def write_markers_csv(motion, path, body=None):
    """Markers as a long CSV: frame, time_s, marker, x, y, z."""
    import pandas as pd

    from stimuli.fileio import atomic_write_text

    tr = marker_trajectories(motion, body)
    t, m = np.meshgrid(np.arange(motion.n_frames), np.arange(len(MARKERS)), indexing="ij")
    df = pd.DataFrame({"frame": t.ravel(), "time_s": (t.ravel() / motion.fps).round(6),
                       "marker": np.array(MARKERS)[m.ravel()], "x": tr[..., 0].ravel().round(6),
                       "y": tr[..., 1].ravel().round(6), "z": tr[..., 2].ravel().round(6)})
    atomic_write_text(path, df.to_csv(index=False))   # creates the folder; never a half-written file
    return path
