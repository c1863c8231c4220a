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
simulation's step-to-step noise). A clip with flight carries the simulation's foot contacts per frame
(metadata ``contacts``, :func:`frame_contacts`), which the display retargeting plants instead of
guessing contacts from foot heights.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import binary_closing

from stimuli.motion import quat
from stimuli.motion.motion import Motion
from stimuli.motion.retarget import is_on_rig
from stimuli.motion.skeleton import role_indices


def segment_quats(sim, labels: list[str]) -> dict[str, np.ndarray]:
    """Simulated world rotations (frames × 4, w-first) of the named ragdoll bodies."""
    return {label: quat.unroll(sim.xquat[:, sim.body_names.index(label)]) for label in labels}


def global_pose(motion: Motion, sim, ref) -> np.ndarray:
    """Local rotations (frames × J × 4) whose followed bones match the simulation."""
    n = sim.xquat.shape[0]
    frames = np.arange(n) % motion.n_frames
    local = motion.rotations[frames].copy()
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
    on_body_rig = is_on_rig(motion, body)
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
    contacts = frame_contacts(sim, len(t) - 1)
    if not np.all(np.logical_or(contacts["l"], contacts["r"])):
        meta["contacts"] = contacts  # a gait with flight: show it as simulated (see frame_contacts)
    out = Motion(fps=motion.fps, joint_names=motion.joint_names, parents=motion.parents, offsets=offsets,
                 rotations=rotations, root_translation=root, metadata=meta)
    return close_loop_linear(out)


# Gaps in a foot's contact of up to this many frames are bridged: the women's simulated jogs lift
# the toe for one frame at push-off and tap down again, which the display would show as a 3-cm hop
# of the foot (its swing clearance) in mid-stance.
MAX_CONTACT_GAP_FRAMES = 2


def frame_contacts(sim, n_frames: int) -> dict[str, list[int]]:
    """Per foot (``l``, ``r``) and output frame, 1 if the simulated foot touched the floor within half a
    frame of it (the recorded pass is periodic), with short gaps bridged (:data:`MAX_CONTACT_GAP_FRAMES`).

    :func:`to_motion` stores them as the motion's ``contacts`` when some frame has no foot down (a
    jog's flight), and the display retargeting plants the feet then. Found from foot heights (a
    foot within 3 cm of its stance height counts as down), the COM jogs, whose feet skim 1–2.5 cm
    over the floor in flight, showed no frame in flight; with these contacts they show 15.4 %, as
    the generated jogs do. A simulated walk keeps a foot down in every frame and is left to the
    height-based detection, which also plants the few-mm hovers of the men's hopping walks (with
    these contacts those feet skated in 4.7–6.3 % of the frames).
    """
    k = len(sim.step_times) // n_frames  # simulation steps per frame (the pass has n_frames·k + 1)
    steps = np.asarray(sim.foot_contact[: n_frames * k], bool)
    touched = np.zeros_like(steps)
    for shift in range(-(k // 2), k // 2 + 1):
        touched |= np.roll(steps, -shift, axis=0)
    per_frame = touched[::k]
    # Closing with a window of gap + 1 frames fills the gaps of up to ``gap`` frames; the pass is
    # periodic, so it is closed as three copies and the middle one kept.
    tiled = np.concatenate([per_frame] * 3)
    closed = binary_closing(tiled, structure=np.ones((MAX_CONTACT_GAP_FRAMES + 1, 1), bool))[n_frames:2 * n_frames]
    return {side: closed[:, i].astype(int).tolist() for i, side in enumerate("lr")}


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
