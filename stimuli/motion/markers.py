"""The 15-marker point-light set (SPEC §1.3; Johansson-style, as in the thesis's surveys).

Markers: hips, left/right upper leg (hip joints), knees, heels, shoulders, elbows, wrists, torso,
head. Trajectories come from any motion with joint roles; heels are the heel sole points.

Examples
--------
>>> len(MARKERS)
15
"""

from __future__ import annotations

import numpy as np

from stimuli.motion.footfix import sole_points, sole_positions
from stimuli.motion.skeleton import role_indices

MARKERS = ["hips", "l_upper_leg", "r_upper_leg", "l_knee", "r_knee", "l_heel", "r_heel", "l_shoulder",
           "r_shoulder", "l_elbow", "r_elbow", "l_wrist", "r_wrist", "torso", "head"]
_FROM_ROLE = {"hips": "pelvis", "l_upper_leg": "l_hip", "r_upper_leg": "r_hip", "l_knee": "l_knee",
              "r_knee": "r_knee", "l_shoulder": "l_shoulder", "r_shoulder": "r_shoulder", "l_elbow": "l_elbow",
              "r_elbow": "r_elbow", "l_wrist": "l_wrist", "r_wrist": "r_wrist", "torso": "chest", "head": "head"}


def marker_trajectories(motion, points: dict | None = None) -> np.ndarray:
    """T×15×3 marker positions (metres, project frame), in the order of MARKERS."""
    roles = role_indices(motion)
    grot, gpos = motion.global_transforms()
    feet = sole_points(motion) if points is None else points
    out = np.zeros((motion.n_frames, len(MARKERS), 3))
    for k, name in enumerate(MARKERS):
        if name.endswith("_heel"):
            s = name[0]
            out[:, k] = sole_positions(grot, gpos, feet[s][:1])[:, 0]
            out[:, k, 1] += 0.03  # a heel marker sits on the back of the shoe, above the sole
        else:
            role = _FROM_ROLE[name]
            if role == "chest" and role not in roles:
                role = "spine"
            out[:, k] = gpos[:, roles[role]]
    return out


def write_markers_csv(motion, path, points: dict | None = None):
    """Markers as a long CSV: frame, time_s, marker, x, y, z."""
    import pandas as pd

    tr = marker_trajectories(motion, points)
    t, m = np.meshgrid(np.arange(motion.n_frames), np.arange(len(MARKERS)), indexing="ij")
    df = pd.DataFrame({"frame": t.ravel(), "time_s": (t.ravel() / motion.fps).round(6),
                       "marker": np.array(MARKERS)[m.ravel()], "x": tr[..., 0].ravel().round(6),
                       "y": tr[..., 1].ravel().round(6), "z": tr[..., 2].ravel().round(6)})
    df.to_csv(path, index=False)
    return path
