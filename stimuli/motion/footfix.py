"""Foot-contact clean-up: sole points, two-bone leg IK, planted feet that neither sink, float nor slide.

Each foot is reduced to three sole points rigidly attached to it (heel, ball, toe tip), found from
the rest pose. While a foot is in contact, its lowest sole point is pinned to the ground (y = 0) at
a horizontal anchor that moves backwards with the treadmill belt (zero overground); when the
lowest point changes (heel → ball during roll-over) the new point is anchored where it is, so the
foot rolls instead of sliding (a capture's footprint then moves to where its foot is on average
over the contact: ``clean_feet(centre_footprints=)``). The ankle target that results is reached
with analytic two-bone IK on hip and knee (Holden's formulation), keeping the foot's orientation.
If a target is out of reach the heel rises about the planted ball or toe (:func:`rise_heel`), and
only then is the pelvis lowered just enough (smoothly, over the loop); a swinging foot comes down
with the pelvis.

The knee is left to the source wherever the feet allow it: near full extension 1 cm of
hip-to-ankle distance is about 18° of knee, so pinning a foot at the source's pitch straightened
the knee late in stance and snapped it at toe off. Late in stance the foot rolls about its planted
ball or toe until the hip-to-ankle distance is the source's (:func:`roll_off`); the frames around
a contact carry its correction as a turn of the hip-to-ankle line (:func:`reblend`); and a
swinging foot that would pass below its clearance turns its toes up before the whole foot is
lifted (:func:`lift_toes`).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d, maximum_filter1d

from stimuli.motion import quat
from stimuli.motion.motion import Motion
from stimuli.motion.skeleton import role_indices

SIDES = ("l", "r")
PIVOT_SWITCH_M = 0.002
# Share of thigh + shank the leg IK may use (a locked knee has no bend plane).
REACH_FRACTION = 0.995
# Largest heel rise (foot turned about its ball or toe) used to reach a trailing footprint;
# push-off plantarflexion is 15-20° in walking and more in running.
MAX_HEEL_RISE_DEG = 35.0
# Most the hip-to-ankle line's heading may differ from the foot's own (backwards) for the heel to rise
# about the line's lateral axis; beyond it the foot's lateral axis is used (see _turn_heel).
HEEL_AXIS_OFF_DEG = 45.0
# Shape of the swing clearance's descent (see swing_clearance).
LANDING_POWER = 0.75
# Clearance from the first to the last frame of swing (skating counts points within 1 cm of the
# ground that move).
SWING_MIN_CLEARANCE_M = 0.015
# Most a swinging foot's toes turn up to clear the ground (swing dorsiflexion: from about 15°
# plantar flexion at toe off to neutral).
MAX_TOE_LIFT_DEG = 15.0
# Least extra clearance for which lift_toes turns the toes past the lowest point's first peak.
TOE_LIFT_GAIN_M = 0.001
# How long a contact's correction takes to blend in before it and out after it (4 frames at 30 fps).
BLEND_S = 4.0 / 30.0
# Fastest change of a swinging foot's toe lift (deg/s): the normative walk's own dorsiflexion speed
# in early swing (CGM2.3 mean ankle curve, stimuli/data/cgm23_walk.json: 131–144°/s at a 1.0–1.1 s
# stride). Set per frame, a lift ended within one frame: CMU 07_12's foot turned 39° in one 30-fps
# frame at toe off, where the capture turns 25°.
TOE_LIFT_RATE_DEG_S = 140.0
# How much faster than the source's a cleaned-up knee may turn, degrees per second (1.5° per 30-fps
# frame; issue 20's bound on knee snapping is the capture's largest change per 30-fps frame + 2°).
KNEE_RATE_DPS = 45.0
# A rest pose stands if its legs are within this of straight down and its feet of level.
STANDING_REST_DEG = 45.0
# A foot stands flat while its ankle and its toe joint both stay put (over the belt), low.
FLAT_FOOT_SPEED_MPS = 0.25
FLAT_FOOT_MIN_S = 0.1
FLAT_FOOT_BAND_M = 0.01


def sole_points(motion: Motion, floor_y: float | None = None) -> dict[str, list[tuple[int, np.ndarray]]]:
    """Per foot: [(joint index, offset in that joint's frame)] for heel, ball, toe tip.

    Found from the rest pose where it stands (legs and feet within :data:`STANDING_REST_DEG` of
    down and of level); the floor is then the lowest rest joint unless ``floor_y`` (rest-pose
    coordinates, root at origin) is given (e.g. from a mesh's lowest vertex). A rig whose rest does
    not stand (CC4: legs pointing up, toes up; Bandai: legs along x) gets them from the motion's
    flat feet instead (:func:`standing_sole_points`).

    >>> from stimuli.motion.generate import GaitParams, generate
    >>> pts = sole_points(generate(GaitParams(), 1.75))
    >>> len(pts["l"]), bool(pts["l"][0][1][1] < -0.05)      # heel, ball, tip; the heel below the ankle
    (3, True)
    """
    roles = role_indices(motion)
    rest = motion.rest_positions()
    if not rest_stands(motion, roles, rest):
        return standing_sole_points(motion, roles)
    y0 = rest[:, 1].min() if floor_y is None else floor_y
    out = {}
    for s in SIDES:
        a = roles[f"{s}_ankle"]
        toe = roles.get(f"{s}_toe")
        ends = motion.children(toe) if toe is not None else []
        tip_pos = rest[ends[0]] if ends else (rest[toe] if toe is not None else rest[a] + np.array([0, 0, 0.15]))
        fwd = tip_pos - rest[a]
        fwd[1] = 0.0
        length = max(np.linalg.norm(fwd), 1e-3)
        back = -fwd / length * 0.25 * length
        heel = np.array([0.0, y0 - rest[a, 1], 0.0]) + back
        pts = [(a, heel)]
        if toe is not None:
            ball = rest[toe] - rest[a]
            ball[1] = y0 - rest[a, 1]
            pts.append((a, ball))
            tip = tip_pos - rest[toe]
            tip[1] = y0 - rest[toe, 1]
            pts.append((toe, tip))
        else:
            pts.append((a, fwd + np.array([0.0, y0 - rest[a, 1], 0.0])))
        out[s] = pts
    return out


def _pitch_deg(v: np.ndarray) -> float:
    """How far a direction points below the horizontal, degrees."""
    return float(np.degrees(np.arcsin(np.clip(-v[1] / max(np.linalg.norm(v), 1e-12), -1.0, 1.0))))


def rest_stands(motion: Motion, roles: dict | None = None, rest: np.ndarray | None = None) -> bool:
    """Whether the rest pose (every rotation zero) stands: each hip→ankle line within
    :data:`STANDING_REST_DEG` of straight down and each ankle→toe line within it of level.

    CMU's rest legs are splayed 20° and its feet pitched 12–18°: standing. CC4's legs point up
    (180°) and Bandai's along x (90°): sole points read off such a rest lay 1 m from the foot.

    >>> from stimuli.motion.generate import GaitParams, generate
    >>> rest_stands(generate(GaitParams(), 1.75))
    True
    """
    roles = role_indices(motion) if roles is None else roles
    rest = motion.rest_positions() if rest is None else rest
    for s in SIDES:
        leg = rest[roles[f"{s}_ankle"]] - rest[roles[f"{s}_hip"]]
        if _pitch_deg(leg) < 90.0 - STANDING_REST_DEG:
            return False
        toe = roles.get(f"{s}_toe")
        if toe is not None and abs(_pitch_deg(rest[toe] - rest[roles[f"{s}_ankle"]])) > STANDING_REST_DEG:
            return False
    return True


def flat_frames(motion: Motion, gpos: np.ndarray, ankle: int, toe: int) -> np.ndarray:
    """Frames (T bool) where a foot stands flat: its ankle and toe joint both slower than
    :data:`FLAT_FOOT_SPEED_MPS` over the ground or belt, horizontally and vertically, and both
    within :data:`FLAT_FOOT_BAND_M` of their lowest (a heel rising slowly late in stance is not flat)."""
    from stimuli.motion.contact import ground_speed

    meta = motion.metadata
    belt = float(meta.get("belt_speed_mps", 0.0)) if meta.get("treadmill") else 0.0
    speed = ground_speed(gpos[:, [ankle, toe]], motion.fps, belt, bool(meta.get("looped")))
    height = gpos[:, [ankle, toe], 1]
    vertical = np.abs(np.gradient(height, 1.0 / motion.fps, axis=0)) if len(height) > 1 else np.zeros_like(height)
    low = height - np.percentile(height, 5, axis=0) < FLAT_FOOT_BAND_M
    return np.all((speed < FLAT_FOOT_SPEED_MPS) & (vertical < FLAT_FOOT_SPEED_MPS) & low, axis=1)


def _tip_joint(motion: Motion, rest: np.ndarray, ankle: int, toe: int | None) -> int:
    """The foot's farthest joint from the ankle in the rest pose: the toe's end site or a toe
    bone's (CC4 has five toe bones under its ball joint), the toe joint itself, or the ankle's end."""
    stack = [toe if toe is not None else ankle]
    found = []
    while stack:
        j = stack.pop()
        found.append(j)
        stack.extend(motion.children(j))
    return max(found, key=lambda j: np.linalg.norm(rest[j] - rest[ankle]))


def standing_sole_points(motion: Motion, roles: dict | None = None) -> dict[str, list[tuple[int, np.ndarray]]]:
    """Sole points (as :func:`sole_points`) from the motion's flat feet, for a rest that does not stand.

    On each frame a foot stands flat (:func:`flat_frames`; if fewer than :data:`FLAT_FOOT_MIN_S`,
    the tenth of the frames where its ankle and ball joint are lowest together) the sole lies level
    with the foot's lowest joint: the heel below the ankle, a quarter of the ankle→tip length back;
    the ball below the toe joint; the tip below the foot's farthest joint. Each is carried into its joint's frame there and averaged over those
    frames. A foot without a toe joint gets heel and tip on the ankle.
    """
    roles = role_indices(motion) if roles is None else roles
    rest = motion.rest_positions()
    grot, gpos = motion.global_transforms()
    out = {}
    for s in SIDES:
        a, toe = roles[f"{s}_ankle"], roles.get(f"{s}_toe")
        tip = _tip_joint(motion, rest, a, toe)
        ball = toe if toe is not None else tip
        use = flat_frames(motion, gpos, a, ball)
        if use.sum() < max(3, FLAT_FOOT_MIN_S * motion.fps):
            low = gpos[:, a, 1] + gpos[:, ball, 1]      # ankle and ball together at their lowest
            use = low <= np.percentile(low, 10)
        g = gpos[use]
        floor = g[:, [a, ball, tip], 1].min(axis=1)
        fwd = (g[:, tip] - g[:, a]) * np.array([1.0, 0.0, 1.0])

        def on_floor(p):
            return np.column_stack([p[:, 0], floor, p[:, 2]])

        world = [(a, on_floor(g[:, a] - 0.25 * fwd))]
        if toe is not None:
            world += [(a, on_floor(g[:, ball])), (toe, on_floor(g[:, tip]))]
        else:
            world.append((a, on_floor(g[:, tip])))
        out[s] = [(j, quat.rotate(quat.inv(grot[use, j]), p - g[:, j]).mean(axis=0)) for j, p in world]
    return out


def sole_positions(grot: np.ndarray, gpos: np.ndarray, points: list[tuple[int, np.ndarray]]) -> np.ndarray:
    """World positions (T×P×3) of one foot's sole points from global transforms."""
    return np.stack([gpos[:, j] + quat.rotate(grot[:, j], off) for j, off in points], axis=1)


# A knee bent more than this (degrees) shows the side it flexes to (see flexion_normal).
FLEXED_KNEE_DEG = 30.0


def flexion_normal(thigh: np.ndarray, bend_normal: np.ndarray, interior: np.ndarray) -> np.ndarray:
    """The normal of the plane a knee flexes in, in the thigh's frame: the mean, over the frames
    where the knee is bent more than :data:`FLEXED_KNEE_DEG` (over all frames if it never is), of
    ``bend_normal`` (T×3, world: hip→ankle × hip→knee, its length grows with the bend) turned into
    the thigh's frame (``thigh``: its world rotations, T×4); ``interior`` (T, radians) is the angle
    at the knee. A leg straight in every frame flexes about its thigh's −x axis (the Anny rig's knees).

    >>> thigh = np.tile([1.0, 0.0, 0.0, 0.0], (3, 1))
    >>> normal = np.array([[0.0, 0.0, -0.3], [0.0, 0.0, -1e-4], [0.0, 0.0, 0.5]])
    >>> flexion_normal(thigh, normal, np.radians([179.0, 179.9, 100.0])).tolist()   # the bent frame
    [0.0, 0.0, 1.0]
    >>> flexion_normal(thigh, normal, np.radians([170.0, 179.9, 160.0])).tolist()   # never bent 30°
    [0.0, 0.0, 1.0]
    >>> flexion_normal(thigh, 0.0 * normal, np.radians([180.0, 180.0, 180.0])).tolist()
    [-1.0, 0.0, 0.0]
    """
    flexed = interior < np.radians(180.0 - FLEXED_KNEE_DEG)
    if not flexed.any():
        flexed[:] = True
    total = quat.rotate(quat.inv(thigh[flexed]), bend_normal[flexed]).sum(axis=0)
    norm = float(np.linalg.norm(total))
    return total / norm if norm > 1e-9 else np.array([-1.0, 0.0, 0.0])


def two_bone_ik(motion: Motion, rot: np.ndarray, root: np.ndarray, side: str, target: np.ndarray,
                keep_foot: np.ndarray) -> np.ndarray:
    """Rotate hip and knee so the ankle reaches ``target`` (T×3); the foot keeps world rotation ``keep_foot``."""
    roles = role_indices(motion)
    hip, knee, ankle = roles[f"{side}_hip"], roles[f"{side}_knee"], roles[f"{side}_ankle"]
    grot, gpos = motion.global_transforms(rot, root)
    a, b, c = gpos[:, hip], gpos[:, knee], gpos[:, ankle]
    a_gr, b_gr = grot[:, hip], grot[:, knee]
    lab = np.linalg.norm(b - a, axis=1)
    lcb = np.linalg.norm(c - b, axis=1)
    lat = np.clip(np.linalg.norm(target - a, axis=1), 1e-4, (lab + lcb) * 0.9999)

    def unit(v):
        return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)

    def ang(u, v):
        return np.arccos(np.clip(np.sum(unit(u) * unit(v), axis=-1), -1.0, 1.0))

    ac_ab_0 = ang(c - a, b - a)
    ba_bc_0 = ang(a - b, c - b)
    ac_at_0 = ang(c - a, target - a)
    ac_ab_1 = np.arccos(np.clip((lcb**2 - lab**2 - lat**2) / (-2 * lab * lat), -1, 1))
    ba_bc_1 = np.arccos(np.clip((lat**2 - lab**2 - lcb**2) / (-2 * lab * lcb), -1, 1))
    axis0 = np.cross(c - a, b - a)
    forward = quat.rotate(a_gr, flexion_normal(a_gr, axis0, ba_bc_0))
    # A straight leg has no bend plane: it bends the way the knee flexes.
    straight = np.linalg.norm(axis0, axis=1) < 1e-6
    axis0[straight] = forward[straight]
    # A knee at or past straight the other way (the Bandai walk's −0.1° at heel strike) that must
    # bend more bends forward: bent further about its own plane it hyperextended 23–36°.
    # (More by a margin above rounding: a target at the ankle itself must not flip a knee.)
    flip = (np.sum(axis0 * forward, axis=1) < 0) & (ba_bc_1 < ba_bc_0 - 1e-6)
    axis0[flip] = -axis0[flip]
    ac_ab_0[flip] = -ac_ab_0[flip]
    ba_bc_0[flip] = 2 * np.pi - ba_bc_0[flip]
    axis0 = unit(axis0)
    axis1 = np.cross(c - a, target - a)
    axis1 = np.where(np.linalg.norm(axis1, axis=1, keepdims=True) < 1e-9, axis0, axis1)
    axis1 = unit(axis1)
    r0 = quat.from_axis_angle(quat.rotate(quat.inv(a_gr), axis0) * (ac_ab_1 - ac_ab_0)[:, None])
    r1 = quat.from_axis_angle(quat.rotate(quat.inv(b_gr), axis0) * (ba_bc_1 - ba_bc_0)[:, None])
    r2 = quat.from_axis_angle(quat.rotate(quat.inv(a_gr), axis1) * ac_at_0[:, None])
    out = rot.copy()
    out[:, hip] = quat.mul(rot[:, hip], quat.mul(r0, r2))
    out[:, knee] = quat.mul(rot[:, knee], r1)
    grot2, _ = motion.global_transforms(out, root)
    # The foot's parent may be a twist bone below the knee (Anny's lowerleg02).
    out[:, ankle] = quat.mul(quat.inv(grot2[:, motion.parents[ankle]]), keep_foot)
    return out


def _intervals(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) runs of True in a boolean array (not wrapping)."""
    d = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def blend_frames(fps: float) -> int:
    """Frames over which a contact's correction is blended in before it and out after it:
    :data:`BLEND_S` at any frame rate (4 frames at 30 fps). Counted in frames, a 120-fps capture
    blended over 33 ms and its knee jumped at heel strike: the CMU 35_01 walk on a 1.80 m BMI-27
    body changed its knee by up to 18.9° per 30-fps frame (the capture: 13.6°), now 13.9°.

    >>> blend_frames(30.0), blend_frames(60.0), blend_frames(120.0)
    (4, 8, 16)
    """
    return max(1, int(round(BLEND_S * fps)))


def contact_targets(sole: np.ndarray, ankle: np.ndarray, contact: np.ndarray, belt: np.ndarray,
                    fps: float, blend: int | None = None, cyclic: bool = True,
                    follow: np.ndarray | None = None, rear_pivot: bool = False,
                    centre: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ankle targets (T×3), blend weights (T) and the planted sole point of each contact frame (T:
    index into the foot's sole points, −1 out of contact) for one foot (see the module docstring).
    ``blend``: frames blended around each contact (default :func:`blend_frames` of ``fps``).

    In contact the targets come from ``sole`` and ``ankle``; the frames around a contact carry
    the correction at its first or last frame on the ankle path ``follow`` (default ``ankle``):
    the motion being cleaned, when the footprints come from a reference pose. ``rear_pivot``: a
    foot whose toes bend (:mod:`stimuli.motion.toes`) turns about the rearmost of the points it
    stands on (sole points within :data:`PIVOT_SWITCH_M` of its lowest; heel, ball, tip order), so
    it rolls over the ball with its toes flat, not over the tips of toes held straight. ``centre``:
    each footprint sits where the source's foot is on average over its contact along the belt too
    (always so sideways), instead of where it landed.
    """
    t_n = len(contact)
    blend = blend_frames(fps) if blend is None else blend
    if cyclic and contact.all():
        contact = contact.copy()
        contact[np.argmax(sole[:, :, 1].min(axis=1))] = False
    shift = _swing_middle(contact) if cyclic else 0
    roll = lambda x: np.roll(x, -shift, axis=0)  # noqa: E731
    sole_r, ankle_r, c_r = roll(sole), roll(ankle), roll(contact)
    follow_r = ankle_r if follow is None else roll(follow)
    target = ankle_r.copy()
    weight = np.zeros(t_n)
    pivots = np.full(t_n, -1)
    step = belt / fps
    for s, e in _intervals(c_r):
        anchor, pivot = None, -1
        for t in range(s, e):
            offsets = sole_r[t] - ankle_r[t]  # sole points relative to the ankle (foot orientation kept)
            heights = sole_r[t, :, 1]
            k = int(np.argmax(heights - heights.min() < PIVOT_SWITCH_M)) if rear_pivot else int(np.argmin(heights))
            # Hysteresis: a flat foot has tied points; switch pivot only for a clearly lower point.
            if pivot >= 0 and sole_r[t, pivot, 1] - sole_r[t, k, 1] < PIVOT_SWITCH_M:
                k = pivot
            if anchor is None:
                anchor = sole_r[t, k].copy()
            elif k != pivot:
                anchor = target[t - 1] + (sole_r[t - 1, k] - ankle_r[t - 1]) + step
            else:
                anchor = anchor + step
            pivot = pivots[t] = k
            anchor[1] = 0.0
            target[t] = anchor - offsets[k]
            weight[t] = 1.0
        # Keep the foot where the source puts it on average over the contact: sideways always, along
        # the belt when centred (see clean_feet).
        axes = [0, 2] if centre else [0]
        target[s:e, axes] += ankle_r[s:e, axes].mean(axis=0) - target[s:e, axes].mean(axis=0)
    # Blend the correction in before and out after each contact.
    for t, ref, w in _blend_frames(c_r, blend):
        target[t] = follow_r[t] + (target[ref] - follow_r[ref])
        weight[t] = w
    unroll = lambda x: np.roll(x, shift, axis=0)  # noqa: E731
    return unroll(target), unroll(weight), unroll(pivots)


def _swing_middle(contact: np.ndarray) -> int:
    """The middle frame of the longest run without contact (0 if there is none): rolled to the
    front, it keeps the blends before and after every contact inside the array (a contact ending
    on a looped clip's last frame used to lose its blend-out, and the clip jumped at its seam)."""
    if not contact.any() or contact.all():
        return 0
    n = len(contact)
    gaps = _intervals(~np.concatenate([contact, contact]))
    s, e = max(gaps, key=lambda g: min(g[1] - g[0], n))
    return (s + e) // 2 % n


def _blend_frames(contact: np.ndarray, blend: int) -> list[tuple[int, int, float]]:
    """(frame, contact frame it follows, weight) for the ``blend`` frames before and after each
    contact, cosine weights; where two blends meet the stronger wins (no wrapping)."""
    n, best = len(contact), {}
    for s, e in _intervals(contact):
        for d in range(1, blend + 1):
            w = 0.5 * (1 + np.cos(np.pi * d / (blend + 1)))
            for t, ref in ((s - d, s), (e - 1 + d, e - 1)):
                if 0 <= t < n and not contact[t] and w > best.get(t, (0, 0.0))[1]:
                    best[t] = (ref, w)
    return [(t, ref, w) for t, (ref, w) in best.items()]


def _blends(weight: np.ndarray, blend: int = 4) -> list[tuple[int, int, float]]:
    """(frame, contact frame it follows, weight) around the contacts (``weight`` 1) of a looped
    clip, as :func:`contact_targets` blends them."""
    contact = weight >= 1.0
    n, shift = len(weight), _swing_middle(contact)
    return [((t + shift) % n, (ref + shift) % n, w) for t, ref, w in _blend_frames(np.roll(contact, -shift), blend)]


def reblend(target: np.ndarray, weight: np.ndarray, follow: np.ndarray, hip: np.ndarray, blend: int = 4) -> np.ndarray:
    """Blended ankle targets of one foot for a looped clip, from its final contact-frame targets
    (``weight`` 1, as :func:`contact_targets` gives): each frame around a contact carries the
    correction of the contact's first or last frame onto the ankle path ``follow`` as a turn of
    the hip-to-ankle line and a change of its length (``hip``: T×3), so the knee changes as the
    source's does through lift-off and landing (a carried offset bent a near-straight knee by up
    to 20° in one frame); frames further away follow ``follow``. ``blend``: frames blended around
    each contact (:func:`blend_frames`).
    """
    out = follow.copy()
    contact = weight >= 1.0
    out[contact] = target[contact]
    for t, ref, w in _blends(weight, blend):
        out[t] = follow[t] + w * (_carry(target[ref], follow[ref], follow[t], hip[ref], hip[t]) - follow[t])
    return out


def reblend_feet(feet: np.ndarray, weight: np.ndarray, source: np.ndarray, blend: int = 4) -> np.ndarray:
    """Foot world rotations of a looped clip with the turn a contact's first or last frame gave
    the foot (``feet`` against ``source``) faded out over the frames around it, as the ankle
    targets are (without it the foot pitch jumped by the roll-off's heel rise at toe off)."""
    out = feet.copy()
    for t, ref, w in _blends(weight, blend):
        turn = quat.mul(feet[ref], quat.inv(source[ref]))
        out[t] = quat.slerp(source[t][None], quat.mul(turn, source[t])[None], np.array([w]))[0]
    return out


def _carry(target_ref: np.ndarray, follow_ref: np.ndarray, follow: np.ndarray, hip_ref: np.ndarray,
           hip: np.ndarray) -> np.ndarray:
    """``follow`` moved as ``follow_ref`` was to reach ``target_ref``: the hip-to-ankle line turned
    by the same angle and lengthened by the same amount."""
    u, v, w = follow_ref - hip_ref, target_ref - hip_ref, follow - hip
    nu, nv, nw = (max(float(np.linalg.norm(x)), 1e-9) for x in (u, v, w))
    axis = np.cross(u, v)
    angle = np.arctan2(np.linalg.norm(axis), np.dot(u, v))
    turn = quat.from_axis_angle(axis / max(float(np.linalg.norm(axis)), 1e-12) * angle)
    return hip + quat.rotate(turn, w) * (nw + nv - nu) / nw


def offsets_of(foot: np.ndarray, local: np.ndarray) -> np.ndarray:
    """Sole points relative to the ankle (T×P×3) for foot world rotations ``foot`` (T×4), from
    their positions in the foot's frame ``local`` (T×P×3)."""
    return quat.rotate(foot[:, None], local)


def lift_toes(ankle: np.ndarray, foot: np.ndarray, offsets: np.ndarray, floor: np.ndarray,
              swing: np.ndarray, max_rate: float | None = None, cyclic: bool = False) -> np.ndarray:
    """Foot rotations with a swinging foot's toes turned up (about the ankle, at most
    :data:`MAX_TOE_LIFT_DEG`) where its lowest sole point would pass below ``floor`` (T).

    In people the ankle dorsiflexes after push-off to clear the ground; lifting the whole foot
    instead bends a nearly straight knee sharply (1 cm ≈ 18°) in the first frames of swing.
    Turns the least that reaches the floor, else as far as the lowest point keeps rising (its first
    peak); beyond that only where the best turn lifts it at least :data:`TOE_LIFT_GAIN_M` more (a
    jog's toes pointing down at toe off sit at the bottom of their arc: they dip a fraction of a
    millimetre before rising). :func:`clean_feet` lifts the ankle for any rest. The best turn of the
    whole range flipped between none and the full :data:`MAX_TOE_LIFT_DEG` from frame to frame:
    a heel that is already the lowest point goes down as the toes come up, then up again, and a
    walk's last frame before heel strike turned its toes up 15° for 0.06 mm (on 4-cycle loops,
    whose seam then read 1.9–2.2; three women's walks pitched a foot 30–36° in one frame).
    ``max_rate`` (radians per frame): in the first half of each swing the lift then falls no faster
    than this — it fades out over the frames after the last that needs it instead of ending at once
    (:func:`cap_landing_turn` limits it before a heel landing); ``cyclic``: a swing across the clip's
    end goes on at its start.

    >>> toe_down = np.array([[[0.0, -0.02, -0.05], [0.0, -0.12, 0.12]]])  # heel, toe tip: toes pointing down
    >>> f = lift_toes(np.array([[0.0, 0.12, 0.0]]), np.array([[1.0, 0, 0, 0]]), toe_down, np.array([0.02]),
    ...               np.array([True]))
    >>> low = offsets_of(f, toe_down)[0, :, 1].min() + 0.12
    >>> bool(0.0195 < low < 0.0215)
    True
    """
    out = foot.copy()
    need = floor - (ankle[:, 1] + offsets[:, :, 1].min(axis=1))
    todo = np.flatnonzero(swing & (need > 0))
    if not len(todo):
        return out
    # Toes up: a turn about the horizontal axis across the foot, forward (heel → toe tip, the
    # first and last sole points) × up.
    fwd_all = offsets[:, -1] - offsets[:, 0]
    fwd_all[:, 1] = 0.0
    fwd_all /= np.maximum(np.linalg.norm(fwd_all, axis=1, keepdims=True), 1e-12)
    axis_all = np.cross(fwd_all, np.array([0.0, 1.0, 0.0]))
    axis = axis_all[todo]
    angles = np.radians(np.arange(0.0, MAX_TOE_LIFT_DEG + 0.25, 0.5))
    turns = quat.from_axis_angle(axis[:, None] * angles[None, :, None])          # todo × angles × 4
    lows = ankle[todo, 1, None] + quat.rotate(turns[:, :, None], offsets[todo][:, None])[..., 1].min(axis=2)
    reached = lows >= floor[todo, None]
    best = np.where(reached.any(axis=1), np.argmax(reached, axis=1), np.argmax(lows, axis=1))
    # Up to the first turn after which the lowest point no longer rises …
    rising = np.diff(lows, axis=1) > 0
    peak = np.where(rising.all(axis=1), len(angles) - 1, np.argmin(rising, axis=1))
    near = reached & (np.arange(len(angles)) <= peak[:, None])
    pick = np.where(near.any(axis=1), np.argmax(near, axis=1), peak)
    # … and further only for a clear gain in clearance.
    rows = np.arange(len(todo))
    gain = np.minimum(lows[rows, best], floor[todo]) - np.minimum(lows[rows, pick], floor[todo])
    pick = np.where(gain >= TOE_LIFT_GAIN_M, best, pick)
    lift = np.zeros(len(foot))
    lift[todo] = angles[pick]
    if max_rate is not None:
        # After toe off: later in swing the foot turns toes-up by itself, and a lift carried on
        # lowered the heel for landing (CMU 07_01: 23° more toes-up than the capture, then 38° in
        # one frame at heel strike). A carried lift keeps the axis it had where it was needed:
        # recomputed from the next frames' heading, it turned the foot sideways where the capture
        # turns it about its long axis (the hold-out Poser walk: 34.6° in one frame, capture 17°).
        lift, origin = rate_limited_envelope(lift, early_stance(swing, cyclic), max_rate, cyclic)
        axis_all = axis_all[origin]
    turned = np.flatnonzero(lift > 0)
    out[turned] = quat.mul(quat.from_axis_angle(axis_all[turned] * lift[turned, None]), foot[turned])
    return out


def cap_landing_turn(feet: np.ndarray, unlifted: np.ndarray, swing: np.ndarray, rate: float,
                     cyclic: bool = False) -> np.ndarray:
    """Foot rotations ``feet`` turned back towards ``unlifted`` where a toes-up swinging foot (a heel
    landing) is turned from it by more than ``rate`` times the frames left to its landing, or by
    more than ``rate`` beyond its turn the frame before (the lift comes in no faster either).

    Lifted 15° more toes-up in the two frames before heel strike, CMU 07_02's foot was laid flat by
    41° in one frame (the capture: 13°). A toes-down foot (a forefoot landing) keeps its lift, which
    turns it towards the flat foot it lands as (capped too, the Bandai dash's landing got worse)."""
    out = feet.copy()
    toes_up = quat.rotate(unlifted, np.array([0.0, 0.0, 1.0]))[:, 1] > 0
    landing = rate * frames_to_contact(swing, cyclic)
    turn = quat.angle(quat.mul(feet, quat.inv(unlifted)))
    n = len(feet)
    start = int(np.argmin(swing)) if cyclic and not swing.all() else 0
    previous = 0.0
    for k in range(n):
        t = (start + k) % n
        if not (swing[t] and toes_up[t]):
            previous = 0.0
            continue
        allowed = min(landing[t], previous + rate)
        if turn[t] > allowed + 1e-9:
            out[t] = quat.slerp(unlifted[t][None], feet[t][None], np.array([allowed / turn[t]]))[0]
            previous = allowed
        else:
            previous = turn[t]
    return out


def frames_to_contact(swing: np.ndarray, cyclic: bool = False) -> np.ndarray:
    """Per frame, the number of frames to the next frame out of ``swing`` (0 on such a frame; a
    swing running off the end of a clip that does not loop counts to one past its last frame).

    >>> frames_to_contact(np.array([0, 1, 1, 1, 0, 1], bool)), frames_to_contact(np.array([0, 1, 1, 1, 0, 1], bool), True)
    (array([0, 3, 2, 1, 0, 1]), array([0, 3, 2, 1, 0, 1]))
    """
    out = np.zeros(len(swing), int)
    shift, runs = contact_runs(swing, cyclic)
    for s, e in runs:
        out[s:e] = e - np.arange(s, e)
    return np.roll(out, shift)


def rate_limited_envelope(x: np.ndarray, inside: np.ndarray, rate: float,
                          cyclic: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(the least values ≥ ``x`` that fall by at most ``rate`` per frame within each run of
    ``inside`` frames, ``x`` itself outside them; per frame, the frame its value comes from).
    ``cyclic``: a run across the end goes on at the start.

    >>> y, origin = rate_limited_envelope(np.array([0, 0, 3.0, 0, 0, 0.5]), np.array([0, 1, 1, 1, 1, 0], bool), 1.0)
    >>> y, origin
    (array([0. , 0. , 3. , 2. , 1. , 0.5]), array([0, 1, 2, 2, 2, 5]))
    """
    n = len(x)
    shift = int(np.argmin(inside)) if cyclic and not inside.all() else 0
    y = np.roll(np.asarray(x, float), -shift)
    ins = np.roll(inside, -shift)
    origin = np.arange(n)
    for t in range(1, n):
        if ins[t] and ins[t - 1] and y[t - 1] - rate > y[t]:
            y[t], origin[t] = y[t - 1] - rate, origin[t - 1]
    return np.roll(y, shift), np.roll((origin + shift) % n, shift)


def swing_clearance(contact: np.ndarray, height: float) -> np.ndarray:
    """Minimum height of the lowest sole point over each swing, peaking at ``height`` mid-swing.

    The foot clears :data:`SWING_MIN_CLEARANCE_M` in every frame of swing (no toe grazing the
    belt after push-off, no heel before landing) and follows the half sine after push-off; a
    square-rooted half sine, steeper, asked a jog's toes for 3.7 cm one frame after toe off where
    the source has 1.5–2.2 cm, and the lift bent the knee 5–15° in that frame. It comes down more
    gently (the half sine to the power :data:`LANDING_POWER`): the
    leg is almost straight then, and every cm of lift late in swing costs degrees of knee flexion
    (last three frames before heel strike: 39/29/22° square-rooted, 37/26/17° here, 18/8/5° in
    the uncleaned normative angles); a plain or squared sine let the heel graze the belt (5–8 % of
    frames skating).
    """
    out = np.zeros(len(contact))
    if height <= 0 or contact.all() or not contact.any():
        return out
    shift = int(np.argmax(contact))
    c = np.roll(contact, -shift)
    for s, e in _intervals(~c):
        u = (np.arange(s, e) - s + 1) / (e - s + 1)
        rise = np.sin(np.pi * u)
        out[s:e] = np.maximum(min(SWING_MIN_CLEARANCE_M, height),
                              height * np.where(u < 0.5, rise, rise**LANDING_POWER))
    return np.roll(out, shift)


def clean_feet(motion: Motion, contacts: dict[str, np.ndarray], belt_speed: float = 0.0,
               floor_y: float | None = None, cyclic: bool = True, iterations: int = 2,
               clearance_m: float = 0.0, reference: Motion | None = None,
               points: dict | None = None, bend_toes: bool = False, centre_footprints: bool = False) -> Motion:
    """Apply the contact clean-up to a motion; ``contacts`` maps "l"/"r" to T booleans.

    ``clearance_m`` lifts a swinging foot whose lowest point would pass lower than a half-sine
    profile of that peak height (a foot must clear the ground, or it would scuff). ``reference``
    (same skeleton and length) supplies where planted feet go, e.g. the motion before the pelvis
    was moved for balance, so that moving the pelvis does not move the footprints. ``bend_toes``
    (a rig whose toes rest at the identity, ``points`` with the tip on a toe joint): planted toes
    bend at the ball (:func:`stimuli.motion.toes.level_toes`) and a foot turns about its ball.
    ``centre_footprints``: each footprint sits where the source's foot is on average over its
    contact, not where it landed. For a capture, whose planted foot creeps over the belt (marker
    drift, a belt speed read from both feet): anchored where it landed, the whole creep was left
    at toe off — the hold-out Poser walk's 19-frame stance ended 47 mm behind its capture, the leg
    reached back with its toes pitched up, and the clean-up's largest joint change on CMU 35_01 and
    07_01 was 34 and 41° (26 and 28° centred). Not for footprints someone laid (the generator's).
    """
    from stimuli.motion.toes import MAX_TOE_BEND_DEG, level_toes

    belt = np.array([0.0, 0.0, -belt_speed])
    points = sole_points(motion, floor_y) if points is None else points
    roles = role_indices(motion)
    rot, root = motion.rotations.copy(), motion.root_translation.copy()
    rot = flatten_feet(motion, rot, root, contacts, cyclic)
    if bend_toes:
        rot = level_toes(motion, rot, root, contacts, points, cyclic)
    _, src = motion.global_transforms()
    src_len = {s: np.linalg.norm(src[:, roles[f"{s}_ankle"]] - src[:, roles[f"{s}_hip"]], axis=1) for s in SIDES}
    rolls, unlifted = {}, {}
    rate = np.radians(TOE_LIFT_RATE_DEG_S) / motion.fps      # the toe lift's, per frame
    for it in range(iterations):
        grot, gpos = motion.global_transforms(rot, root)
        rgrot, rgpos = (grot, gpos) if reference is None or it > 0 else reference.global_transforms()
        targets, feet, free, foot_offsets, weights, toes = {}, {}, {}, {}, {}, {}
        for s in SIDES:
            ankle = gpos[:, roles[f"{s}_ankle"]]
            sole = sole_positions(grot, gpos, points[s])
            rsole = sole_positions(rgrot, rgpos, points[s])
            rankle = rgpos[:, roles[f"{s}_ankle"]]
            tgt, w, planted = contact_targets(rsole, rankle, contacts[s], belt, motion.fps, cyclic=cyclic, follow=ankle,
                                              rear_pivot=bend_toes, centre=centre_footprints)
            tgt = ankle + w[:, None] * (tgt - ankle)
            # Out of contact the foot follows the motion (blended into and out of its footprints).
            free[s], weights[s] = w == 0, w
            tgt[free[s]] = ankle[free[s]]
            foot = grot[:, roles[f"{s}_ankle"]]
            # The sole points in the foot's own frame, to place them for any foot rotation.
            foot_offsets[s] = quat.rotate(quat.inv(foot)[:, None], sole - ankle[:, None])
            reach = leg_reach(gpos, roles, s)
            toes[s] = None
            if bend_toes:
                ball_joint = points[s][1][0]
                toes[s] = (gpos[:, ball_joint] - ankle, np.radians(MAX_TOE_BEND_DEG) - quat.angle(rot[:, ball_joint]))
            targets[s], feet[s] = rise_heel(gpos[:, roles[f"{s}_hip"]], tgt, sole - ankle[:, None], foot, reach, planted,
                                            toes=toes[s])
            rolls[s] = (tgt, sole - ankle[:, None], foot, planted, reach)
        needs = targets
        if cyclic and bend_toes:
            # The frames around a contact are blended again from its final targets below (reblend):
            # their needs are those, heel rise included, not the footprint carried without it
            # (with bending toes the carried footprint lowered CMU 07_12's pelvis 4 cm at toe off).
            needs = {s: reblend(targets[s], weights[s], gpos[:, roles[f"{s}_ankle"]], gpos[:, roles[f"{s}_hip"]],
                                blend_frames(motion.fps)) for s in SIDES}
        lowered = _lower_pelvis(motion, gpos, roles, needs, root, cyclic)
        for s in SIDES:
            # Late in stance the foot rolls about its planted ball or toe so that the knee keeps
            # the source's bend (near a straight knee 1 cm of hip-to-ankle distance is ~18° of knee).
            tgt, offsets, foot, planted, reach = rolls[s]
            hip = gpos[:, roles[f"{s}_hip"]] + (lowered - root)
            late = roll_weight(contacts[s], cyclic=cyclic)
            rolled, turned = roll_off(hip, tgt, offsets, foot, planted, src_len[s], late, reach, toes=toes[s])
            done = late > 0
            targets[s][done], feet[s][done] = rolled[done], turned[done]
            # A swinging foot comes down with a lowered pelvis, its leg keeping its angles (held in
            # place, it bent the knee of a leg about to land: 23° instead of 6° before heel strike).
            follow = gpos[:, roles[f"{s}_ankle"]] + (lowered - root)
            if cyclic:
                targets[s] = reblend(targets[s], weights[s], follow, hip, blend_frames(motion.fps))
                feet[s] = reblend_feet(feet[s], weights[s], grot[:, roles[f"{s}_ankle"]], blend_frames(motion.fps))
            else:
                targets[s][free[s]] = follow[free[s]]
            # Never below the ground, in or out of contact; clear it in swing.
            floor = swing_clearance(contacts[s], clearance_m) if cyclic else np.zeros(motion.n_frames)
            unlifted.setdefault(s, feet[s].copy())
            feet[s] = lift_toes(targets[s], feet[s], offsets_of(feet[s], foot_offsets[s]), floor, ~contacts[s],
                                max_rate=rate, cyclic=cyclic)
            # Each pass lifts again where the clearance is still short: the landing cap holds for
            # the lifts of all passes together (three passes lifted CMU 07_02's toes-up foot 18°
            # in the frames before heel strike, each within its own cap).
            feet[s] = cap_landing_turn(feet[s], unlifted[s], ~contacts[s], rate, cyclic)
            low = offsets_of(feet[s], foot_offsets[s])[:, :, 1].min(axis=1)
            targets[s][:, 1] += np.maximum(0.0, floor - (low + targets[s][:, 1]))
        root = lowered
        for s in SIDES:
            rot = two_bone_ik(motion, rot, root, s, targets[s], feet[s])
        if bend_toes:
            rot = level_toes(motion, rot, root, contacts, points, cyclic)
    out = motion.replace(rotations=rot, root_translation=root)
    out.metadata["foot_cleanup"] = True
    return out


def contact_runs(contact: np.ndarray, cyclic: bool) -> tuple[int, list[tuple[int, int]]]:
    """(shift, [start, stop) contact runs of ``contact`` rolled left by shift). On a loop
    (``cyclic``) the roll starts in swing, so a contact across the clip's end is one run; otherwise
    the clip's own order, where a contact cut by its end or start is a run of its own."""
    shift = int(np.argmin(contact)) if cyclic and not contact.all() else 0
    return shift, _intervals(np.roll(contact, -shift))


def flat_weight(contact: np.ndarray, rise: float = 0.15, fall: float = 0.5, cyclic: bool = True) -> np.ndarray:
    """0…1 per frame: how flat a foot should be — ramps up over the first ``rise`` of each contact
    (heel strike → foot flat), holds, and ramps down after ``fall`` (heel rise before push-off)."""
    out = np.zeros(len(contact))
    shift, runs = contact_runs(contact, cyclic)
    for s, e in runs:
        u = (np.arange(s, e) - s + 0.5) / (e - s)
        out[s:e] = np.clip(np.minimum(u / rise, (1.0 - u) / (1.0 - fall)), 0.0, 1.0)
    return np.roll(out, shift)


def _contact_mean_yaw(yaw: np.ndarray, contact: np.ndarray, cyclic: bool = True) -> np.ndarray:
    """Heading per frame, constant (its circular mean) within each contact: a planted foot does
    not turn on the ground."""
    shift, runs = contact_runs(contact, cyclic)
    y = np.roll(yaw, -shift)
    for s, e in runs:
        y[s:e] = np.arctan2(np.sin(y[s:e]).mean(), np.cos(y[s:e]).mean())
    return np.roll(y, shift)


def roll_weight(contact: np.ndarray, start: float = 0.5, full: float = 0.75, cyclic: bool = True) -> np.ndarray:
    """0…1 per frame: how far the late-stance roll-off (:func:`roll_off`) applies — 0 until
    ``start`` of each contact (where :func:`flat_weight` lets the heel rise), 1 from ``full`` on."""
    out = np.zeros(len(contact))
    if contact.all():
        return out
    shift, runs = contact_runs(contact, cyclic)
    for s, e in runs:
        u = (np.arange(s, e) - s + 0.5) / (e - s)
        out[s:e] = np.clip((u - start) / (full - start), 0.0, 1.0)
    return np.roll(out, shift)


def early_stance(contact: np.ndarray, cyclic: bool = True) -> np.ndarray:
    """Frames in the first half of each contact."""
    out = np.zeros(len(contact), bool)
    if contact.all():
        return out
    shift, runs = contact_runs(contact, cyclic)
    for s, e in runs:
        out[s:s + (e - s + 1) // 2] = True
    return np.roll(out, shift)


def flatten_feet(motion: Motion, rot: np.ndarray, root: np.ndarray, contacts: dict[str, np.ndarray],
                 cyclic: bool = True) -> np.ndarray:
    """Turn planted feet flat on the ground (keeping their heading) during mid-stance.

    The rest pose stands flat, so a flat foot is a pure heading rotation of the rest orientation.
    ``cyclic``: the clip loops, so a contact running over its last frame goes on at its first.
    """
    roles = role_indices(motion)
    out = rot.copy()
    grot, _ = motion.global_transforms(rot, root)
    for s in SIDES:
        ankle, parent = roles[f"{s}_ankle"], motion.parents[roles[f"{s}_ankle"]]
        fwd = quat.rotate(grot[:, ankle], np.array([0.0, 0.0, 1.0]))
        yaw = _contact_mean_yaw(np.arctan2(fwd[:, 0], fwd[:, 2]), contacts[s], cyclic)
        flat = quat.from_axis_angle(np.stack([0 * yaw, yaw, 0 * yaw], -1))
        want = quat.slerp(grot[:, ankle], flat, flat_weight(contacts[s], cyclic=cyclic))
        # Before mid-stance the heel stays down: a foot pitching toes-down is laid flat instead
        # (otherwise the heel would lift and slide as the toes land).
        early = quat.rotate(want, np.array([0.0, 0.0, 1.0]))[:, 1] < 0
        early &= early_stance(contacts[s], cyclic)
        want[early] = flat[early]
        out[:, ankle] = quat.mul(quat.inv(grot[:, parent]), want)
    return out


def _lower_pelvis(motion, gpos, roles, targets, root, cyclic):
    """Lower the root where an ankle target lies beyond the leg's reach (smoothly over time)."""
    drop = np.zeros(motion.n_frames)
    for s in SIDES:
        hip = gpos[:, roles[f"{s}_hip"]]
        reach = leg_reach(gpos, roles, s)
        d = targets[s] - hip
        horiz = np.linalg.norm(d[:, [0, 2]], axis=1)
        need_y = np.sqrt(np.maximum(reach**2 - horiz**2, 0.0))
        drop = np.maximum(drop, -d[:, 1] - need_y)
    drop = np.maximum(drop, 0.0)
    if drop.max() <= 0:
        return root
    mode = "wrap" if cyclic else "nearest"
    # Widen, then smooth: the lowered pelvis follows a smooth curve that still covers every need.
    smooth = gaussian_filter1d(maximum_filter1d(drop, 7, mode=mode), 2.0, mode=mode)
    smooth = np.maximum(smooth, drop)
    out = root.copy()
    out[:, 1] -= smooth
    return out


def leg_reach(gpos: np.ndarray, roles: dict, side: str) -> float:
    """Hip-to-ankle distance the IK may use: thigh plus shank, just short of a locked knee."""
    hip, knee, ankle = (gpos[0, roles[f"{side}_{j}"]] for j in ("hip", "knee", "ankle"))
    return float(np.linalg.norm(knee - hip) + np.linalg.norm(ankle - knee)) * REACH_FRACTION


def _turn_about(pivot, arm, axis, angle):
    """``pivot + arm`` turned by ``angle`` (radians, per row) about ``axis`` through ``pivot``."""
    return pivot + quat.rotate(quat.from_axis_angle(axis * angle[:, None]), arm)


def _bisect(f, lo, hi, iterations: int = 20):
    """Per row, the angle in [lo, hi] where the boolean ``f`` turns from True to False."""
    for _ in range(iterations):
        mid = (lo + hi) / 2
        go = f(mid)
        lo, hi = np.where(go, mid, lo), np.where(go, hi, mid)
    return hi


def roll_off(hip: np.ndarray, target: np.ndarray, offsets: np.ndarray, foot: np.ndarray, planted: np.ndarray,
             want: np.ndarray, weight: np.ndarray, reach: float,
             toes: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Ankle targets and foot rotations with the foot turned about its planted ball or toe so that
    the hip-to-ankle distance moves towards ``want`` (T, the source's: its knee bend) by
    ``weight`` (T, 0…1), never beyond ``reach``.

    A knee near full extension turns hip-to-ankle distance into large angles (1 cm ≈ 18°), so
    a planted foot held at its source pitch straightens or snaps the knee in late stance; the
    heel pitch takes up the distance instead. The foot turns heel-up at most
    :data:`MAX_HEEL_RISE_DEG` and heel-down no further than flat (no sole point below the one it
    stands on). Frames not planted on a point ahead of the ankle, or with zero weight, are kept.
    ``toes`` as :func:`rise_heel`'s: a foot on its ball turns about the toe joint above it, then
    over its toe tips.

    >>> hip = np.array([[0.0, 0.9, 0.0]])
    >>> ball = np.array([[[0.0, -0.07, 0.15], [0.0, -0.07, -0.05]]])   # ball, heel (ankle-relative)
    >>> t, f = roll_off(hip, np.array([[0.0, 0.07, -0.4]]), ball, np.array([[1.0, 0, 0, 0]]), np.array([0]),
    ...                 np.array([0.9]), np.array([1.0]), 0.95)
    >>> round(float(np.linalg.norm(t[0] - hip[0])), 3), bool(t[0, 1] > 0.07)
    (0.9, True)
    """
    todo = np.flatnonzero(_planted_ahead(target, offsets, foot, planted) & (weight > 0))
    now = np.linalg.norm(target[todo] - hip[todo], axis=1)
    goal = np.minimum(now + weight[todo] * (want[todo] - now), reach)
    if toes is None:
        return _turn_heel(hip, target, offsets, foot, planted, todo, goal, heel_down=True)
    return _turn_on_toes(hip, target, offsets, foot, planted, todo, goal, True, toes)


def rise_heel(hip: np.ndarray, target: np.ndarray, offsets: np.ndarray, foot: np.ndarray, reach: float,
              planted: np.ndarray, toes: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Ankle targets (T×3) and foot world rotations (T×4) with the heel raised where out of reach.

    A trailing leg reaches its footprint at push-off by lifting the heel — the foot turns about
    the ball or toe it stands on — not by crouching. Where a frame's ankle target lies further
    from the hip than ``reach`` and its ``planted`` sole point (index into ``offsets``, the sole
    points relative to the ankle, T×P×3, in the foot's rotation ``foot``; −1 = none) is ahead of
    the ankle, the foot turns heel-up about that point, which stays put, by the smallest angle
    that brings the ankle within reach (at most :data:`MAX_HEEL_RISE_DEG`; :func:`_lower_pelvis`
    covers any rest). Elsewhere nothing changes.

    ``toes`` (bending toes, :mod:`stimuli.motion.toes`: the toe joint above the ball relative to the
    ankle, T×3, and how much further the toes can bend, T radians): a foot planted on its ball
    turns about that joint while its toes can bend, then over its toe tips
    (:func:`_turn_on_toes`), as a foot rolls over its toes once they are at their limit.

    >>> up = np.array([[0.0, 0.9, 0.0]])
    >>> toe = np.array([[[0.0, -0.07, 0.15]]])      # the ball, 15 cm ahead of and 7 cm below the ankle
    >>> t, f = rise_heel(up, np.array([[0.0, 0.07, -0.5]]), toe, np.array([[1.0, 0, 0, 0]]), 0.95, np.array([0]))
    >>> round(float(np.linalg.norm(t[0] - up[0])), 3), bool(t[0, 1] > 0.07)
    (0.95, True)
    """
    far = np.linalg.norm(target - hip, axis=1) > reach
    todo = np.flatnonzero(_planted_ahead(target, offsets, foot, planted) & far)
    if toes is None:
        return _turn_heel(hip, target, offsets, foot, planted, todo, np.full(len(todo), reach), heel_down=False)
    return _turn_on_toes(hip, target, offsets, foot, planted, todo, np.full(len(todo), reach), False, toes)


def _turn_on_toes(hip, target, offsets, foot, planted, todo, goal, heel_down: bool, toes):
    """:func:`_turn_heel` for a foot whose toes bend (``toes``: the toe joint above the ball
    relative to the ankle, T×3, and the toes' room to bend, T radians): planted on its ball
    (sole point 1) it turns about that joint, heel-up no further than the room; still short of
    ``goal``, it rolls on over its toe tips (the last sole point), which the turn about the joint
    left where they were, up to :data:`MAX_HEEL_RISE_DEG` in all."""
    hinge, room = toes
    on_ball = planted[todo] == 1
    ball = todo[on_ball]
    out, turned = _turn_heel(hip, target, offsets, foot, planted, todo[~on_ball], goal[~on_ball], heel_down)
    out, turned, used = _turn_foot(hip, out, offsets, turned, planted, ball, goal[on_ball], heel_down,
                                   pivot_offset=hinge[ball], most=room[ball])
    short = np.linalg.norm(out[ball] - hip[ball], axis=1) > goal[on_ball] + 1e-6
    last = ball[short]
    tips = target[last] + offsets[last, -1] - out[last]
    out, turned, _ = _turn_foot(hip, out, offsets, turned, planted, last, goal[on_ball][short], False,
                                pivot_offset=tips, most=np.radians(MAX_HEEL_RISE_DEG) - np.maximum(used[short], 0.0))
    return out, turned


def _planted_ahead(target, offsets, foot, planted) -> np.ndarray:
    """Frames whose planted sole point lies ahead of the ankle (a ball or toe, not the heel)."""
    pivot = target + offsets[np.arange(len(target)), np.maximum(planted, 0)]
    return (planted >= 0) & _ahead_of_ankle(pivot, target, foot)


def _ahead_of_ankle(point, ankle, foot) -> np.ndarray:
    """Per frame: ``point`` lies ahead of ``ankle`` along the foot's heading (horizontally)."""
    forward = quat.rotate(foot, np.array([0.0, 0.0, 1.0]))
    return np.einsum("ij,ij->i", (point - ankle)[:, [0, 2]], forward[:, [0, 2]]) > 0


def _turn_heel(hip, target, offsets, foot, planted, todo, goal, heel_down: bool):
    """Turn the foot of frames ``todo`` about its planted point until the ankle is ``goal`` from
    the hip: heel-up at most :data:`MAX_HEEL_RISE_DEG` and no further than the ankle straight above
    the pivot, heel-down (if allowed) until flat."""
    return _turn_foot(hip, target, offsets, foot, planted, todo, goal, heel_down)[:2]


def _turn_foot(hip, target, offsets, foot, planted, todo, goal, heel_down: bool, pivot_offset=None, most=None):
    """:func:`_turn_heel` with, for the ``todo`` frames, the pivot at ``pivot_offset`` from the ankle
    target (default: the planted sole point) and the heel rise capped at ``most`` (radians);
    returns the targets, the feet and the turn of each ``todo`` frame."""
    target, foot = target.copy(), foot.copy()
    if not len(todo):
        return target, foot, np.zeros(0)
    idx = planted[todo]
    off = offsets[todo, idx] if pivot_offset is None else pivot_offset
    pivot = target[todo] + off
    arm = target[todo] - pivot
    up = np.array([0.0, 1.0, 0.0])
    axis = np.cross(arm, up)
    axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12)
    # With the ankle almost over its planted toe the arm's horizontal part is short and points
    # anywhere: turned about it, a Bandai jog's foot flipped sideways (22 cm) or over its toe at
    # toe off. There the heel rises about the foot's own lateral axis.
    back = -quat.rotate(foot[todo], np.array([0.0, 0.0, 1.0])) * np.array([1.0, 0.0, 1.0])
    back /= np.maximum(np.linalg.norm(back, axis=1, keepdims=True), 1e-12)
    flat = arm * np.array([1.0, 0.0, 1.0])
    steep = np.einsum("ij,ij->i", flat, back) < np.cos(np.radians(HEEL_AXIS_OFF_DEG)) * np.linalg.norm(flat, axis=1)
    axis[steep] = np.cross(back[steep], up)
    lo = np.zeros(len(todo))
    if heel_down:
        # The other sole points relative to the pivot: heel-down stops where one touches the floor
        # (the planted point is on it; a pivot above it, a toe joint, is at its own height).
        others = offsets[todo] - off[:, None]
        floor = np.zeros(len(todo)) if pivot_offset is None else -pivot[:, 1]

        def below(angle):
            q = quat.from_axis_angle(axis * angle[:, None])
            return quat.rotate(q[:, None], others)[:, :, 1].min(axis=1) < floor - 1e-4

        lo = _bisect(below, np.full(len(todo), -np.radians(60.0)), lo)
    # The distance to the hip shrinks as the heel rises.
    # No foot rises further than its ankle straight above the pivot (35° more took the Bandai
    # jog's foot over its toe: the ankle 7 cm ahead of the toe tip, the ball joint sliding; on an
    # unseen toe-less walk the foot went to 84° below level against the capture's 61° and, nearly
    # vertical, spun 100° about its long axis in 5 frames).
    upright = np.arctan2(np.einsum("ij,ij->i", arm, np.cross(up, axis)), arm[:, 1])
    hi = np.clip(upright, 0.0, np.radians(MAX_HEEL_RISE_DEG))
    if most is not None:
        hi = np.minimum(hi, np.maximum(most, 0.0))
    angle = _bisect(lambda a: np.linalg.norm(_turn_about(pivot, arm, axis, a) - hip[todo], axis=1) > goal,
                    np.minimum(lo, hi), hi)
    target[todo] = _turn_about(pivot, arm, axis, angle)
    foot[todo] = quat.mul(quat.from_axis_angle(axis * angle[:, None]), foot[todo])
    return target, foot, angle


def least_above(x: np.ndarray, lo: np.ndarray, hi: np.ndarray, cyclic: bool = False) -> np.ndarray:
    """The least sequence at or above ``x`` whose step from frame t to t + 1 lies in [``lo[t]``,
    ``hi[t]``] (``lo`` ≤ 0 ≤ ``hi``): per frame, the most any frame's value forces on it
    (McShane–Whitney, with a bound per step), by one pass forward (what earlier frames force,
    falling at most ``lo`` a step) and one backward (later frames, rising at most ``hi``). A looped
    clip is solved on three copies of itself and its middle one kept.

    >>> least_above(np.array([0.0, 0.0, 6.0, 0.0]), np.full(4, -2.0), np.full(4, 2.0)).tolist()
    [2.0, 4.0, 6.0, 4.0]
    """
    n = len(x)
    y, lo, hi = (np.tile(np.asarray(v, float), 3 if cyclic else 1) for v in (x, lo, hi))
    for t in range(1, len(y)):
        y[t] = max(y[t], y[t - 1] + lo[t - 1])
    for t in range(len(y) - 2, -1, -1):
        y[t] = max(y[t], y[t + 1] - hi[t])
    return y[n:2 * n] if cyclic else y


def pivot_reach(hip: np.ndarray, pivot: np.ndarray, ankle: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """Ankle positions (T×3) ``reach`` (T) from the hip that keep their distance to the foot's
    ``pivot`` (its planted sole point), the nearest such to ``ankle``: the foot turns about its
    pivot while the leg swings about the hip. Where no such point exists, the nearest to both.

    >>> p = pivot_reach(np.array([[0.0, 1.0, 0.0]]), np.array([[0.0, 0.0, 0.1]]), np.array([[0.0, 0.1, 0.0]]),
    ...                 np.array([0.9]))
    >>> round(float(np.linalg.norm(p[0] - [0, 1, 0])), 6), round(float(np.linalg.norm(p[0] - [0, 0, 0.1])), 6)
    (0.9, 0.141421)
    """
    arm = np.linalg.norm(ankle - pivot, axis=1)
    axis = pivot - hip
    d = np.maximum(np.linalg.norm(axis, axis=1), 1e-9)
    u = axis / d[:, None]
    # The circle where the sphere about the hip meets the one about the pivot.
    along = np.minimum(np.clip((reach**2 - arm**2 + d**2) / (2.0 * d), d - arm, d + arm), reach)
    radius = np.sqrt(np.maximum(reach**2 - along**2, 0.0))
    side = (ankle - hip) - u * np.sum((ankle - hip) * u, axis=1, keepdims=True)
    side /= np.maximum(np.linalg.norm(side, axis=1, keepdims=True), 1e-12)
    return hip + u * along[:, None] + side * radius[:, None]


def keep_knee_rate(motion: Motion, reference: Motion, contacts: dict[str, np.ndarray], points: dict,
                   rate_dps: float | None = None, cyclic: bool = True, bend_toes: bool = False) -> Motion:
    """The motion with each knee turning between two frames no more than ``reference``'s knee (the
    motion before the clean-up) does there plus ``rate_dps`` degrees per second (:data:`KNEE_RATE_DPS`).

    Why: the clean-up's corrections switch on and off with the contacts; at a walk's toe off the
    planted toe held the foot back and the knee flexed 19° in one 30-fps frame where the capture
    turns it 13° at most (CMU 02_01). The knee is bent further than the clean-up bent it, as little
    as the limit allows (:func:`least_above`), and never straightened: a longer leg pushed planted
    toes and swinging feet through the floor (by up to 11 cm on the CC4 walks). The foot keeps its
    footprint with hip and ankle instead: a planted foot turns heel-up about its foremost sole point
    on the floor (within :data:`~stimuli.motion.contact.LOW_BAND_M` of the lowest) while the leg
    swings about the hip (:func:`pivot_reach`); a swinging foot rises along the hip-to-ankle line.
    A knee whose largest change between frames is within the source knee's largest + the margin is
    left untouched (generated gaits: the bound would only reshape a knee that never snaps).
    ``contacts`` maps "l"/"r" to T booleans; ``points`` as :func:`sole_points` gives them (heel first).
    ``bend_toes`` (as :func:`clean_feet`'s): a foot on its ball turns about the toe joint the ball
    hangs from, and its toes bend to stay on the floor (:func:`stimuli.motion.toes.level_toes`).
    """
    from stimuli.motion.contact import LOW_BAND_M
    from stimuli.motion.metrics import knee_angles
    from stimuli.motion.toes import MAX_TOE_BEND_DEG, level_toes

    margin = (KNEE_RATE_DPS if rate_dps is None else rate_dps) / motion.fps
    roles = role_indices(motion)
    rot, root = motion.rotations.copy(), motion.root_translation
    grot, gpos = motion.global_transforms()
    have, want = knee_angles(motion, gpos), knee_angles(reference)
    for s in SIDES:
        turn = np.diff(want[s], append=want[s][:1] if cyclic else want[s][-1:])
        turned = np.diff(have[s], append=have[s][:1] if cyclic else have[s][-1:])
        # A knee the clean-up turns no faster than the source's fastest (+ the margin) has no snap to
        # remove: left as it is (the per-frame bound still reshaped it, costing Float and stability
        # on generated gaits for no gain in the largest change).
        if np.abs(turned).max() <= np.abs(turn).max() + margin:
            continue
        depart = have[s] - want[s]
        bent = least_above(depart, -np.abs(turn) - margin - turn, np.abs(turn) + margin - turn, cyclic)
        todo = bent - depart > 1e-3
        if not todo.any():
            continue
        hip, knee, ankle = (gpos[:, roles[f"{s}_{j}"]] for j in ("hip", "knee", "ankle"))
        thigh, shank = np.linalg.norm(knee - hip, axis=1), np.linalg.norm(ankle - knee, axis=1)
        goal = np.sqrt(thigh**2 + shank**2 + 2.0 * thigh * shank * np.cos(np.radians(want[s] + bent)))
        line = ankle - hip
        target = hip + line * (goal / np.maximum(np.linalg.norm(line, axis=1), 1e-9))[:, None]
        target[~todo] = ankle[~todo]
        foot = grot[:, roles[f"{s}_ankle"]].copy()
        down = np.flatnonzero(todo & contacts[s])
        sole = sole_positions(grot[down], gpos[down], points[s])
        touching = sole[:, :, 1] <= sole[:, :, 1].min(axis=1, keepdims=True) + LOW_BAND_M
        front = np.where(touching, np.arange(sole.shape[1]), -1).max(axis=1)
        pivot = sole[np.arange(len(sole)), front]
        if bend_toes:
            # On its ball the foot turns about the toe joint above it, which the level toes keep
            # at its height (turned about the sole point below, the joint sank 1 cm at 45°); toes
            # at their limit turn with the foot, about its foremost point.
            ball_joint = points[s][1][0]
            room = np.radians(MAX_TOE_BEND_DEG) - quat.angle(rot[down, ball_joint])
            on_ball = touching[:, 1] & (room > np.radians(0.5))
            pivot[on_ball] = gpos[down[on_ball], ball_joint]
            tips = sole[:, -1]
        # Only a ball or toe ahead of the ankle is a pivot: turned about the heel (a landing foot
        # on its heel alone), the bend pitched the toes up by 29° in one frame on an unseen toe-less
        # walk. There the foot rises along the hip-to-ankle line, as a swinging one does.
        ahead = _ahead_of_ankle(pivot, ankle[down], foot[down])
        down, pivot = down[ahead], pivot[ahead]
        target[down] = pivot_reach(hip[down], pivot, ankle[down], goal[down])
        foot[down] = quat.mul(quat.between(pivot - ankle[down], pivot - target[down]), foot[down])
        if bend_toes:
            # A turn about the toe joint beyond the toes' room goes on about the toe tips.
            on_ball, room, tips = on_ball[ahead], room[ahead], tips[ahead]
            turn = quat.angle(quat.between(pivot - ankle[down], pivot - target[down]))
            over = np.flatnonzero(on_ball & (turn > room))
            if len(over):
                rows, joint = down[over], pivot[over]
                axis = np.cross(ankle[rows] - joint, target[rows] - joint)
                axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12)
                first = quat.from_axis_angle(axis * room[over, None])
                start = joint + quat.rotate(first, ankle[rows] - joint)
                target[rows] = pivot_reach(hip[rows], tips[over], start, goal[rows])
                foot[rows] = quat.mul(quat.between(tips[over] - start, tips[over] - target[rows]),
                                      quat.mul(first, grot[rows, roles[f"{s}_ankle"]]))
        rot = two_bone_ik(motion, rot, root, s, target, foot)
    if bend_toes:
        rot = level_toes(motion, rot, root, contacts, points, cyclic)
    return motion.replace(rotations=rot)


def _edge_runs(contact: np.ndarray, low: np.ndarray, cyclic: bool) -> list[tuple[int, list[int]]]:
    """Per contact edge: (the contact's first or last frame, the swing frames next to it, nearest
    first, while ``low``). On a loop the frames wrap round; otherwise they stop at the clip's ends."""
    t_n, out = len(contact), []
    if contact.all() or not contact.any():
        return out
    for t in range(t_n):
        if not contact[t]:
            continue
        for step in (-1, 1):
            nxt = t + step
            if not cyclic and not 0 <= nxt < t_n or contact[nxt % t_n]:
                continue
            run = []
            k = nxt
            while (cyclic or 0 <= k < t_n) and not contact[k % t_n] and low[k % t_n] and len(run) < t_n:
                run.append(k % t_n)
                k += step
            if run:
                out.append((t, run))
    return out


def ease_edges(motion: Motion, contacts: dict[str, np.ndarray], belt_speed: float = 0.0,
               cyclic: bool = True) -> Motion:
    """The motion with a landing foot already over its footprint while its HUMOS foot joint (the
    ball: ``metrics.foot_joints``) is within the HUMOS height of the ground before touchdown, and a
    lifting foot still over it while that joint is that low after toe off.

    Why: the clean-up pins a foot only from the contact's first frame, so the last swing frame, its
    foot joint already below 5 cm, still moved 0.5–1.6 m/s over the belt, and HUMOS counted that
    20-fps pair as a skate (CMU 35_17's run on the women's bodies: 7.1 %, one pair of 14). Each such
    frame's foot is moved horizontally by the distance that separates it from the contact's edge
    frame on the belt; the move fades in (before a landing) or out (after a toe off) over
    :data:`BLEND_S` seconds on the frames farther from the contact, the foot keeps its orientation
    and height, and hip and knee reach it (:func:`two_bone_ik`). Only an edge whose low frames move
    faster than HUMOS's speed over the belt is eased: a motion that does not skate there (every
    generated gait on its own rig, and its walks on a body) comes back unchanged. In a run (a clip
    with frames of flight) the frame after a low frame counts as low too: HUMOS's 20-fps pairs fall
    between 30-fps frames, and a generated jog on a body, its toes pushing off from the ball, left
    the floor from a 25-mm-high toe joint between two (F_Lo2: 5.9 % skate without this).

    >>> from stimuli.motion.generate import GaitParams, generate
    >>> m = generate(GaitParams(), 1.75)
    >>> c = {s: np.asarray(m.metadata["contacts"][s], bool) for s in SIDES}
    >>> ease_edges(m, c, float(m.metadata["belt_speed_mps"])) is m
    True
    """
    from stimuli.motion.metrics import HUMOS_HEIGHT_M, HUMOS_SPEED_MPS

    roles = role_indices(motion)
    grot, gpos = motion.global_transforms()
    t_n, fps = motion.n_frames, motion.fps
    fade = blend_frames(fps)
    rot = motion.rotations
    running = not np.all(contacts["l"] | contacts["r"])
    for s in SIDES:
        joint = roles.get(f"{s}_toe", roles[f"{s}_ankle"])
        # Horizontal place on the belt (a planted foot stays put there).
        place = gpos[:, joint][:, [0, 2]] + np.column_stack([np.zeros(t_n), np.arange(t_n) * belt_speed / fps])
        shift = np.zeros((t_n, 2))
        weight = np.zeros(t_n)
        low = gpos[:, joint, 1] < HUMOS_HEIGHT_M
        if running:
            # HUMOS samples at 20 fps: a pair can fall between a low frame and the next, where the
            # joint is still low (a jog's toes, pushing off from the ball, release it from 25 mm).
            low |= np.roll(low, 1)
        for edge, run in _edge_runs(contacts[s], low, cyclic):
            # Unwrapped frame numbers, so the belt's travel across a loop's seam counts.
            step = 1 if run[0] == (edge + 1) % t_n else -1
            frames = [edge + step * (i + 1) for i in range(len(run))]
            rel = np.array([_belt_place(place, f, t_n, belt_speed, fps) for f in [edge] + frames])
            speed = np.linalg.norm(np.diff(rel, axis=0), axis=1) * fps
            if speed.max() <= HUMOS_SPEED_MPS:
                continue
            held = rel[0] - rel[1:]
            for i, f in enumerate(run):
                shift[f], weight[f] = held[i], 1.0
            # Fade the last move over the frames beyond the run (farther from the contact).
            for i in range(1, fade + 1):
                f = frames[-1] + step * i
                if not cyclic and not 0 <= f < t_n or contacts[s][f % t_n]:
                    break
                w = 0.5 * (1.0 + np.cos(np.pi * i / (fade + 1)))
                if w > weight[f % t_n]:
                    shift[f % t_n], weight[f % t_n] = held[-1] * w, w
        if not weight.any():
            continue
        ankle = roles[f"{s}_ankle"]
        target = gpos[:, ankle].copy()
        target[:, [0, 2]] += shift
        rot = two_bone_ik(motion, rot, motion.root_translation, s, target, grot[:, ankle])
    return motion if rot is motion.rotations else motion.replace(rotations=rot)


def _belt_place(place: np.ndarray, frame: int, t_n: int, belt_speed: float, fps: float) -> np.ndarray:
    """Where frame ``frame`` (unwrapped: may be < 0 or ≥ T on a loop) of a foot is on the belt."""
    wraps = frame // t_n
    return place[frame % t_n] + np.array([0.0, wraps * t_n * belt_speed / fps])


# ---------------------------------------------------------------------------- whole-clip foot locking
# Time constants of the foot-locking solve, in seconds (the same at any frame rate): how fast a
# correction fades once a foot leaves the ground, and how fast a landing foot settles onto the floor.
LOCK_RELEASE_S = 0.12
LOCK_SETTLE_S = 0.03
# Task weights: contact points pinned hard, swinging sole points led along their path, the feet's
# orientation, the pelvis and every joint held lightly (so that joints change no more than the pins
# need).
LOCK_PIN_COST = 100.0
LOCK_PELVIS_COST = (5.0, 1.0)
LOCK_POSTURE_COST = 1.0
LOCK_SWING_COST = 10.0
LOCK_FOOT_TURN_COST = 5.0
# A planted foot's lowest point may stay this far above the floor where the source has it so.
LOCK_HOVER_M = 0.003
# Joints other than hip, knee and ankle (toes, twist bones, a pelvis-to-hip bone) change reluctantly:
# free toes spun 58° to keep heel, ball and toe tip all on their footprints.
LOCK_OTHER_POSTURE_COST = 10.0
LOCK_ITERATIONS = 4
# Largest knee flexion the solve may leave (degrees; 0 = straight).
KNEE_LIMIT_DEG = 160.0


def _leg_joints(motion: Motion, points: dict) -> list[int]:
    """The joints from the root down to every joint carrying a sole point (sorted, root first)."""
    keep = {0}
    for pts in points.values():
        for j, _ in pts:
            while j > 0 and j not in keep:
                keep.add(j)
                j = int(motion.parents[j])
    return sorted(keep)


def leg_model_xml(motion: Motion, points: dict) -> tuple[str, list[int]]:
    """MJCF of the motion's root and leg chains (ball joints, a free root, one site per sole
    point), and the motion joints it holds in body order. Rest pose = identity rotations, as in
    :class:`~stimuli.motion.motion.Motion`."""
    joints = _leg_joints(motion, points)
    kids = {j: [k for k in joints if k > 0 and motion.parents[k] == j] for j in joints}
    sites = {j: [] for j in joints}
    for s, pts in points.items():
        for i, (j, off) in enumerate(pts):
            sites[j].append((f"{s}{i}", off))

    def body(j: int, depth: int) -> str:
        pad = "  " * depth
        pos = "0 0 0" if j == 0 else " ".join(f"{v:.6g}" for v in motion.offsets[j])
        joint = '<freejoint name="j0"/>' if j == 0 else f'<joint name="j{j}" type="ball"/>'
        inner = [f'{pad}  {joint}', f'{pad}  <geom type="sphere" size="0.01" mass="1" contype="0" conaffinity="0"/>']
        inner += [f'{pad}  <site name="{n}" pos="{" ".join(f"{v:.6g}" for v in off)}"/>' for n, off in sites[j]]
        inner += [body(k, depth + 1) for k in kids[j]]
        return f'{pad}<body name="b{j}" pos="{pos}">\n' + "\n".join(inner) + f"\n{pad}</body>"

    return f'<mujoco><worldbody>\n{body(0, 1)}\n</worldbody></mujoco>', joints


def joint_change_deg(before: np.ndarray, after: np.ndarray, rms_joints: list[int] | None = None) -> tuple[float, float]:
    """Largest rotation (degrees) between two sets of local joint rotations (T×J×4), over every joint,
    and the RMS over the frames of ``rms_joints`` (default every joint; a rig's untouched fingers
    would dilute it).

    >>> q = np.tile([1.0, 0, 0, 0], (2, 3, 1))
    >>> r = q.copy(); r[1, 2] = [np.cos(np.pi / 12), np.sin(np.pi / 12), 0, 0]   # one joint 30°, once
    >>> tuple(round(x, 1) for x in joint_change_deg(q, r, rms_joints=[2]))
    (30.0, 21.2)
    """
    d = np.abs(np.sum(before * after, axis=-1)).clip(0.0, 1.0)
    ang = np.degrees(2.0 * np.arccos(d))
    sub = ang if rms_joints is None else ang[:, list(rms_joints)]
    return float(ang.max()), float(np.sqrt(np.mean(sub**2)))


def leg_joint_indices(motion: Motion) -> list[int]:
    """Hips, knees and ankles (the joints a foot clean-up is about): the RMS joint change is over these."""
    roles = role_indices(motion)
    return [roles[f"{s}_{r}"] for s in SIDES for r in ("hip", "knee", "ankle") if f"{s}_{r}" in roles]


def lock_feet(motion: Motion, contacts=None, points: dict | None = None, floor_y: float = 0.0) -> Motion:
    """Whole-clip foot locking: inverse kinematics (``mink`` on a MuJoCo model of the leg chains),
    frame by frame in time order, with

    * every sole point of a foot in contact that is within ``contact.LOW_BAND_M`` of the foot's
      lowest point (read on the motion given, so a rolling foot lets go heel first) pinned where it
      was a frame before it joined (carried by the belt on a treadmill clip), at its height in the
      motion moved as little as brings the foot's lowest point within :data:`LOCK_HOVER_M` above the
      floor (a landing point settles there over :data:`LOCK_SETTLE_S`);
    * every other sole point led along its own path plus its offset of the frame before, faded over
      :data:`LOCK_RELEASE_S`, never below the floor; each foot held lightly to its own orientation;
    * the pelvis held lightly to its pose, every leg joint to its angle, both plus the correction
      of the frame before faded over :data:`LOCK_RELEASE_S` — out of contact the motion returns to
      the one given smoothly, in seconds whatever the frame rate;
    * knee flexion at most :data:`KNEE_LIMIT_DEG`.

    A looped clip (metadata ``looped``) is solved twice round, so its seam carries the corrections
    of its end into its start; any other clip is solved once, with no wrap-around. ``contacts``: a
    :class:`~stimuli.motion.contact.Contacts` whose ``down`` says which frames a foot is planted
    (default: :func:`~stimuli.motion.contact.foot_contacts` with ``points``). The metadata records,
    from the motion given, ``joint_change_max_deg`` (any joint) and ``joint_change_rms_deg`` (hips,
    knees, ankles: :func:`leg_joint_indices`), and ``pin_error_max_mm`` (the farthest a pinned point
    ended from its pin: where a leg cannot reach).
    """
    import mink
    import mujoco

    from stimuli.motion.contact import LOW_BAND_M, foot_contacts

    points = sole_points(motion) if points is None else points
    contacts = foot_contacts(motion, points, floor_y=floor_y) if contacts is None else contacts
    xml, joints = leg_model_xml(motion, points)
    model = mujoco.MjModel.from_xml_string(xml)
    config = mink.Configuration(model)
    fps, n = motion.fps, motion.n_frames
    belt = contacts.belt_speed
    sides = [s for s in SIDES if s in points]
    names = {s: [f"{s}{i}" for i in range(len(points[s]))] for s in sides}
    pins = {nm: mink.FrameTask(nm, "site", position_cost=0.0, orientation_cost=0.0) for s in sides for nm in names[s]}
    pelvis = mink.FrameTask("b0", "body", position_cost=LOCK_PELVIS_COST[0], orientation_cost=LOCK_PELVIS_COST[1])
    roles = role_indices(motion)
    cost = {roles[f"{s}_{r}"]: LOCK_POSTURE_COST for s in sides for r in ("hip", "knee", "ankle") if f"{s}_{r}" in roles}
    posture = mink.PostureTask(model, cost=np.concatenate(
        [np.zeros(6)] + [np.full(3, cost.get(j, LOCK_OTHER_POSTURE_COST)) for j in joints[1:]]))
    # Each foot keeps its source orientation in the world unless its pins need otherwise: heel, ball
    # and toe tip lie on one line, so the pins alone left the foot free to roll and its mesh edge dug in.
    feet = {s: mink.FrameTask(f"b{roles[f'{s}_ankle']}", "body", position_cost=0.0, orientation_cost=LOCK_FOOT_TURN_COST)
            for s in sides}
    tasks = [pelvis, posture, *pins.values(), *feet.values()]
    # qpos of every frame of the source: free root (position, w-first quaternion), then ball joints.
    src_q = np.concatenate([motion.root_translation, motion.rotations[:, 0]]
                           + [motion.rotations[:, j] for j in joints[1:]], axis=1)
    cyclic = bool(motion.metadata.get("looped"))
    order = list(range(n)) * (2 if cyclic else 1)
    carry = np.zeros(model.nv)
    decay = float(np.exp(-1.0 / (fps * LOCK_RELEASE_S)))
    settle = float(np.exp(-1.0 / (fps * LOCK_SETTLE_S)))
    anchor: dict[str, np.ndarray | None] = {nm: None for nm in pins}
    last: dict[str, np.ndarray | None] = {nm: None for nm in pins}   # each point's solved place a frame ago
    pin_error = 0.0
    prev_src: dict[str, np.ndarray] = {}
    grot, gpos = motion.global_transforms()
    src_pts = {s: sole_positions(grot, gpos, points[s]) for s in sides}   # the sole points as given
    out_q = src_q.copy()
    knees = {s: tuple(roles[f"{s}_{r}"] for r in ("hip", "knee", "ankle")) for s in sides}
    for step, t in enumerate(order):
        want = src_q[t].copy()
        mujoco.mj_integratePos(model, want, carry * decay, 1.0)
        config.update(want)
        posture.set_target(want)
        pelvis.set_target(mink.SE3.from_rotation_and_translation(mink.SO3(want[3:7]), want[:3]))
        for s in sides:
            world = np.array([config.get_transform_frame_to_world(nm, "site").translation() for nm in names[s]])
            # Which points touch, and how far above the lowest, is read on the source: on the
            # solved pose the pins would keep a rolling foot flat for ever.
            src = src_pts[s][t]
            lowest = src[:, 1].min()
            low = src[:, 1] <= lowest + LOW_BAND_M
            for i, nm in enumerate(names[s]):
                if contacts.down[s][t] and low[i]:
                    if anchor[nm] is None:
                        # Where it was a frame ago (then carried by the belt): a point that lands
                        # stops there, and one that joins a planted foot is where that foot holds it
                        # (the source pose would put it elsewhere, and the foot would slide to it).
                        anchor[nm] = (world[i] if last[nm] is None else last[nm]).copy()
                    anchor[nm][2] -= belt / fps
                    # At the source's height, moved as little as brings the foot's lowest point within
                    # LOCK_HOVER_M above the floor (the foot keeps the source's tilt, heel strike to
                    # push-off; pulled onto the floor exactly, a rolling mesh sole dug in), a landing
                    # point settling there over LOCK_SETTLE_S.
                    level = src[i, 1] - (lowest - np.clip(lowest, floor_y, floor_y + LOCK_HOVER_M))
                    anchor[nm][1] = level + (anchor[nm][1] - level) * settle
                    pins[nm].set_position_cost(LOCK_PIN_COST)
                    pins[nm].set_target(mink.SE3.from_translation(anchor[nm]))
                else:
                    # A foot off the ground follows its own path in the source, plus the offset it had
                    # a frame ago fading with LOCK_RELEASE_S (held by the joints alone, it came down
                    # with a pelvis lowered for the other foot and scuffed the ground), never below the
                    # floor (a FrameTask weighs its error in the site's own axes, hence a whole target).
                    anchor[nm] = None
                    goal = src[i] if last[nm] is None else src[i] + decay * (last[nm] - prev_src[s][i])
                    goal[1] = max(goal[1], floor_y)
                    pins[nm].set_position_cost(LOCK_PIN_COST if world[i, 1] < floor_y else LOCK_SWING_COST)
                    pins[nm].set_target(mink.SE3.from_translation(goal))
            prev_src[s] = src
            feet[s].set_target(mink.SE3.from_rotation_and_translation(
                mink.SO3(grot[t, roles[f"{s}_ankle"]]), gpos[t, roles[f"{s}_ankle"]]))
        for _ in range(LOCK_ITERATIONS):
            vel = mink.solve_ik(config, tasks, 1.0, "daqp", damping=1e-3)
            config.integrate_inplace(vel, 1.0)
        for nm in pins:
            last[nm] = config.get_transform_frame_to_world(nm, "site").translation().copy()
            if anchor[nm] is not None and step >= len(order) - n:
                pin_error = max(pin_error, float(np.linalg.norm(last[nm] - anchor[nm])))
        q = config.q.copy()
        out_q[t] = q
        carry = np.zeros(model.nv)
        mujoco.mj_differentiatePos(model, carry, 1.0, src_q[t], q)
    rot = motion.rotations.copy()
    rot[:, 0] = out_q[:, 3:7]
    for k, j in enumerate(joints[1:]):
        rot[:, j] = out_q[:, 7 + 4 * k: 11 + 4 * k]
    out = motion.replace(rotations=rot, root_translation=out_q[:, :3].copy())
    out = _limit_knees(out, knees)
    biggest, rms = joint_change_deg(motion.rotations, out.rotations, leg_joint_indices(motion))
    out.metadata.update(foot_locked=True, joint_change_max_deg=round(biggest, 2), joint_change_rms_deg=round(rms, 3),
                        pin_error_max_mm=round(1000.0 * pin_error, 2))
    return out


def _limit_knees(motion: Motion, knees: dict) -> Motion:
    """Knee flexion above :data:`KNEE_LIMIT_DEG` brought back to it (the hip-to-ankle line kept)."""
    grot, gpos = motion.global_transforms()
    rot = motion.rotations.copy()
    changed = False
    for s, (hip, knee, ankle) in knees.items():
        thigh, shank = gpos[:, knee] - gpos[:, hip], gpos[:, ankle] - gpos[:, knee]
        cosang = np.sum(thigh * shank, 1) / np.linalg.norm(thigh, axis=1) / np.linalg.norm(shank, axis=1)
        flex = np.degrees(np.arccos(np.clip(cosang, -1.0, 1.0)))
        bad = flex > KNEE_LIMIT_DEG
        if not bad.any():
            continue
        axis = np.cross(thigh[bad], shank[bad])
        axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12)
        back = quat.from_axis_angle(-axis * np.radians(flex[bad] - KNEE_LIMIT_DEG)[:, None])
        # Turn the shank back in the world, expressed in the knee's parent frame.
        parent = grot[bad, motion.parents[knee]]
        rot[bad, knee] = quat.mul(quat.mul(quat.inv(parent), quat.mul(back, parent)), rot[bad, knee])
        changed = True
    return motion.replace(rotations=rot) if changed else motion
