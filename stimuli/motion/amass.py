"""AMASS / SMPL-family ``.npz`` import without SMPL model files.

AMASS files hold ``poses`` (T×3N axis-angle, body joints first: 22 for SMPL-H/SMPL-X bodies, 24
for SMPL), ``trans`` (T×3), ``mocap_framerate`` (or ``mocap_frame_rate``), ``betas``, ``gender``.
The SMPL kinematic tree is public; the rest joint positions below are those of the mean SMPL
body (Loper et al. 2015), rounded to millimetres, which is all a skeleton needs: the shape
(``betas``) only shifts joints by a few centimetres and is not applied (scale with ``height_m``).
AMASS worlds are z-up; the motion is turned to the project's y-up frame.

Examples
--------
>>> len(SMPL_JOINTS), int(SMPL_PARENTS[4])
(22, 1)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from stimuli.errors import StimuliError
from stimuli.motion import quat
from stimuli.motion.loop import rotate_world
from stimuli.motion.motion import Motion
from stimuli.motion.skeleton import detect_roles

SMPL_JOINTS = ["pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2",
               "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar",
               "right_collar", "head", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
               "left_wrist", "right_wrist"]
SMPL_PARENTS = np.array([-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19])
# Rest joint positions of the mean SMPL body (metres, SMPL's own y-up frame, +x = body left).
SMPL_REST = np.array([
    [-0.002, -0.223, 0.028], [0.070, -0.314, 0.024], [-0.068, -0.315, 0.022], [-0.003, -0.104, 0.002],
    [0.104, -0.690, 0.017], [-0.105, -0.694, 0.015], [0.006, 0.028, 0.002], [0.088, -1.087, -0.028],
    [-0.088, -1.095, -0.025], [0.004, 0.082, 0.031], [0.123, -1.143, 0.097], [-0.118, -1.144, 0.103],
    [-0.002, 0.291, -0.013], [0.079, 0.197, -0.003], [-0.076, 0.198, -0.005], [0.005, 0.352, 0.038],
    [0.171, 0.225, -0.017], [-0.172, 0.226, -0.019], [0.419, 0.209, -0.040], [-0.417, 0.211, -0.040],
    [0.676, 0.222, -0.041], [-0.674, 0.222, -0.042],
])
SMPL_STATURE_M = 1.70  # approximate standing height of the mean body the rest joints come from


def smpl_offsets(scale: float = 1.0) -> np.ndarray:
    """Parent-relative rest offsets of the 22 SMPL body joints."""
    off = SMPL_REST.copy()
    off[1:] = SMPL_REST[1:] - SMPL_REST[SMPL_PARENTS[1:]]
    off[0] = 0.0
    return off * scale


def _field(data, path: Path, *names: str):
    for n in names:
        if n in data.files:
            return data[n]
    raise StimuliError(f"{path}: missing field {' or '.join(names)} (AMASS .npz needs poses, trans, mocap_framerate)")


def read_amass(path: str | Path, height_m: float | None = None, z_up: bool = True) -> Motion:
    """Import an AMASS/SMPL-H/SMPL-X ``.npz`` as a Motion on the SMPL body skeleton (22 joints)."""
    path = Path(path)
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise StimuliError(f"{path}: not a readable .npz file ({exc})") from None
    poses = np.asarray(_field(data, path, "poses"), float)
    trans = np.asarray(_field(data, path, "trans"), float)
    fps = float(_field(data, path, "mocap_framerate", "mocap_frame_rate"))
    if poses.ndim != 2 or poses.shape[1] < 66 or poses.shape[1] % 3:
        raise StimuliError(f"{path}: poses must be T×(3·joints) with at least 22 joints, got {poses.shape}")
    if trans.shape != (poses.shape[0], 3):
        raise StimuliError(f"{path}: trans must be {poses.shape[0]}×3, got {trans.shape}")
    if not (np.all(np.isfinite(poses)) and np.all(np.isfinite(trans))):
        raise StimuliError(f"{path}: poses/trans contain NaN or inf")
    scale = 1.0 if height_m is None else height_m / SMPL_STATURE_M
    rot = quat.from_axis_angle(poses[:, :66].reshape(-1, 22, 3))
    # SMPL places the pelvis joint at trans + J_pelvis(rest), then rotates about it.
    root = trans + SMPL_REST[0] * scale
    gender = str(data["gender"]) if "gender" in data.files else "unknown"
    names = list(SMPL_JOINTS)
    motion = Motion(fps=fps, joint_names=names, parents=SMPL_PARENTS, offsets=smpl_offsets(scale),
                    rotations=rot, root_translation=root,
                    metadata={"source": f"amass:{path.name}", "gender": gender, "naming": "smpl",
                              "roles": detect_roles(names)["roles"], "source_height_m": SMPL_STATURE_M * scale})
    if z_up:
        # AMASS world: z up. Rotating −90° about x takes +z to +y.
        motion = rotate_world(motion, quat.from_axis_angle(np.array([-np.pi / 2, 0.0, 0.0])))
    return motion


def write_amass(motion: Motion, path: str | Path) -> Path:
    """Write a SMPL-skeleton motion back to an AMASS-style ``.npz`` (z-up world), for round trips."""
    if motion.joint_names != SMPL_JOINTS:
        raise StimuliError("write_amass: the motion must be on the 22-joint SMPL skeleton")
    m = rotate_world(motion, quat.from_axis_angle(np.array([np.pi / 2, 0.0, 0.0])))
    scale = motion.metadata.get("source_height_m", SMPL_STATURE_M) / SMPL_STATURE_M
    poses = np.concatenate([quat.to_axis_angle(m.rotations).reshape(m.n_frames, -1),
                            np.zeros((m.n_frames, 156 - 66))], axis=1)
    np.savez(path, poses=poses, trans=m.root_translation - SMPL_REST[0] * scale,
             mocap_framerate=np.float64(m.fps), betas=np.zeros(16), gender=np.array("neutral"))
    return Path(path)
