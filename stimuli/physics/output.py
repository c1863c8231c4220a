"""Simulated ragdoll → Motion (the ``.npz`` contract), looped, on the reference motion's skeleton.

Each ragdoll segment gives the world rotation of the motion bone it follows (``S · A⁻¹``, undoing
the rest alignment of :mod:`stimuli.physics.reference`); the other bones keep their reference local
rotations, so fingers, toes and twist bones move as in the reference. When the motion is on the
body's own rig (Anny bone names), offsets and root translation are the target body's; otherwise
the root is placed so the motion's hip centre follows the simulated one, in the motion's scale.
The belt progression added for the simulation is removed again (treadmill clip), and the recorded
pass (N + 1 frames) is closed into a seamless N-frame loop by spreading the small pose mismatch
between its last and first frame linearly over the clip (the simulation is periodic after the
warm-up, so the mismatch is small; a velocity-matching Hermite closure would amplify the
simulation's step-to-step noise).
"""

from __future__ import annotations

import numpy as np

from stimuli.motion import quat
from stimuli.motion.motion import Motion
from stimuli.motion.skeleton import role_indices


def segment_quats(sim, labels: list[str]) -> dict[str, np.ndarray]:
    """Simulated world rotations (frames × 4, w-first) of the named ragdoll bodies."""
    return {label: quat.unroll(sim.xquat[:, sim.body_names.index(label)]) for label in labels}


def global_pose(motion: Motion, sim, ref) -> np.ndarray:
    """Local rotations (frames × J × 4) whose followed bones match the simulation."""
    n = sim.xquat.shape[0]
    frames = np.arange(n) % motion.n_frames
    local = motion.rotations[frames].copy()
    ref_global, _ = motion.global_transforms()
    followed = {j: label for label, j in ref.bones.items()}
    sims = segment_quats(sim, list(ref.bones))
    out_global = np.empty_like(local)
    for j in range(motion.n_joints):
        p = motion.parents[j]
        if j in followed:
            label = followed[j]
            out_global[:, j] = quat.mul(sims[label], quat.inv(ref.align[label]))
            parent_g = out_global[:, p] if p >= 0 else np.tile([1.0, 0, 0, 0], (n, 1))
            local[:, j] = quat.mul(quat.inv(parent_g), out_global[:, j])
        else:
            out_global[:, j] = quat.mul(out_global[:, p], local[:, j]) if p >= 0 else local[:, j]
    return quat.unroll(local)


def to_motion(motion: Motion, body, sim, ref, ragdoll) -> Motion:
    """The COM motion: same skeleton and fps as ``motion``, looped, on a treadmill."""
    rotations = global_pose(motion, sim, ref)
    t = np.arange(sim.xquat.shape[0]) / sim.fps
    pelvis = sim.body_names.index("pelvis")
    on_body_rig = list(motion.joint_names) == list(body.rig.names)
    if on_body_rig:
        offsets = body.rig.offsets.copy()
        root = sim.xpos[:, pelvis].copy()
        belt = ref.belt_speed
    else:
        seg = {s.label: s for s in body.segments}
        hip_rest = 0.5 * (seg["upper_leg.L"].proximal + seg["upper_leg.R"].proximal)
        hip_sim = sim.xpos[:, pelvis] + quat.rotate(sim.xquat[:, pelvis], hip_rest - ragdoll.link("pelvis").anchor)
        roles = role_indices(motion)
        rest = motion.rest_positions()
        hip_motion_rest = 0.5 * (rest[roles["l_hip"]] + rest[roles["r_hip"]])
        root = hip_sim / ref.scale - quat.rotate(rotations[:, 0], hip_motion_rest)
        offsets = motion.offsets.copy()
        belt = ref.belt_speed / ref.scale
    root[:, 2] -= belt * t
    meta = dict(motion.metadata)
    meta.update(method="COM", treadmill=True, belt_speed_mps=float(belt), looped=True,
                physics={"body_id": ragdoll.body_id, "weight_kg": ragdoll.weight_kg, "height_m": ragdoll.height_m})
    out = Motion(fps=motion.fps, joint_names=motion.joint_names, parents=motion.parents, offsets=offsets,
                 rotations=rotations, root_translation=root, metadata=meta)
    return close_loop_linear(out)


def close_loop_linear(motion: Motion) -> Motion:
    """Make frame N equal frame 0 by a linearly growing correction, then drop frame N."""
    n = motion.n_frames - 1
    s = np.arange(n + 1) / n
    q = quat.unroll(motion.rotations)
    d = quat.to_axis_angle(quat.mul(quat.inv(q[-1]), q[0]))
    rot = quat.mul(q, quat.from_axis_angle(s[:, None, None] * d))
    root = motion.root_translation + s[:, None] * (motion.root_translation[0] - motion.root_translation[-1])
    return motion.replace(rotations=rot[:-1], root_translation=root[:-1])


def joint_rms_difference(a: Motion, b: Motion, ref, ragdoll) -> dict[str, float]:
    """RMS (degrees) over frames of the difference between two motions' ragdoll-joint angles.

    For each ragdoll joint the rotation of the child segment's bone relative to the parent
    segment's bone is compared (the angle of ``R_a⁻¹ R_b``), so both motions are measured on the
    same joints the controller drives.
    """
    n = min(a.n_frames, b.n_frames)
    ga, gb = a.global_transforms()[0][:n], b.global_transforms()[0][:n]
    out = {}
    for link in ragdoll.links:
        if not link.dofs:
            continue
        jc, jp = ref.bones[link.label], ref.bones[link.parent]
        ra = quat.mul(quat.inv(ga[:, jp]), ga[:, jc])
        rb = quat.mul(quat.inv(gb[:, jp]), gb[:, jc])
        ang = quat.angle(quat.mul(quat.inv(ra), rb))
        out[link.joint_name] = float(np.degrees(np.sqrt(np.mean(ang**2))))
    return out
