"""Retargeting any motion onto the Anny rig of a fitted body (``stimuli.bodies``).

Method (rest-pose alignment, then clean-up):

1. Every mapped Anny bone takes the *world* rotation of the source joint that drives the same
   limb segment, composed with a fixed rest alignment A = between(Anny rest direction, source rest
   direction): G_anny(t) = D_src(t) · A. This absorbs rest-pose differences (a T-pose source on
   Anny's A-pose, splayed legs, a CMU foot bone pointing down) while keeping the source's twist; a
   final swing makes each bone point exactly along the source segment. The spine is spread over
   Anny's five spine bones by slerp between pelvis and chest, the neck over its three. Pelvis,
   chest, head and the legs' roll take a rest turn snapped to the 24 axis-to-axis turns
   (:func:`rest_turn`: a rig whose rest frames lie along other axes, Bandai's); a foot standing flat
   on the source's floor stands flat on Anny's (:func:`flat_foot_turn`). The upper arm and forearm
   turn about their bones so that Anny's elbow flexes in the capture's bend plane
   (:func:`stimuli.motion.arms.elbow_hinge_twist`: rigs disagree about the arms' twist).
2. The pelvis path is scaled by the leg-length ratio (thigh + shank + ankle height, from the
   segment lengths, whatever the rest pose): root height and stride follow the target's legs, so
   the belt speed scales too (recorded).
3. Foot clean-up (``footfix``): contacts are detected on the retargeted feet (near the ground and
   slow relative to the belt), planted feet are pinned and moved at belt speed by two-bone IK, the
   sole points come from the body mesh so the ground is at y = 0; a foot whose ball slides low next
   to a contact is held over its footprint there (``footfix.ease_edges``); last, each knee is kept
   from turning faster than the source's (``footfix.keep_knee_rate``: no knee snap at contact edges).
   The toes bend at the ball while the foot stands on them (:mod:`stimuli.motion.toes`): the foot
   turns about the ball, then rolls over the toe tips, instead of standing on straight toes' tips.

Twist bones and fingers keep their rest orientation relative to their parents; so do the toes, but
for their bend in contact.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial.transform import Rotation

from stimuli.errors import StimuliError
from stimuli.motion import quat
from stimuli.motion.arms import clavicle_world, elbow_hinge_twist
from stimuli.motion.events import stance_from_events
from stimuli.motion.balance import balance
from stimuli.motion.contact import contact_mask, foot_contacts
from stimuli.motion.footfix import (clean_feet, contact_runs, ease_edges, flat_frames, joint_change_deg, keep_knee_rate,
                                    leg_joint_indices, lock_feet, sole_positions)
from stimuli.motion.motion import Motion
from stimuli.motion.skeleton import NAMINGS, leg_length, role_indices
from stimuli.motion.toes import toe_joints

ANNY_ROLES = {role: names[0] for role, names in NAMINGS["anny"].items()}
# Anny bone → (source role whose world rotation drives it, (from role, to role) of the segment).
LIMBS = {}
for _s, _S in (("l", "L"), ("r", "R")):
    LIMBS.update({
        f"upperleg01.{_S}": (f"{_s}_hip", (f"{_s}_hip", f"{_s}_knee")),
        f"lowerleg01.{_S}": (f"{_s}_knee", (f"{_s}_knee", f"{_s}_ankle")),
        f"foot.{_S}": (f"{_s}_ankle", (f"{_s}_ankle", f"{_s}_toe")),
        f"clavicle.{_S}": (f"{_s}_clavicle", (f"{_s}_clavicle", f"{_s}_shoulder")),
        f"upperarm01.{_S}": (f"{_s}_shoulder", (f"{_s}_shoulder", f"{_s}_elbow")),
        f"lowerarm01.{_S}": (f"{_s}_elbow", (f"{_s}_elbow", f"{_s}_wrist")),
    })
LEG_BONES = ("upperleg01", "lowerleg01", "foot")
SPINE = ["spine05", "spine04", "spine03", "spine02", "spine01"]
NECK = ["neck01", "neck02", "neck03", "head"]
NEAR_GROUND_M = 0.025
STANCE_HEIGHT_M = 0.03
# A foot stands flat (footfix.flat_frames) for at least this long to set its turn.
FLAT_FOOT_MIN_S = 0.1
# Flat feet whose ankle→toe line is this close to the target's pitch keep the segment swing: the
# CMU rigs (14–19°), CC4 (11–13°) and the generator (18.6°) against Anny's 15°. Turning those too
# moved the generated walk's unstable % from 31 to 41 and the CMU walk's deepest vertex 2.5 → 9 mm.
FLAT_FOOT_TOLERANCE_DEG = 10.0


def _rest_pos(rig) -> np.ndarray:
    return np.asarray(rig.rest_heads, float)


# Bone offsets of a motion on a body's rig equal the rig's exactly; a body 0.01 m taller or 0.3 BMI
# heavier is 0.7–3.5 mm off.
SAME_RIG_TOLERANCE_M = 1e-4


def is_on_rig(motion: Motion, body) -> bool:
    """Whether ``motion`` is on ``body``'s own rig: the same joints and the same bones. Every Anny rig has
    the same joint names, so the names alone let a motion of a 1.80 m man pass for a 1.50 m woman's.

    >>> from types import SimpleNamespace
    >>> rig = SimpleNamespace(names=["root", "leg"], offsets=np.array([[0, 0, 0], [0, -0.4, 0]]))
    >>> walk = SimpleNamespace(joint_names=["root", "leg"], offsets=np.array([[0, 1.0, 0], [0, -0.4, 0]]))
    >>> is_on_rig(walk, SimpleNamespace(rig=rig)), is_on_rig(walk, SimpleNamespace(rig=SimpleNamespace(
    ...     names=rig.names, offsets=rig.offsets * 1.1)))
    (True, False)
    """
    rig = body.rig
    if list(motion.joint_names) != list(rig.names):
        return False
    # the root's offset is where the motion starts, not a bone
    return bool(np.abs(np.asarray(motion.offsets)[1:] - np.asarray(rig.offsets)[1:]).max(initial=0.0)
                < SAME_RIG_TOLERANCE_M)


def anny_motion(body, rotations: np.ndarray, root: np.ndarray, fps: float, metadata: dict) -> Motion:
    """A Motion on the body's Anny rig (joint names, parents and offsets of ``body.rig``)."""
    rig = body.rig
    meta = dict(metadata)
    meta.update(naming="anny", roles=dict(ANNY_ROLES), body_id=getattr(body, "body_id", None))
    return Motion(fps=fps, joint_names=list(rig.names), parents=np.asarray(rig.parents), offsets=np.asarray(rig.offsets),
                  rotations=rotations, root_translation=root, metadata=meta)


def rig_leg_length(rig) -> float:
    """Thigh + shank + ankle height of an Anny rig's rest legs (its mesh stands on y = 0): the same
    measure as :func:`~stimuli.motion.skeleton.leg_length` of a source, so their ratio is the legs'."""
    rest = _rest_pos(rig)
    out = []
    for s in ("L", "R"):
        hip, knee, ankle = (rest[rig.index(f"{b}.{s}")] for b in ("upperleg01", "lowerleg01", "foot"))
        out.append(np.linalg.norm(knee - hip) + np.linalg.norm(ankle - knee) + ankle[1])
    return float(np.mean(out))


def standing_pelvis_height(source: Motion, roles: dict[str, int]) -> float:
    """Height of the source's pelvis joint when standing: the legs' length plus how far the pelvis
    joint sits above the hip joints (median over the frames; the rest pose need not stand)."""
    pos = source.positions()
    hips = 0.5 * (pos[:, roles["l_hip"], 1] + pos[:, roles["r_hip"], 1])
    return leg_length(source) + float(np.median(pos[:, roles["pelvis"], 1] - hips))


def _axis_frame(lateral: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) whose columns are the body's left, up and forward axes."""
    x = lateral / np.linalg.norm(lateral, axis=-1, keepdims=True)
    y = up - x * np.sum(up * x, axis=-1, keepdims=True)
    y = y / np.linalg.norm(y, axis=-1, keepdims=True)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


# The 24 rotations that take the coordinate axes onto coordinate axes.
_AXIS_TURNS = np.array([m for m in (np.diag(signs) @ np.eye(3)[list(order)]
                                    for order in itertools.permutations(range(3))
                                    for signs in itertools.product((1, -1), repeat=3))
                        if np.linalg.det(m) > 0])


def rest_turn(grot: np.ndarray, frame: np.ndarray, target_frame: np.ndarray) -> np.ndarray:
    """A fixed turn (w-first quaternion) from a source joint's frame to the target's matching bone,
    for joints whose world rotation is copied (pelvis, chest, head): the turn between where the
    body's left/up/forward axes (``frame``, T×3×3, measured on the motion) sit in the joint's frame
    and where they sit in the target's rest (``target_frame``), snapped to the nearest of the 24
    axis-to-axis turns.

    Why snapped: an exporter authors a rig's rest frames along its world axes (Bandai's pelvis has
    its x axis up: copied as it is, Anny's pelvis lay on its side, the left foot hung 14 cm above
    the right and the clean-up crouched the walk to reach the floor: 35 % skate, 36 mm penetration,
    a 112° knee where the capture has 73°); what is left beyond such a quarter turn is the actor's
    own posture (pelvis tilt, trunk lean), which is kept: on the CMU and CC4 rigs the turn is none.

    >>> tilted = _axis_frame(np.array([[0.0, -1.0, 0.0]]), np.array([[1.0, 0.05, 0.0]]))  # lying on its side
    >>> turn = rest_turn(np.tile(quat.IDENTITY, (1, 1)), tilted, np.eye(3))
    >>> np.round(quat.rotate(turn, np.array([0.0, 1.0, 0.0])), 6).tolist()   # the target's up is the joint's x
    [1.0, 0.0, 0.0]
    """
    local = np.einsum("tji,tjk->tik", quat.to_scipy(grot).as_matrix(), frame)      # Rᵀ·F per frame
    u, _, vt = np.linalg.svd(local.mean(axis=0))
    mean = u @ vt
    want = mean @ np.asarray(target_frame).T
    best = _AXIS_TURNS[np.argmax(np.einsum("nij,ij->n", _AXIS_TURNS, want))]
    return quat.from_scipy(Rotation.from_matrix(best))


def _pitch_deg(v: np.ndarray) -> np.ndarray:
    """How far directions (..., 3) point below the horizontal, degrees."""
    return np.degrees(np.arcsin(np.clip(-v[..., 1] / np.linalg.norm(v, axis=-1), -1.0, 1.0)))


def _heading_frame(direction: np.ndarray) -> np.ndarray:
    """Frames (..., 3, 3) of a foot standing flat: up is the world's, forward its heading."""
    up = np.broadcast_to(np.array([0.0, 1.0, 0.0]), direction.shape)
    return _axis_frame(np.cross(up, direction * np.array([1.0, 0.0, 1.0])), up)


def flat_foot_turn(source: Motion, grot: np.ndarray, gpos: np.ndarray, ankle: int, toe: int,
                   rest_direction: np.ndarray) -> np.ndarray | None:
    """The fixed turn (w-first quaternion) from the source ankle's frame to the target's foot that
    puts a foot standing flat on the source's floor flat on the target's, heading as it heads; None
    where the capture shows less than 0.1 s of flat foot (ankle and toe joint both slower than
    0.25 m/s over the belt, horizontally and vertically, both within 1 cm of their lowest), and
    where that foot's ankle→toe line is within :data:`FLAT_FOOT_TOLERANCE_DEG` of the target's
    (the bone is then swung onto the line, and the clean-up lays the foot flat in mid-stance).

    Why: the ankle→toe line of a flat foot points 14–19° down on the CMU rigs, 38–43° on Bandai's
    (its toe joint sits low), Anny's 15°; swung onto that line, a Bandai foot stood on its toes all
    stance (toe tip 9 cm below the floor, heel 3 cm above) and the clean-up turned it back.
    """
    flat = flat_frames(source, gpos, ankle, toe)
    if flat.sum() < FLAT_FOOT_MIN_S * source.fps:
        return None
    segment = gpos[flat, toe] - gpos[flat, ankle]
    if abs(np.median(_pitch_deg(segment)) - _pitch_deg(np.asarray(rest_direction, float))) < FLAT_FOOT_TOLERANCE_DEG:
        return None
    frames = _heading_frame(segment)
    local = np.einsum("tji,tjk->tik", quat.to_scipy(grot[flat, ankle]).as_matrix(), frames)
    u, _, vt = np.linalg.svd(local.mean(axis=0))
    turn = (u @ vt) @ _heading_frame(np.asarray(rest_direction, float)).T
    return quat.from_scipy(Rotation.from_matrix(turn))


def _world_rotations(source: Motion, rig) -> tuple[np.ndarray, dict]:
    """Anny world rotations (T×J×4) for the mapped bones; unmapped bones get None (marked)."""
    roles = role_indices(source)
    missing = [r for r in ("pelvis", "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle") if r not in roles]
    if missing:
        raise StimuliError(f"retarget: source motion lacks role(s) {', '.join(missing)}")
    grot, gpos = source.global_transforms()
    src_rest = source.rest_positions()
    tgt_rest = _rest_pos(rig)
    t = source.n_frames
    world: dict[int, np.ndarray] = {}
    hips = gpos[:, roles["l_hip"]] - gpos[:, roles["r_hip"]]
    trunk_top = roles.get("chest", roles.get("neck", roles.get("head")))
    lean = gpos[:, trunk_top] - gpos[:, roles["pelvis"]] if trunk_top is not None else np.tile([0.0, 1.0, 0.0], (t, 1))
    rest_hips = tgt_rest[rig.index("upperleg01.L")] - tgt_rest[rig.index("upperleg01.R")]
    rest_lean = tgt_rest[rig.index("spine01")] - tgt_rest[rig.index("root")]
    trunk = _axis_frame(hips, lean)
    rest_trunk = _axis_frame(rest_hips, rest_lean)
    world[rig.index("root")] = quat.mul(grot[:, roles["pelvis"]],
                                        rest_turn(grot[:, roles["pelvis"]], trunk, rest_trunk))
    chest = (quat.mul(grot[:, roles["chest"]], rest_turn(grot[:, roles["chest"]], trunk, rest_trunk))
             if "chest" in roles else world[rig.index("root")])
    for i, name in enumerate(SPINE):
        world[rig.index(name)] = quat.slerp(world[rig.index("root")], chest, np.full(t, (i + 1) / len(SPINE)))
    head = (quat.mul(grot[:, roles["head"]], rest_turn(grot[:, roles["head"]], trunk, rest_trunk))
            if "head" in roles else chest)
    for i, name in enumerate(NECK):
        world[rig.index(name)] = quat.slerp(chest, head, np.full(t, (i + 1) / len(NECK)))
    # Clavicles: the source's clavicle motion about its mean, on the target's chest (arms.clavicle_world:
    # a CMU clavicle's own slope shrugged Anny's shoulders into a hump on heavy bodies).
    for side, q in clavicle_world(grot, roles, world[rig.index("spine01")]).items():
        world[rig.index(f"clavicle.{side.upper()}")] = q
    for bone, (driver, (a, b)) in LIMBS.items():
        if driver not in roles or a not in roles or b not in roles or bone.startswith("clavicle."):
            continue
        tb = {"upperleg01": "lowerleg01", "lowerleg01": "foot", "foot": "toe1-1", "clavicle": "upperarm01",
              "upperarm01": "lowerarm01", "lowerarm01": "wrist"}[bone.split(".")[0]] + "." + bone.split(".")[1]
        r_t = tgt_rest[rig.index(tb)] - tgt_rest[rig.index(bone)]
        r_s = src_rest[roles[b]] - src_rest[roles[a]]
        if np.linalg.norm(r_s) < 1e-6 or np.linalg.norm(r_t) < 1e-6:
            continue
        # Exact direction: swing the bone onto the source segment (corrects intermediate joints).
        want = gpos[:, roles[b]] - gpos[:, roles[a]]
        if bone.split(".")[0] in LEG_BONES:
            # The leg's roll as well as its direction: frames of its segment and the hips' line, as for
            # the trunk (rest_turn). The shortest turn between rest directions rolled Bandai's and CC4's
            # feet (rests along ±x, +y) onto their sides; the clean-up then turned them back by 100-180°.
            align = rest_turn(grot[:, roles[driver]], _axis_frame(hips, want), _axis_frame(rest_hips, r_t))
        else:
            align = quat.between(r_t, r_s)
        g = quat.mul(grot[:, roles[driver]], align)
        if bone.startswith("foot."):
            turn = flat_foot_turn(source, grot, gpos, roles[a], roles[b], r_t)
            if turn is not None:
                world[rig.index(bone)] = quat.mul(grot[:, roles[a]], turn)
                continue
        have = quat.rotate(g, r_t)
        world[rig.index(bone)] = quat.mul(quat.between(have, want), g)
    forward = rest_trunk[:, 2] * [1.0, 0.0, 1.0]      # level: the rest trunk's lean is no part of the elbow's axis
    for s in ("l", "r"):
        S = s.upper()
        upper, fore = rig.index(f"upperarm01.{S}"), rig.index(f"lowerarm01.{S}")
        if upper in world and fore in world:
            world[upper], world[fore] = elbow_hinge_twist(
                world[upper], world[fore], tgt_rest[fore] - tgt_rest[upper], tgt_rest[rig.index(f"wrist.{S}")] - tgt_rest[fore],
                gpos[:, roles[f"{s}_elbow"]] - gpos[:, roles[f"{s}_shoulder"]],
                gpos[:, roles[f"{s}_wrist"]] - gpos[:, roles[f"{s}_elbow"]], forward)
    return world, roles


def _to_local(world: dict[int, np.ndarray], parents: np.ndarray, t: int) -> np.ndarray:
    """Local rotations from world rotations; unmapped bones follow their parent (local identity)."""
    j = len(parents)
    glob = np.tile(quat.IDENTITY, (t, j, 1))
    local = np.tile(quat.IDENTITY, (t, j, 1))
    for k in range(j):
        p = parents[k]
        if k in world:
            glob[:, k] = world[k]
            local[:, k] = world[k] if p < 0 else quat.mul(quat.inv(glob[:, p]), world[k])
        else:
            glob[:, k] = glob[:, p] if p >= 0 else quat.IDENTITY
    return local


def mesh_sole_points(body) -> dict[str, list[tuple[int, np.ndarray]]]:
    """Heel, ball and toe-tip points of each foot from the rest mesh: the heel attached to the foot
    bone, ball and tip to the first joint of the toe they lie under (they follow the toes' bend)."""
    rig = body.rig
    v = np.asarray(body.vertices, float)
    rest = _rest_pos(rig)
    out = {}
    for s, S, sign in (("l", "L", 1.0), ("r", "R", -1.0)):
        foot = rig.index(f"foot.{S}")
        side = (v[:, 0] * sign > 0.02) & (v[:, 1] < 0.03)
        sole = v[side]
        if len(sole) < 3:
            raise StimuliError(f"retarget: body {getattr(body, 'body_id', '?')} has no sole vertices on side {S}")
        heel = sole[np.argmin(sole[:, 2])]
        tip = sole[np.argmax(sole[:, 2])]
        ball_z = rest[rig.index(f"toe1-1.{S}"), 2]
        ball = sole[np.argmin(np.abs(sole[:, 2] - ball_z) + 10 * sole[:, 1])]
        # Ball and tip go with the toe they lie under (the nearest toe joint), so that they follow
        # the toes' bend (stimuli.motion.toes): a foot standing on level toes then turns about the
        # toe joint, which stays at its height, as the metatarsal heads roll.
        toes = [j for j in range(len(rig.names)) if rig.parents[j] == foot]

        def under(p):
            return toes[int(np.argmin([abs(rest[j, 0] - p[0]) for j in toes]))] if toes else foot

        pts = []
        for p, joint in ((heel, foot), (ball, under(ball)), (tip, under(tip))):
            q = p.copy()
            q[1] = 0.0  # the rest mesh stands on y = 0
            pts.append((joint, q - rest[joint]))
        out[s] = pts
    return out


def retarget(source: Motion, body, cleanup: bool = True, keep_speed: bool = False, foot_lock: bool = False) -> Motion:
    """Retarget ``source`` onto ``body``'s Anny rig (see the module docstring).

    ``source`` should be a treadmill loop (``make_loop``) or a generated motion; an overground
    motion is retargeted too (its path scaled). ``keep_speed`` keeps the source's belt speed
    instead of scaling the stride by the leg-length ratio. ``foot_lock`` adds the whole-clip
    foot-locking solve after the clean-up (:func:`cleanup_feet`).
    """
    rig = body.rig
    world, roles = _world_rotations(source, rig)
    rot = _to_local(world, np.asarray(rig.parents), source.n_frames)
    tgt_rest = _rest_pos(rig)
    # Leg lengths from the segments, not the rest hip height: a rest pose with splayed legs (or
    # CC4's, all bones along +y) made strides 4–11 % too long.
    k = rig_leg_length(rig) / leg_length(source)
    p = source.positions()[:, roles["pelvis"]]
    root = p * k
    root[:, 1] = tgt_rest[0, 1] + k * (p[:, 1] - standing_pelvis_height(source, roles))
    belt = float(source.metadata.get("belt_speed_mps", 0.0))
    meta = {k_: v for k_, v in source.metadata.items() if k_ not in ("roles", "naming")}
    meta.update(source=f"{source.metadata.get('source', 'motion')}→anny", leg_scale=k,
                belt_speed_mps=belt if keep_speed else belt * k, retargeted=True)
    if keep_speed and source.metadata.get("treadmill"):
        root[:, [0, 2]] = p[:, [0, 2]]
    out = anny_motion(body, rot, root, source.fps, meta)
    # A capture's belt is what the target's legs carry (stance_belt_speed); the generator lays its
    # feet out at its own belt, so its scaled belt is exact (and the renderer matches it to the
    # protocol's speed to 0.1 %: the estimate read it 0.5-0.8 % off).
    if not keep_speed and source.metadata.get("treadmill") and source.metadata.get("naming") != "canonical":
        out.metadata["belt_speed_leg_scaled_mps"] = belt * k
        carried = stance_belt_speed(out, foot_contacts(source).down, mesh_sole_points(body),
                                    cyclic=bool(source.metadata.get("looped")))
        if carried is not None:
            out.metadata["belt_speed_mps"] = carried
    if cleanup:
        out = cleanup_feet(out, body, foot_lock=foot_lock)
    return out


def stance_belt_speed(motion: Motion, contacts: dict[str, np.ndarray], points: dict, cyclic: bool = True) -> float | None:
    """The belt speed (m/s) at which ``motion``'s own legs carry a planted foot backwards: the median
    backward speed of each foot's lowest sole point (``points``: :func:`mesh_sole_points`, the point
    the foot stands on) over the middle third of each contact (``contacts``: per side, frame mask);
    None where no contact is 3 frames long.

    Why not the source's belt times the leg-length ratio: the target's legs take the source's joint
    angles with their own proportions, and on the CMU and CC4 rigs they carried a planted foot back
    5–10 % slower than that belt (CMU 07_12 on a 1.75 m man: 1.89 against 2.09 m/s). The clean-up
    then dragged each planted foot at the faster belt until the ankle was out of the leg's reach and
    lowered the pelvis to reach it: 07_12's pelvis rose and fell 116 mm per step (the source: 55 mm),
    dropping by up to 92 mm in double support, and the physics step's ragdoll trailed its target by 7
    cm. (The ankle is no such point: it rolls forward over a running foot, 13–27 % slower than the belt.)

    >>> from stimuli.bodies import fit_body
    >>> from stimuli.motion.generate import GaitParams, generate
    >>> body = fit_body("M", 1.75, 23.0)
    >>> walk = retarget(generate(GaitParams(gait="walk", speed_mps=1.3), height_m=1.75), body, cleanup=False)
    >>> belt = stance_belt_speed(walk, foot_contacts(walk).down, mesh_sole_points(body))
    >>> bool(abs(belt / walk.metadata["belt_speed_mps"] - 1) < 0.02)   # the generator's feet: its own belt
    True
    """
    grot, gpos = motion.global_transforms()
    speeds = []
    for side in ("l", "r"):
        sole = sole_positions(grot, gpos, points[side])[:, :, [1, 2]]           # frame × point × (y, z)
        vz = (np.roll(sole[:, :, 1], -1, axis=0) - np.roll(sole[:, :, 1], 1, axis=0)) * motion.fps / 2.0
        if not cyclic:
            vz[0], vz[-1] = (sole[1, :, 1] - sole[0, :, 1]) * motion.fps, (sole[-1, :, 1] - sole[-2, :, 1]) * motion.fps
        lowest = vz[np.arange(len(vz)), np.argmin(sole[:, :, 0], axis=1)]
        shift, runs = contact_runs(np.asarray(contacts[side], bool), cyclic)
        lowest = np.roll(lowest, -shift)
        speeds += [lowest[start + (stop - start) // 3:stop - (stop - start) // 3]
                   for start, stop in runs if (stop - start) // 3 >= 1]
    if not speeds:
        return None
    return float(-np.median(np.concatenate(speeds)))


def planted(motion: Motion, body) -> dict[str, np.ndarray]:
    """Feet in contact: heel strike to toe off (Zeni events) while the contact model also has the
    foot down (``contact.contact_mask``: height and belt-relative speed with hysteresis), grown by up
    to two frames before heel strike where the foot is already near the ground; where a foot has no
    events, the contact model alone. Zeni's toe off comes late on real captures: the foot stayed
    pinned while its toes already slid forward (Bandai dash 16.7 % skate, now 5.6 % with that alone)
    and was let go with the knee straightened (CC4 07_12: 11° → 47° in one 60-fps frame).
    A contact is not broken inside its stance (:func:`_unbroken_in_stance`), and a walk's contacts
    leave no frame with neither foot down (:func:`_double_support`)."""
    grot, gpos = motion.global_transforms()
    pts = mesh_sole_points(body)
    belt_speed = float(motion.metadata.get("belt_speed_mps", 0.0)) if motion.metadata.get("treadmill") else 0.0
    looped = bool(motion.metadata.get("looped"))
    stance = stance_from_events(motion, gpos)
    out = {}
    for s in ("l", "r"):
        sole = sole_positions(grot, gpos, pts[s])
        low = sole[:, :, 1].min(axis=1)
        # Zeni's toe off is late in running: keep only the frames the foot is still near its
        # stance height. Measured from the stance frames' median, not from the clip's lowest
        # point: the retargeted toes do not bend, so at push-off their tips dip 3–4 cm below the
        # flat foot, and from that dip the whole flat stance of a walk read as "not near" (the
        # Exp-2 men's average walk then floated 2 cm with 62 % of frames airborne).
        flat = np.median(low[stance[s]]) if stance[s].any() else np.percentile(low, 2)
        near = low - flat < STANCE_HEIGHT_M
        model = contact_mask(sole, motion.fps, belt_speed, flat, cyclic=looped)
        c = _unbroken_in_stance(stance[s] & near & model, stance[s], looped) if stance[s].any() else model
        out[s] = _dilate_near_ground(c, sole[:, :, 1].min(axis=1), looped)
    if motion.metadata.get("gait") == "walk":
        out = _double_support(out, looped)
    return out


def _double_support(contact: dict[str, np.ndarray], cyclic: bool) -> dict[str, np.ndarray]:
    """A walk's contacts with no frame where neither foot is down: through such frames the foot that
    was down last stays down (a later toe off) until the other lands. A walk has no flight (the
    loop is labelled a walk only where the capture's steady range flies too little to be a run),
    and a shuffle's events misplace toe off: CMU 131_02 at 0.3 m/s read both feet up for 3 of its
    37 frames, by Zeni's events as well as by the contact model; the clean-up lifted both feet 15
    mm or more there, and the physics step's ragdoll flew 9.6 % against its reference's 5.7 %.

    >>> c = {"l": np.array([1, 1, 0, 0, 0, 0, 1, 1], bool), "r": np.array([0, 0, 0, 0, 1, 1, 1, 0], bool)}
    >>> {s: v.astype(int).tolist() for s, v in _double_support(c, True).items()}
    {'l': [1, 1, 1, 1, 0, 0, 1, 1], 'r': [0, 0, 0, 0, 1, 1, 1, 0]}
    """
    out = {s: c.copy() for s, c in contact.items()}
    down = out["l"] | out["r"]
    if down.all() or not down.any():
        return out
    n = len(down)
    first = int(np.argmax(down))
    for t in (first + np.arange(n)) % n if cyclic else range(first, n):
        if out["l"][t] or out["r"][t]:
            continue
        before = (t - 1) % n
        held = [s for s in ("l", "r") if out[s][before]]
        # Both were down and both lift (a hop, not a walk): hold the one down longer, the trailing foot.
        side = max(held, key=lambda s: _run_back(out[s], before, cyclic))
        out[side][t] = True
    return out


def _run_back(contact: np.ndarray, t: int, cyclic: bool) -> int:
    """How many frames ``contact`` has been down up to and including frame ``t``."""
    k = 0
    while k < len(contact) and (cyclic or t - k >= 0) and contact[(t - k) % len(contact)]:
        k += 1
    return k


def _unbroken_in_stance(contact: np.ndarray, stance: np.ndarray, cyclic: bool) -> np.ndarray:
    """``contact`` with every break inside one stance (heel strike to toe off) closed: between its
    first and last contact frame of a stance the foot is down. A foot does not lift and land again
    within its own stance; a break there is the contact model reading a marker's jitter as speed
    (the hold-out Poser walk: one 30-fps frame at 1.0 m/s over the belt in mid-stance, between
    frames at 0.3-0.5). The clean-up lifted that foot 30 mm for the frame, and the physics step's
    ragdoll left the floor with it.

    >>> stance = np.array([0, 1, 1, 1, 1, 1, 0, 0], bool)
    >>> _unbroken_in_stance(np.array([0, 1, 1, 0, 1, 0, 0, 0], bool), stance, False).astype(int).tolist()
    [0, 1, 1, 1, 1, 0, 0, 0]
    """
    shift, runs = contact_runs(stance, cyclic)
    c = np.roll(contact, -shift)
    for start, stop in runs:
        down = np.flatnonzero(c[start:stop])
        if len(down):
            c[start + down[0]:start + down[-1] + 1] = True
    return np.roll(c, shift)


def _dilate_near_ground(contact: np.ndarray, low: np.ndarray, cyclic: bool, height: float = NEAR_GROUND_M) -> np.ndarray:
    """Grow each contact back over the frames before it whose lowest point is already near the
    ground: a landing foot grazing the ground must not slide. Not forward: after lift-off a foot
    near the ground is already swinging forward, and pinning it to its footprint stretched the leg
    back and snapped the knee (a CMU walk's 43° → 11° → 38°); the swing clearance lifts it instead."""
    c = contact.copy()
    if not c.any():
        return c
    for _ in range(2):
        grow = np.roll(c, -1) & ~c & (low < height)
        if not cyclic:
            grow[-1] = False
        if not grow.any():
            break
        c |= grow
    return c


def cleanup_feet(motion: Motion, body, balance_root: bool = True, foot_lock: bool = False) -> Motion:
    """Ground the body (lowest sole point of the planted feet at y = 0), then the contact clean-up;
    with ``foot_lock`` then the whole-clip foot-locking solve (``footfix.lock_feet``, contacts from
    ``contact.foot_contacts`` on the body's sole points). The metadata records how far the joints
    moved from the retargeted source: ``joint_change_max_deg`` (any joint but the toes) and
    ``joint_change_rms_deg`` (hips, knees and ankles), and ``toe_bend_max_deg``, the largest bend
    of the toes at the ball (:mod:`stimuli.motion.toes`)."""
    grot, gpos = motion.global_transforms()
    pts = mesh_sole_points(body)
    low = np.min([sole_positions(grot, gpos, pts[s])[:, :, 1].min(axis=1) for s in ("l", "r")], axis=0)
    # Shift the whole clip so its typical lowest foot point is on the ground (mocap floors vary).
    shifted = motion.root_translation.copy()
    shifted[:, 1] -= float(np.percentile(low, 10))
    m = motion.replace(root_translation=shifted)
    known = m.metadata.get("contacts")
    if known and all(len(known.get(s, [])) == m.n_frames for s in ("l", "r")):
        contact = {s: np.asarray(known[s], bool) for s in ("l", "r")}  # e.g. the generator's stance phases
        centre = False   # footprints a motion brings with its contacts stay where they were laid
    else:
        contact = planted(m, body)
        centre = True    # a capture's footprints are centred on its creeping feet (clean_feet)
    belt = float(m.metadata.get("belt_speed_mps", 0.0)) if m.metadata.get("treadmill") else 0.0
    cyclic = bool(m.metadata.get("looped"))
    out = clean_feet(m, contact, belt_speed=belt, cyclic=cyclic, points=pts, clearance_m=0.03, iterations=3,
                     bend_toes=True, centre_footprints=centre)
    walking = bool(np.all(contact["l"] | contact["r"]))
    if cyclic and balance_root and walking:
        # Move the pelvis so the ZMP follows the feet, then re-plant the feet where they were
        # (walks only: with a flight phase the cart-table model has no support to follow).
        balanced = balance(out, contact, points=pts)
        out = clean_feet(balanced, contact, belt_speed=belt, cyclic=True, points=pts, clearance_m=0.03, iterations=3,
                         reference=out, bend_toes=True, centre_footprints=centre)
    out = ease_edges(out, contact, belt_speed=belt, cyclic=cyclic)
    out = keep_knee_rate(out, m, contact, pts, cyclic=cyclic, bend_toes=True)
    if foot_lock:
        locked = foot_contacts(out, pts, floor_y=0.0)
        out, contact = lock_feet(out, locked, pts), locked.down
    out.metadata["contacts"] = {s: c.astype(int).tolist() for s, c in contact.items()}
    # The toes' bend is a joint the source does not move (retargeted toes keep their rest pose):
    # reported on its own, so that the joint change still says how far the clean-up moved the rest.
    toes = [j for s in ("l", "r") for j in toe_joints(out, s)]
    kept = out.rotations.copy()
    kept[:, toes] = motion.rotations[:, toes]
    biggest, rms = joint_change_deg(motion.rotations, kept, leg_joint_indices(motion))
    bend = float(np.degrees(quat.angle(out.rotations[:, toes])).max()) if toes else 0.0
    out.metadata.update(joint_change_max_deg=round(biggest, 2), joint_change_rms_deg=round(rms, 3),
                        toe_bend_max_deg=round(bend, 1))
    return out
