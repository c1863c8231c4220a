"""The reference motion as ragdoll targets: segment rotations, joint angles and root path.

Any motion whose joint roles are known (``stimuli.motion.skeleton``: the Anny rig, CMU, Mixamo,
SMPL, …) can drive the ragdoll. Each ragdoll segment follows one bone of the motion (the bone
that spans it, e.g. the thigh follows the bone whose child is the knee). Where the motion's rest
pose differs from the body's (a T-pose BVH against Anny's A-pose), a constant rest alignment
``A`` (the smallest rotation taking the ragdoll's rest segment direction onto the motion's) is
applied: target global rotation ``R = G_motion · A``; on an Anny-rig motion ``A`` is the identity.

The root target is the pelvis body's origin, placed so that the ragdoll's hip centre follows the
motion's hip centre scaled by the ratio of leg lengths (body / motion). Treadmill motions (the
project's clips) get the belt's forward progression back for the simulation, on a fixed floor.
All targets are periodic cubic splines over the looped clip, so any simulation time can be sampled.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.interpolate import CubicSpline

from stimuli.errors import StimuliError
from stimuli.motion import quat
from stimuli.motion.skeleton import role_indices

# Ragdoll segment → (bone it follows, given as a role or "parent:<role>"; direction from, to).
SEGMENT_BONES = {
    "pelvis": ("pelvis", None, None),
    "spine": ("spine", "spine", "neck"),
    "head": ("head", "neck", "head"),
    "upper_arm.{s}": ("parent:{s}_elbow", "{s}_shoulder", "{s}_elbow"),
    "lower_arm.{s}": ("{s}_elbow", "{s}_elbow", "{s}_wrist"),
    "upper_leg.{s}": ("parent:{s}_knee", "{s}_hip", "{s}_knee"),
    "lower_leg.{s}": ("{s}_knee", "{s}_knee", "{s}_ankle"),
    "foot.{s}": ("{s}_ankle", "{s}_ankle", "{s}_toe"),
}
# Ragdoll side letters → role side prefixes.
SIDE = {"L": "l", "R": "r"}


def _expand(table: dict) -> dict:
    out = {}
    for key, vals in table.items():
        if "{s}" in key:
            for s, r in SIDE.items():
                out[key.format(s=s)] = tuple(v.format(s=r) if v else v for v in vals)
        else:
            out[key] = vals
    return out


def _bone(motion, roles: dict[str, int], spec: str) -> int:
    if spec.startswith("parent:"):
        return int(motion.parents[roles[spec[7:]]])
    return roles[spec]


def _rest_direction(positions: np.ndarray, roles: dict[str, int], a: str, b: str) -> np.ndarray:
    return positions[roles[b]] - positions[roles[a]]


def ragdoll_rest_directions(body) -> dict[str, np.ndarray]:
    """Rest direction (proximal → distal) of each ragdoll segment of a fitted body."""
    return {s.label: np.asarray(s.distal - s.proximal, float) for s in body.segments}


def segment_rotations(motion, body) -> tuple[dict[str, np.ndarray], dict[str, int], dict[str, np.ndarray]]:
    """Target world rotations (T×4, w-first) of the ragdoll segments, the motion bone of each and ``A``.

    StimuliError naming the missing roles when the motion lacks a bone the ragdoll needs.
    """
    roles = role_indices(motion)
    table = _expand(SEGMENT_BONES)
    needed = {r[7:] if r.startswith("parent:") else r for v in table.values() for r in v if r}
    missing = sorted(needed - set(roles))
    if missing:
        raise StimuliError(f"motion {motion.metadata.get('source', '')!s}: the ragdoll needs joint role(s) "
                           f"{', '.join(missing)}; joints are {', '.join(motion.joint_names)}")
    grot, _ = motion.global_transforms()
    grot = quat.unroll(grot)
    rest = motion.rest_positions()
    body_dirs = ragdoll_rest_directions(body)
    rotations, bones, align = {}, {}, {}
    for label, (bone_spec, a, b) in table.items():
        j = _bone(motion, roles, bone_spec)
        if a is None:
            al = np.array([1.0, 0, 0, 0])
        else:
            al = quat.between(body_dirs[label], _rest_direction(rest, roles, a, b))
        rotations[label] = quat.unroll(quat.mul(grot[:, j], al))
        bones[label] = j
        align[label] = al
    return rotations, bones, align


def relative_rotation(rotations: dict[str, np.ndarray], child: str, parent: str) -> np.ndarray:
    """Rotation of ``child`` relative to ``parent`` (T×4)."""
    return quat.unroll(quat.mul(quat.inv(rotations[parent]), rotations[child]))


def hinge_axis(rel: np.ndarray) -> np.ndarray:
    """Dominant rotation axis of a relative rotation over time (principal direction of its rotation
    vectors), signed so that the mean angle about it is positive (flexion positive)."""
    rv = quat.to_axis_angle(rel)
    if np.abs(rv).max() < 1e-6:
        return np.array([1.0, 0.0, 0.0])
    _, _, vt = np.linalg.svd(rv, full_matrices=False)
    axis = vt[0]
    return axis if (rv @ axis).mean() >= 0 else -axis


def twist_angle(rel: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Angle (rad) of the twist of ``rel`` about ``axis`` (swing–twist decomposition), unwrapped."""
    rel = quat.unroll(rel)
    return np.unwrap(2.0 * np.arctan2(rel[:, 1:] @ axis, rel[:, 0]))


def euler_angles(rel: np.ndarray, order: str) -> np.ndarray:
    """Intrinsic Euler angles (T×3, rad, unwrapped) matching MuJoCo's chained hinges in ``order``."""
    return np.unwrap(quat.to_euler(rel, order, degrees=False), axis=0)


def leg_length(points: dict[str, np.ndarray]) -> float:
    """Hip–knee plus knee–ankle length (left side)."""
    return float(np.linalg.norm(points["hip"] - points["knee"]) + np.linalg.norm(points["knee"] - points["ankle"]))


@dataclasses.dataclass
class Reference:
    """Ragdoll targets at the motion's frames plus periodic splines to sample them at any time."""

    fps: float
    dof_names: list[str]
    q: np.ndarray
    root_pos: np.ndarray
    root_quat: np.ndarray
    belt_speed: float
    scale: float
    rotations: dict[str, np.ndarray]
    bones: dict[str, int]
    align: dict[str, np.ndarray]

    def __post_init__(self) -> None:
        n = self.q.shape[0]
        self.period = n / self.fps
        t = np.arange(n + 1) / self.fps
        self._q = CubicSpline(t, np.vstack([self.q, self.q[:1]]), bc_type="periodic")
        self._root = CubicSpline(t, np.vstack([self.root_pos, self.root_pos[:1]]), bc_type="periodic")
        # Root orientation as a rotation vector about its mean: small angles, smooth to spline.
        self._mean_root = quat.mean(self.root_quat)
        rv = quat.to_axis_angle(quat.mul(quat.inv(self._mean_root), quat.unroll(self.root_quat)))
        self._rootrot = CubicSpline(t, np.vstack([rv, rv[:1]]), bc_type="periodic")

    @property
    def n_frames(self) -> int:
        return int(self.q.shape[0])

    def sample(self, t: np.ndarray) -> dict[str, np.ndarray]:
        """Targets at times ``t`` (s, any real; the clip repeats): q, qd, root pos/vel (with belt
        progression along +z), root quat and world angular velocity."""
        t = np.asarray(t, float)
        tm = np.mod(t, self.period)
        pos = self._root(tm)
        vel = self._root(tm, 1)
        pos[..., 2] += self.belt_speed * t
        vel[..., 2] += self.belt_speed
        rv = self._rootrot(tm)
        rq = quat.mul(self._mean_root, quat.from_axis_angle(rv))
        # Angular velocity: finite difference of the spline (world frame, rad/s).
        h = 1e-4
        rq2 = quat.mul(self._mean_root, quat.from_axis_angle(self._rootrot(np.mod(tm + h, self.period))))
        omega = quat.to_axis_angle(quat.mul(rq2, quat.inv(rq))) / h
        return {"q": self._q(tm), "qd": self._q(tm, 1), "root_pos": pos, "root_vel": vel,
                "root_quat": rq, "root_omega": omega}


def build_reference(motion, body, ragdoll_factory) -> tuple[Reference, object]:
    """Targets of ``motion`` for the ragdoll of ``body``; returns (Reference, Ragdoll).

    ``ragdoll_factory(hinge_axes)`` builds the ragdoll once the elbow/knee axes are known (they
    are the motion's own dominant axes, so a hinge can follow the reference exactly).
    """
    from stimuli.motion.loop import to_treadmill

    if not motion.metadata.get("treadmill"):
        motion = to_treadmill(motion)
    rotations, bones, align = segment_rotations(motion, body)
    axes = {}
    for label in ("lower_arm.L", "lower_arm.R", "lower_leg.L", "lower_leg.R"):
        parent = label.replace("lower", "upper")
        axes[label] = hinge_axis(relative_rotation(rotations, label, parent))
    ragdoll = ragdoll_factory(axes)
    cols = []
    for link in ragdoll.links:
        if link.kind == "ball":
            cols.append(euler_angles(relative_rotation(rotations, link.label, link.parent), link.euler))
        elif link.kind == "hinge":
            cols.append(twist_angle(relative_rotation(rotations, link.label, link.parent), link.hinge_axis)[:, None])
    q = np.hstack(cols)
    roles = role_indices(motion)
    rest = motion.rest_positions()
    seg = {s.label: s for s in body.segments}
    body_leg = leg_length({"hip": seg["upper_leg.L"].proximal, "knee": seg["upper_leg.L"].distal,
                           "ankle": seg["lower_leg.L"].distal})
    motion_leg = leg_length({k: rest[roles[f"l_{k}"]] for k in ("hip", "knee", "ankle")})
    scale = body_leg / motion_leg
    pos = motion.positions()
    hip_centre = 0.5 * (pos[:, roles["l_hip"]] + pos[:, roles["r_hip"]]) * scale
    pelvis = ragdoll.link("pelvis").anchor
    body_hip_centre = 0.5 * (seg["upper_leg.L"].proximal + seg["upper_leg.R"].proximal)
    root_pos = hip_centre + quat.rotate(rotations["pelvis"], pelvis - body_hip_centre)
    belt = float(motion.metadata.get("belt_speed_mps", 0.0)) * scale
    ref = Reference(float(motion.fps), ragdoll.dof_names, q, root_pos, rotations["pelvis"], belt, float(scale),
                    rotations, bones, align)
    return ref, ragdoll
