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
# Each followed segment's parent segment (rest alignments are chained down these).
SEGMENT_PARENT = {"spine": "pelvis", "head": "spine", "upper_arm": "spine", "lower_arm": "upper_arm",
                  "upper_leg": "pelvis", "lower_leg": "upper_leg", "foot": "lower_leg"}
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


# A motion bone further than this from its ragdoll segment's direction at rest is "flipped".
FLIPPED_BONE_DEG = 90.0


def _angle_deg(u: np.ndarray, v: np.ndarray) -> float:
    c = float(np.dot(u, v) / (np.linalg.norm(u) * np.linalg.norm(v)))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def parent_segment(label: str) -> str:
    """The ragdoll segment ``label`` hangs from (:data:`SEGMENT_PARENT`), with its side.

    >>> parent_segment("lower_leg.L"), parent_segment("upper_leg.R"), parent_segment("head")
    ('upper_leg.L', 'pelvis', 'spine')
    """
    base, dot, side = label.partition(".")
    parent = SEGMENT_PARENT[base]
    return parent + dot + side if parent in ("upper_arm", "lower_leg", "upper_leg") else parent


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
    frame = rest_frame_rotation(body, rest, roles)
    for label, (bone_spec, a, b) in table.items():
        j = _bone(motion, roles, bone_spec)
        if a is None:
            al = frame
        else:
            direction = quat.rotate(quat.inv(frame), _rest_direction(rest, roles, a, b))
            up = frame
            if _angle_deg(body_dirs[label], direction) > FLIPPED_BONE_DEG:
                # A bone pointing the other way at rest (the CC4 rig's BVHs: thigh and shank both
                # point up) is aligned inside its parent segment's alignment: two unrelated
                # half-turns gave the knee 150° of twist that its hinge cannot follow (the knee
                # stayed straight and the walk flew). Bones near their body direction keep the
                # shortest rotation (chaining them too changed CMU 35_01's flight from 9 to 14 %).
                up = align[parent_segment(label)]
                direction = quat.rotate(quat.inv(up), _rest_direction(rest, roles, a, b))
            al = quat.mul(up, quat.between(body_dirs[label], direction))
        rotations[label] = quat.unroll(quat.mul(grot[:, j], al))
        bones[label] = j
        align[label] = al
    for s, r in SIDE.items():
        # The toes follow the toe bone, aligned as their foot: a toe bone has no distal joint of
        # its own to take a direction from in many rigs (End Sites), and it lies along the foot at
        # rest. A toe-less rig's toe is its ankle's End Site, which turns with the ankle: toes straight.
        j = roles[f"{r}_toe"]
        rotations[f"toes.{s}"] = quat.unroll(quat.mul(grot[:, j], align[f"foot.{s}"]))
        bones[f"toes.{s}"] = j
        align[f"toes.{s}"] = align[f"foot.{s}"]
    return rotations, bones, align


# A capture whose rest pose is turned this far from the body's (pelvis up and left-right axes) was
# stored in another frame (the Bandai BVHs' rest pose lies on its side, spine along +x, while
# they walk upright); below it the difference is the actor's own rest posture and is kept.
REST_FRAME_TURN_DEG = 45.0


def rest_frame_rotation(body, rest: np.ndarray, roles: dict[str, int]) -> np.ndarray:
    """Rotation (w-first) taking the body's rest pelvis frame onto the motion's, or the identity.

    Frames from the hip centre → spine direction (up) and right → left hip (lateral). Each
    segment's rest alignment is then taken inside this frame, so a rest pose lying on its side
    gets its twist right too (the shortest rotation between two bone directions alone would not).
    """
    seg = {s.label: s for s in body.segments}
    b_hips = (np.asarray(seg["upper_leg.L"].proximal, float), np.asarray(seg["upper_leg.R"].proximal, float))
    b_up = np.asarray(seg["spine"].proximal, float) - 0.5 * (b_hips[0] + b_hips[1])
    m_hips = rest[roles["l_hip"]], rest[roles["r_hip"]]
    m_up = rest[roles["spine"]] - 0.5 * (m_hips[0] + m_hips[1])
    fb = _frame(b_up, b_hips[0] - b_hips[1])
    fm = _frame(m_up, m_hips[0] - m_hips[1])
    q = _quat_from_matrix(fm @ fb.T)
    if np.degrees(float(quat.angle(q))) < REST_FRAME_TURN_DEG:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return q


def _frame(up: np.ndarray, lateral: np.ndarray) -> np.ndarray:
    """Orthonormal columns (lateral, up, forward) from an up and a lateral direction."""
    y = up / np.linalg.norm(up)
    x = lateral - (lateral @ y) * y
    x /= np.linalg.norm(x)
    return np.stack([x, y, np.cross(x, y)], axis=1)


def _quat_from_matrix(m: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(m).as_quat()
    return np.array([w, x, y, z])


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
    grounded: bool = False       # the floor is in root_pos already (stimuli.physics.toes)

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
    labels = {link.label for link in ragdoll.links}
    rotations, bones, align = ({k: v for k, v in d.items() if k in labels} for d in (rotations, bones, align))
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
