"""The toes bend at the ball of the foot while the foot stands on them.

A retargeted foot used to be rigid from heel to toe tip (the Anny toes kept their rest pose), so
late in stance the clean-up turned it heel-up about its toe *tips*: the ball of the foot rose
20–70 mm off the floor and the foot stood on pointed toes at push-off (the generated walk's ball
34 mm up with the heel 12 cm up), and the ankle, turned back by the roll-off to keep the knee's
bend, lost up to 12° of the plantar flexion the generator gave it from the CGM2.3 curve. A walker
with a first metatarsophalangeal joint held stiff does the same: less plantar flexion, more
dorsiflexion (Xu et al. 2021, Med Sci Monit 27:e930081). Here the toes bend up at the ball
(:func:`level_toes`): in contact, every bone hinged at the ankle's distal end (on the Anny rig the
first phalanx of each toe) turns up about the foot's left–right axis until the toes lie level, at
most :data:`MAX_TOE_BEND_DEG`; after toe off the bend relaxes at :data:`TOE_RELAX_DEG_S`. The
clean-up then turns a foot heel-up about its ball, the rearmost point it stands on
(``footfix.contact_targets(..., rear_pivot=True)``); the ball's sole point hangs from the toe joint
above it, so a foot on level toes turns about that joint, which keeps its height, as the metatarsal
heads roll; toes at their limit roll on over their tips.
"""

from __future__ import annotations

import numpy as np

from stimuli.motion import quat
from stimuli.motion.skeleton import role_indices

# The largest toe bend; a foot pitched further rolls over its toe tips. Within the 40-60° usually
# given for the first metatarsophalangeal joint at push-off, chosen with two bounds in view: at 60°
# CMU 35_01 on a woman's body skated 6.8 % (HUMOS; bound 5), at 50° an Exp-1 walk's foot turned
# 5.6° a frame faster than the generator's at toe off (bound 5), at 45° both are met
# (docs/readme_motion.md, "Toes that bend at the ball").
MAX_TOE_BEND_DEG = 45.0
# After toe off the bent toes return to their rest pose at this rate (45° in 0.15 s).
TOE_RELAX_DEG_S = 300.0
SIDES = ("l", "r")


def toe_joints(motion, side: str) -> list[int]:
    """The joints hinged at the ball of one foot: the children of its ankle joint that lie ahead
    of it at rest (a heel joint behind it is not a toe).

    >>> from stimuli.motion.generate import GaitParams, generate
    >>> walk = generate(GaitParams(), 1.75)
    >>> [walk.joint_names[j] for j in toe_joints(walk, "l")]
    ['l_toe']
    """
    ankle = role_indices(motion)[f"{side}_ankle"]
    rest = motion.rest_positions()
    return [j for j in range(len(motion.joint_names)) if motion.parents[j] == ankle and rest[j, 2] > rest[ankle, 2]]


def bend_needed(ball: np.ndarray, tip: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Toe bend (radians, T) about ``axis`` (T×3, unit: the foot's left–right axis, positive =
    toes up) that lays the toe line from ``ball`` to ``tip`` (T×3, both on the toes) level: its
    pitch below the horizontal in the plane across that axis, within 0…:data:`MAX_TOE_BEND_DEG`
    (toes pointing up are not bent; a foot turned past upright, its toes pointing backwards and
    down, gets the most).

    >>> ball = np.zeros((3, 3))
    >>> tip = np.array([[0.0, -0.03, 0.05], [0.0, 0.01, 0.05], [0.0, -0.06, -0.01]])
    >>> axis = np.tile([-1.0, 0.0, 0.0], (3, 1))               # forward (+z) × up
    >>> np.degrees(bend_needed(ball, tip, axis)).round(1).tolist()
    [31.0, 0.0, 45.0]
    """
    line = tip - ball
    forward = np.cross(np.array([0.0, 1.0, 0.0]), axis)
    down = np.arctan2(-line[:, 1], np.einsum("ij,ij->i", line, forward))
    return np.clip(down, 0.0, np.radians(MAX_TOE_BEND_DEG))


def level_toes(motion, rot: np.ndarray, root: np.ndarray, contacts: dict[str, np.ndarray], points: dict,
               cyclic: bool = True) -> np.ndarray:
    """Local rotations ``rot`` with each foot's toes bent up where it stands on them.

    ``points`` are the sole points per side (heel, ball, toe tip; e.g.
    ``retarget.mesh_sole_points``) with ball and tip attached to toe joints. In ``contacts`` frames
    the toes turn up about the foot's left–right axis (across its rest toe line), each about its
    own joint, until the line from the ball to the tip is level (:func:`bend_needed`); after a
    contact the bend falls at :data:`TOE_RELAX_DEG_S`. The toes start from their rest pose (the
    identity: the rig's rotations are relative to its rest pose, as on the Anny rig, where
    retargeted toes keep it), so a bend already in ``rot`` is replaced, not added to.
    """
    from stimuli.motion.footfix import rate_limited_envelope, sole_positions

    out = rot.copy()
    rate = np.radians(TOE_RELAX_DEG_S) / motion.fps
    roles = role_indices(motion)
    rest = motion.rest_positions()
    up = np.array([0.0, 1.0, 0.0])
    sides = {s: toe_joints(motion, s) for s in SIDES}
    sides = {s: toes for s, toes in sides.items() if points[s][-1][0] in toes}   # a tip on the foot: no bend
    for toes in sides.values():
        out[:, toes] = quat.IDENTITY
    grot, gpos = motion.global_transforms(out, root)
    for s, toes in sides.items():
        (ball_joint, ball_offset), (tip_joint, tip_offset) = points[s][1], points[s][-1]
        # The toes' hinge: across the rest toe line, in the rest frame the local rotations use.
        line = rest[tip_joint] + tip_offset - rest[ball_joint] - ball_offset
        hinge = np.cross(line * [1.0, 0.0, 1.0], up)
        hinge /= np.linalg.norm(hinge)
        sole = sole_positions(grot, gpos, points[s])
        axis = quat.rotate(grot[:, roles[f"{s}_ankle"]], hinge)
        bend = np.where(contacts[s], bend_needed(sole[:, 1], sole[:, -1], axis), 0.0)
        bend, _ = rate_limited_envelope(bend, np.ones(len(bend), bool), rate, cyclic)
        out[:, toes] = quat.from_axis_angle(hinge * bend[:, None])[:, None]
    return out
