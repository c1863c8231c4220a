"""The toes the ragdoll's foot lacks: where the motion stands on its toes, the box stands on its ball.

The ragdoll's foot is one box from the heel to the ball (``ragdoll._foot_box``); the Anny foot runs
6 cm further, to the toe tips. Through push-off a motion's foot rolls over its ball and stands on
its toes, so the posed box rises off the floor while the motion is still down: in the women's Exp-2
jog average the box's ball rose 16–25 mm over the last 3–4 frames of every 10-frame stance, pitched
11–21° toe down, and only 46 % of the frames had a box within 10 mm of the floor where the contact
model has a foot down in 77 %. Tracked as it is, that reference leaves the floor early: the
simulated jog flew 30 % against the reference's 23 % (docs/physics_log.md, "Runs: the reference
stands on the ball of its box").

:func:`stand_on_toes` therefore lays the reference's feet on the floor the way a foot without toes
can: through the second half of each contact-model stance (:func:`stimuli.motion.contact.foot_contacts`)
a box whose lowest corner is above the floor is plantar-flexed about its ankle until that corner
touches the floor (at most :data:`MAX_PITCH_DEG`), the change fading in and out over
:data:`RAMP_FRAMES`; through the first half, a box hovering over the floor (by no more than the
contact model's entry height, 3 cm) is lowered onto it by leg IK, fading in over the frames before
(at touchdown the jogs' boxes hovered 4–9 mm up, so the simulated foot landed late: 0.65 of a frame
on the men's Exp-2 jog); then no box corner is left below the floor (the foot is raised by leg IK).
The floor is the simulation's (:func:`stimuli.physics.simulate.ground_offset`), which the returned
reference carries in its root, so its own ground offset is zero.

It is used with the feed-forward on runs (``retarget(..., toes=)`` overrides). Base character,
flight against the reference's: the generated jog 0.50 → 0.30 (0.31), the Bandai dash 0.66 → 0.74
(0.71), CMU 35_17 0.45 → 0.45 (0.44), the women's Exp-2 jog average 0.30 → 0.24 (0.23); the tired
jog got worse, 0.30 → 0.41 (0.15). On walks, where the swing placement already keeps the feet
down, it moved the flight figures both ways and met no further bound (CMU 02_01 0.000 → 0.047,
131_02 0.089 → 0.177, 07_12 0.127 → 0.088, the Bandai walk 0.128 → 0.098), so walks keep their
reference's feet as they are (docs/physics_log.md, the same section).

Example
-------
>>> import numpy as np
>>> late_stance(np.array([1, 1, 1, 1, 0, 0, 1, 1], bool)).astype(int).tolist()   # one contact, across the seam
[0, 1, 1, 1, 0, 0, 0, 0]
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial.transform import Rotation

from stimuli.motion import quat

# The largest plantar flexion added (a foot on its toes pitches 11–21° at push-off in the jogs).
MAX_PITCH_DEG = 40.0
# Frames over which the added pitch fades in before and out after the frames that need it.
RAMP_FRAMES = 2
BISECTIONS = 30


def late_stance(down: np.ndarray) -> np.ndarray:
    """The second half of each contact run of one foot (the clip repeats; a foot always down has none)."""
    down = np.asarray(down, bool)
    n, out = len(down), np.zeros(len(down), bool)
    if down.all() or not down.any():
        return out
    start = int(np.argmin(down))               # a swing frame: runs do not wrap past it
    run = None
    for k in range(start, start + n + 1):
        if down[k % n] and run is None:
            run = k
        elif not down[k % n] and run is not None:
            out[np.arange(run + (k - run) // 2, k) % n] = True
            run = None
    return out


def stand_on_toes(ref, model, stance: np.ndarray):
    """``ref`` (a :class:`stimuli.physics.reference.Reference`, posed on the compiled ragdoll ``model``)
    with the floor in its root and its
    feet on the floor where ``stance`` (frame × 2, the motion's contact model) has them down, and
    the frames changed (a dict: share of frames whose ankles were pitched, largest pitch in degrees,
    largest raise in mm)."""
    import mujoco

    from stimuli.physics.simulate import foot_geoms, ground_offset
    from stimuli.physics.swing import actuator_qpos, leg_dofs

    root = ref.root_pos + [0.0, ground_offset(model, ref), 0.0]
    data, qadr = mujoco.MjData(model), actuator_qpos(model)
    legs, dofs = leg_dofs(model)
    feet = [(model.body(f"foot.{s}").id, model.geom(f"foot.{s}").id) for s in "LR"]
    q = ref.q.copy()

    def pose(f):
        data.qpos[:3], data.qpos[3:7], data.qpos[qadr] = root[f], ref.root_quat[f], q[f]
        mujoco.mj_kinematics(model, data)

    late = np.stack([late_stance(stance[:, 0]), late_stance(stance[:, 1])], axis=1)
    needed = np.zeros(q.shape[:1] + (2,))
    for f in np.flatnonzero(late.any(axis=1)):
        pose(f)
        for side in np.flatnonzero(late[f]):
            needed[f, side] = _toe_down_pitch(model, data, *feet[side], np.radians(MAX_PITCH_DEG), reach_only=True)
    # The ramp around those frames never takes a box below the floor: on frames already down it adds nothing.
    ramped, pitch = np.abs(_ramp(needed, RAMP_FRAMES)), np.zeros_like(needed)
    for f in np.flatnonzero(ramped.any(axis=1)):
        pose(f)
        for side in np.flatnonzero(ramped[f]):
            pitch[f, side] = _toe_down_pitch(model, data, *feet[side], ramped[f, side], reach_only=False)
    for f in np.flatnonzero(pitch.any(axis=1)):
        pose(f)
        for side in np.flatnonzero(pitch[f]):
            body = feet[side][0]
            turn = _about_lateral(data, body, pitch[f, side])
            goal_rot = np.empty(4)
            mujoco.mju_mulQuat(goal_rot, turn, data.xquat[body])
            solve_leg_at(model, data, qadr[legs[side]], dofs[side], body, data.xpos[body].copy(), goal_rot)
        q[f] = data.qpos[qadr]
    lowered = _lower_heels(model, data, pose, q, qadr, legs, dofs, feet, stance & ~late)
    has_toes = len(foot_geoms(model)[0]) > 1
    toe_bend = _lay_toes_flat(model, data, pose, q, qadr) if has_toes else np.zeros((len(q), 2))
    raise_m = _clear_the_floor(model, data, pose, q, qadr, legs, dofs, feet)
    changed = {"pitched_share": round(float(pitch.any(axis=1).mean()), 3),
               "max_pitch_deg": round(float(np.degrees(np.abs(pitch).max())), 1),
               "lowered_share": round(float(lowered.any(axis=1).mean()), 3),
               "max_lower_mm": round(1000 * float(lowered.max()), 1),
               "toes_bent_share": round(float((toe_bend != 0).any(axis=1).mean()), 3),
               "max_toe_bend_deg": round(float(np.degrees(np.abs(toe_bend).max())), 1),
               "max_raise_mm": round(1000 * raise_m, 1)}
    return dataclasses.replace(ref, q=q, root_pos=root, grounded=True), changed


def solve_leg_at(model, data, qadr, dofs, body, goal, rot) -> None:
    """One leg to a foot pose, solved to a tenth of a millimetre (posing a reference, not controlling)."""
    from stimuli.physics.swing import solve_leg

    solve_leg(model, data, qadr, dofs, body, goal, rot, iterations=30, tolerance_m=1e-5)


def _toe_down_pitch(model, data, body: int, geom: int, cap: float, reach_only: bool) -> float:
    """Plantar flexion (rad, signed about the foot's lateral axis, at most ``cap`` in size) that
    brings the box's lowest corner down to the floor: 0 when it is on or below the floor; when
    ``cap`` cannot bring it there, 0 with ``reach_only`` (a foot in the air, not on its toes), else ``cap``."""
    from stimuli.physics.simulate import box_corners

    rot, pos = data.xmat[body].reshape(3, 3), data.xpos[body]
    local_pos, local_rot = model.geom_pos[geom], rot.T @ data.geom_xmat[geom].reshape(3, 3)

    def lowest(angle):
        r = _rotation(rot[:, 0], angle) @ rot
        return float((pos[1] + (r @ local_pos)[1] + box_corners(model, geom) @ (r @ local_rot)[1]).min())

    if lowest(0.0) <= 0.0:
        return 0.0
    # toes down: the sign that lowers the foot's forward axis
    sign = 1.0 if (_rotation(rot[:, 0], 0.01) @ rot[:, 2])[1] < rot[1, 2] else -1.0
    if lowest(sign * cap) > 0.0:
        return 0.0 if reach_only else sign * cap
    lo, hi = 0.0, cap
    for _ in range(BISECTIONS):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if lowest(sign * mid) > 0.0 else (lo, mid)
    return sign * hi


def _ramp(pitch: np.ndarray, frames: int) -> np.ndarray:
    """Each frame's pitch, or a neighbour's within ``frames`` scaled by a half-cosine, whichever is larger."""
    out = pitch.copy()
    for k in range(1, frames + 1):
        w = 0.5 * (1.0 + np.cos(np.pi * k / (frames + 1)))
        for shift in (k, -k):
            cand = np.roll(pitch, shift, axis=0) * w
            out = np.where(np.abs(cand) > np.abs(out), cand, out)
    return out


def _lower_heels(model, data, pose, q, qadr, legs, dofs, feet, early: np.ndarray) -> np.ndarray:
    """Lower every box that hovers over the floor in the first half of a contact-model stance
    (``early``, frame × 2) by at most the contact model's entry height until its lowest corner
    touches the floor, by leg IK keeping its orientation, fading in over :data:`RAMP_FRAMES` before;
    returns the lowering asked per frame and foot (m)."""
    from stimuli.motion.contact import ENTER_HEIGHT_M
    from stimuli.physics.simulate import lowest_corner

    need = np.zeros(early.shape)
    for f in np.flatnonzero(early.any(axis=1)):
        pose(f)
        for side in np.flatnonzero(early[f]):
            height = lowest_corner(model, data, feet[side][1])
            need[f, side] = height if 0.0 < height <= ENTER_HEIGHT_M else 0.0
    ramped = _ramp(need, RAMP_FRAMES)
    for f in np.flatnonzero(ramped.any(axis=1)):
        pose(f)
        for side in np.flatnonzero(ramped[f]):
            drop = min(ramped[f, side], lowest_corner(model, data, feet[side][1]))   # never below the floor
            if drop > 0.0:
                body = feet[side][0]
                solve_leg_at(model, data, qadr[legs[side]], dofs[side], body, data.xpos[body] - [0.0, drop, 0.0],
                             data.xquat[body].copy())
        q[f] = data.qpos[qadr]
    return need


def _lay_toes_flat(model, data, pose, q, qadr) -> np.ndarray:
    """Bend up every toe box that reaches below the floor until its lowest corner is on it (at most
    :data:`stimuli.motion.toes.MAX_TOE_BEND_DEG` more than the motion's bend), as a planted foot's
    toes lie flat; returns the bend added per frame and foot (rad, signed about the toe hinge).

    Used on a ragdoll with toe segments (``retarget(..., toe_segment=True)``; jogs have none by
    default). Why: a foot plantar-flexed onto its ball (above) drives toes that the motion keeps
    straight into the floor (the generator's jog bends them 4.5° at most); the base character's
    generated jog then flew 0.234 of the time against its reference's 0.283 (laid flat: 0.288)."""
    import mujoco

    from stimuli.motion.toes import MAX_TOE_BEND_DEG
    from stimuli.physics.simulate import lowest_corner

    toes = [(int(qadr[model.actuator(f"toe.{s}").id]), model.geom(f"toes.{s}").id) for s in "LR"]
    cap = np.radians(MAX_TOE_BEND_DEG)
    bend = np.zeros((len(q), 2))
    for f in range(len(q)):
        pose(f)
        for side, (adr, geom) in enumerate(toes):
            if lowest_corner(model, data, geom) >= 0.0:
                continue
            start = float(data.qpos[adr])

            def low(angle):
                data.qpos[adr] = start + angle
                mujoco.mj_kinematics(model, data)
                return lowest_corner(model, data, geom)

            up = 1.0 if low(0.01) > low(-0.01) else -1.0
            lo, hi = 0.0, cap
            if low(up * cap) >= 0.0:
                for _ in range(BISECTIONS):
                    mid = 0.5 * (lo + hi)
                    lo, hi = (lo, mid) if low(up * mid) >= 0.0 else (mid, hi)
            bend[f, side] = up * hi
            low(bend[f, side])
        q[f] = data.qpos[qadr]
    return bend


def _clear_the_floor(model, data, pose, q, qadr, legs, dofs, feet) -> float:
    """Raise every foot whose box or toes' box has a corner below the floor (that frame and its
    neighbours' depth) by leg IK, keeping its orientation; returns the largest raise (m)."""
    from stimuli.physics.simulate import foot_geoms, lowest_corner

    n = len(q)
    depth = np.zeros((n, 2))
    geoms = foot_geoms(model)
    for f in range(n):
        pose(f)
        depth[f] = [max(0.0, -min(lowest_corner(model, data, g) for g in side)) for side in geoms]
    need = np.maximum.reduce([depth, np.roll(depth, 1, axis=0), np.roll(depth, -1, axis=0)])
    for f in np.flatnonzero(need.any(axis=1)):
        pose(f)
        goals = [(side, data.xpos[feet[side][0]] + [0.0, need[f, side], 0.0], data.xquat[feet[side][0]].copy())
                 for side in np.flatnonzero(need[f])]
        for side, goal, rot in goals:
            solve_leg_at(model, data, qadr[legs[side]], dofs[side], feet[side][0], goal, rot)
        q[f] = data.qpos[qadr]
    return float(need.max())


def _about_lateral(data, body: int, angle: float) -> np.ndarray:
    """Quaternion (w, x, y, z) of a turn by ``angle`` about the foot body's lateral (x) axis, in the world."""
    return quat.from_axis_angle(data.xmat[body].reshape(3, 3)[:, 0] * angle)


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix of ``angle`` about the unit ``axis``."""
    return Rotation.from_rotvec(axis * angle).as_matrix()
