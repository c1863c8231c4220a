"""The thesis's five-parameter walk modifier (Shewhorak 2017, ch. 8 and Appendix D; SPEC §1.3).

Inputs: height H (m), body-fat BF (%), optionally chest (m) and waist-to-hip ratio (otherwise
interpolated from BF between the lean baseline and 35 % as the thesis script does). Outputs, in
order of perceptual dominance: a speed ratio (retime: cadence and speed scale, step length kept),
an arm abduction offset (°, mean shift), a walking-base offset (cm, added to each foot
laterally — the thesis's Softimage script offsets each heel by it), an arm-bob ratio and an
arm-swing ratio (arm curves scaled about their mean: v′ = (v − mean)·ratio + mean), plus the
height scale H / 1.758.

The perceptual surveys' strengths are below it: Table 4-1 (point-light survey, ch. 4) and the rows
Table 5-2 (character mesh survey, ch. 5) adds, together ``STRENGTH_ROWS``. ``table_strengths`` looks
up named rows at a body-fat %, ``modify_strengths`` applies them with the same operations plus hip
twist, torso twist, torso swagger and spinal erectness, which the five-parameter modifier does not
model.

Examples
--------
>>> p = thesis_parameters(1.83, 34.1)
>>> round(p["speed_ratio"], 6), round(p["swing_ratio"], 6)
(1.077012, 1.286497)
"""

from __future__ import annotations

import numpy as np

from stimuli.errors import StimuliError
from stimuli.motion import quat
from stimuli.motion.footfix import two_bone_ik
from stimuli.motion.loop import retime
from stimuli.motion.motion import Motion
from stimuli.motion.skeleton import role_indices

# Baselines of the lean actor "MP" (Appendix D, lines 15–25).
LEAN = {"speed": 1.2154, "abduction": 7.7564, "base": 55.0658, "bob": 7.97632, "swing": 22.269,
        "height": 1.758, "wthr": 0.83, "wthr_bf35": 0.95, "chest": 0.98, "chest_bf35": 1.14}


def _lerp(a: float, b: float, t: float) -> float:
    return (1 - t) * a + t * b


# Units of the walking base. The thesis script labels the regression's walking base "cm" and
# converts with cmToSi = 0.1, which would put AE's heels 31 cm further out each and a lean walker's
# step width at 55 cm; normal adult step width is 8-12 cm. Read as millimetres the numbers are
# physical (lean 5.5 cm, AE 8.6 cm) and so are Table 4-1's heel offsets read as centimetres
# (-1 ... 4 cm per heel). ``base_scale=10`` restores the script's literal reading.
WALKING_BASE_UNIT_M = 0.001


def thesis_parameters(height_m: float, body_fat_pct: float, chest_m: float | None = None,
                      wthr: float | None = None) -> dict:
    """The modifier's intermediate values and the five modifiers, exactly as the thesis script."""
    if not (0.5 < height_m < 2.5) or not (0.0 <= body_fat_pct < 80.0):
        raise StimuliError(f"modifier: height {height_m} m or body fat {body_fat_pct} % out of range "
                           "(expected 0.5–2.5 m and 0–80 %)")
    t = (body_fat_pct - 12.0) / (35.0 - 12.0)
    wthr = _lerp(LEAN["wthr"], LEAN["wthr_bf35"], t) if wthr is None else wthr
    chest = _lerp(LEAN["chest"], LEAN["chest_bf35"], t) if chest_m is None else chest_m
    speed = -1.07 + 1.3 * height_m
    abduction = -31.424 + 39.98 * chest
    base = -167.59 + 268.26 * wthr
    bob = -13.19 + 12.04 * height_m
    swing = 18.76 + 0.29 * body_fat_pct
    return {"t": t, "wthr": wthr, "chest_m": chest, "speed_mps": speed, "abduction_deg": abduction,
            "base_mm": base, "bob_deg": bob, "swing_deg": swing,
            "speed_ratio": speed / LEAN["speed"], "abduction_offset_deg": abduction - LEAN["abduction"],
            "base_offset_mm": base - LEAN["base"], "bob_ratio": bob / LEAN["bob"],
            "swing_ratio": swing / LEAN["swing"], "height_scale": height_m / LEAN["height"]}


def _arm_angles(rot_local: np.ndarray, sign: float, rest_dir: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Abduction and flexion (rad) of an upper arm in its parent's rest-aligned frame, from its
    local rotation and its rest direction (any rest pose: arms down, A-pose or T-pose)."""
    d = quat.rotate(rot_local, rest_dir)
    abd = np.arctan2(sign * d[:, 0], -d[:, 1])
    flex = np.arctan2(d[:, 2], -d[:, 1])
    return abd, flex


def _scale_arm(rot: np.ndarray, j: int, sign: float, bob: float, swing: float, offset_rad: float,
               rest_dir: np.ndarray) -> None:
    """Scale the abduction (bob) and flexion (swing) curves of one upper arm about their means."""
    abd, flex = _arm_angles(rot[:, j], sign, rest_dir)
    d_abd = (abd - abd.mean()) * (bob - 1.0) + offset_rad
    d_flex = (flex - flex.mean()) * (swing - 1.0)
    # Pre-multiplying turns the arm about the parent's (rest-aligned) axes.
    turn = quat.mul(quat.from_axis_angle(np.stack([-d_flex, 0 * d_flex, 0 * d_flex], -1)),
                    quat.from_axis_angle(np.stack([0 * d_abd, 0 * d_abd, sign * d_abd], -1)))
    rot[:, j] = quat.mul(turn, rot[:, j])


def _widen_base(m: Motion, rot: np.ndarray, offset_m: float) -> np.ndarray:
    """Move each foot ``offset_m`` outwards (two-bone IK, foot orientation kept)."""
    if abs(offset_m) < 1e-9:
        return rot
    roles = role_indices(m)
    for s, sign in (("l", 1.0), ("r", -1.0)):
        grot, gpos = m.global_transforms(rot, m.root_translation)
        target = gpos[:, roles[f"{s}_ankle"]] + np.array([sign * offset_m, 0.0, 0.0])
        rot = two_bone_ik(m, rot, m.root_translation, s, target, grot[:, roles[f"{s}_ankle"]])
    return rot


def modify(motion: Motion, height_m: float, body_fat_pct: float, chest_m: float | None = None,
           wthr: float | None = None, scale_height: bool = True, base_scale: float = 1.0) -> Motion:
    """Apply the five modifiers (and the height scaling) to a walk.

    ``base_scale`` multiplies the walking-base offset (1 = the thesis's centimetres per foot).
    """
    p = thesis_parameters(height_m, body_fat_pct, chest_m, wthr)
    roles = role_indices(motion)
    m = motion
    if scale_height:
        k = p["height_scale"]
        m = m.replace(offsets=m.offsets * k, root_translation=m.root_translation * k)
    rot = m.rotations.copy()
    rest = m.rest_positions()
    for s, sign in (("l", 1.0), ("r", -1.0)):
        if f"{s}_shoulder" in roles and f"{s}_elbow" in roles:
            arm = rest[roles[f"{s}_elbow"]] - rest[roles[f"{s}_shoulder"]]
            _scale_arm(rot, roles[f"{s}_shoulder"], sign, p["bob_ratio"], p["swing_ratio"],
                       np.radians(p["abduction_offset_deg"]), arm / np.linalg.norm(arm))
    # The regression's walking base is read in millimetres (see WALKING_BASE_UNIT_M).
    rot = _widen_base(m, rot, p["base_offset_mm"] * WALKING_BASE_UNIT_M * base_scale)
    m = m.replace(rotations=rot)
    if abs(p["speed_ratio"] - 1.0) > 1e-12:
        m = retime(m, p["speed_ratio"])
    m.metadata.update(modifier={k: float(v) for k, v in p.items()}, source=f"{motion.metadata.get('source', '')}+thesis")
    return m


# -- Table 4-1: the point-light survey's strengths ------------------------------------------------
# The point-light survey (thesis ch. 4) predates the regressions above: the animator set each gait
# parameter's value for 35 % body fat by eye (speed from Equation 2), and the other strengths were
# interpolated linearly from the unchanged lean walker at 12 %. Table 4-1 prints the six values per
# parameter; they are kept here as printed (garbled digits restored from that linear rule) so that
# a protocol names rows and the numbers stay data. At MP's height the regression modifier cannot
# stand in for them: its speed and arm bob depend on height only, so they would not vary at all.
STRENGTH_BODY_FAT = (0.5, 12.0, 23.5, 35.0, 46.5, 58.0)
SI_UNIT_M = 0.01  # Table 4-1 heel offsets: one Softimage unit read as 1 cm (see WALKING_BASE_UNIT_M)
_TWIST = (-0.8, 1.0, 2.8, 4.644041, 6.5, 8.3)
TABLE_4_1 = {
    # row: (operation, values at STRENGTH_BODY_FAT); "swing" scales a curve about its mean,
    # "mean_deg" shifts its mean, "retime" plays the whole walk faster (cadence and speed × value),
    # "offset_si" moves each heel outwards by value Softimage units.
    "hip_twist": ("swing", _TWIST),                       # Hips local.roty
    "torso_twist": ("swing", _TWIST),                     # Chest local.rotx
    "arm_abduction": ("mean_deg", (-3.19355, 0.0, 3.19355, 6.3871, 9.58065, 12.7742)),
    "arm_bob": ("swing", (0.6, 1.0, 1.4, 1.895681, 2.3, 2.8)),
    "arm_swing": ("swing", (0.5, 1.0, 1.5, 2.0, 2.5, 3.0)),
    "arm_swing_mild": ("swing", (0.6, 1.0, 1.3, 1.6, 1.9, 2.2)),   # survey 5 (whole body) only
    "speed_cadence": ("retime", (1.1, 1.0, 0.9, 0.805026, 0.7, 0.6)),
    "walking_base": ("offset_si", (-1.0, 0.0, 1.0, 2.0, 3.0, 4.0)),
    "spinal_erectness": ("mean_deg", (-5.0, 0.0, 5.0, 10.0, 15.0, 20.0)),  # lowest spine bone, extension
}


# -- Table 5-2: the character mesh survey's strengths ----------------------------------------------
# The mesh survey (thesis ch. 5) kept Table 4-1's columns and reused its rows where the values
# carried over (arm_abduction, arm_bob, speed_cadence, walking_base, hip_twist, torso_twist: same
# names above); these are the rows it changed or added, as printed in Table 5-2.
_DECREASING = (1.25, 1.0, 0.75, 0.5, 0.25, 0.0)
TABLE_5_2 = {
    "hip_twist_decreased": ("swing", _DECREASING),        # Hips local.roty
    "torso_twist_decreased": ("swing", _DECREASING),      # Chest local.rotx
    "arm_swing_decreased": ("swing", _DECREASING),        # Upper Arm (printed local.roty and local.rotz)
    "torso_swagger": ("swing", (0.8, 1.0, 1.2, 1.4, 1.6, 1.8)),   # Chest local.roty: lateral bend (_sway_torso)
    # Survey 5 (arm bob alone), kept as printed: 1 (unchanged) stands under 23.5 %, not 12 %. The
    # text ("35% set at an expanded magnification of 3.7 and 0.5% dipping into the negative
    # direction of -0.8") names the row's two ends; no column shift puts 3.7 at 35 % and -0.8 at
    # 0.5 %, and the text's body fats disagree with Table 5-2's columns for walking base (4 "at
    # 35%", printed at 58 %) and hip twist (0.25 "at 35%", printed at 46.5 %) as well.
    "arm_bob_isolated": ("swing", (-0.79136, 0.104319, 1.0, 1.895681, 2.791363, 3.687044)),
    "arm_bob_whole_body": ("swing", (0.55, 1.0, 1.45, 1.895681, 2.34, 2.79)),   # survey 9 (whole body) only
}
STRENGTH_ROWS = {**TABLE_4_1, **TABLE_5_2}   # every row a protocol's ``modifies`` may name
# Rows acting on the same curve; given together, their factors multiply (scalings about one mean compose).
_SAME_CURVE = {
    "hip_twist": ("hip_twist", "hip_twist_decreased"),
    "torso_twist": ("torso_twist", "torso_twist_decreased"),
    "arm_bob": ("arm_bob", "arm_bob_isolated", "arm_bob_whole_body"),
    "arm_swing": ("arm_swing", "arm_swing_mild", "arm_swing_decreased"),
}


def table_strengths(parameters: str, body_fat_pct: float) -> dict[str, float]:
    """The values of the ``+``-joined rows of ``STRENGTH_ROWS`` at a body-fat %, linear between
    the columns (Tables 4-1 and 5-2 share them: ``STRENGTH_BODY_FAT``).

    >>> table_strengths("arm_abduction+arm_bob", 35)
    {'arm_abduction': 6.3871, 'arm_bob': 1.895681}
    >>> table_strengths("torso_swagger+arm_swing_decreased", 58)
    {'torso_swagger': 1.8, 'arm_swing_decreased': 0.0}
    """
    names = [n.strip() for n in str(parameters).split("+") if n.strip()]
    unknown = [n for n in names if n not in STRENGTH_ROWS]
    if not names or unknown:
        raise StimuliError(f"modifier: unknown Table 4-1/5-2 parameter(s) {unknown or [parameters]}; "
                           f"expected names joined by '+' from: {', '.join(STRENGTH_ROWS)}")
    lo, hi = STRENGTH_BODY_FAT[0], STRENGTH_BODY_FAT[-1]
    if not lo <= float(body_fat_pct) <= hi:
        raise StimuliError(f"modifier: body fat {body_fat_pct} % is outside the tables' strengths ({lo}–{hi} %)")
    return {n: float(np.interp(float(body_fat_pct), STRENGTH_BODY_FAT, STRENGTH_ROWS[n][1])) for n in names}


def _yaw(grot: np.ndarray) -> np.ndarray:
    """Heading (rad, about +y) of world rotations whose rest pose faces +z, unwrapped over time."""
    f = quat.rotate(grot, np.array([0.0, 0.0, 1.0]))
    return np.unwrap(np.arctan2(f[..., 0], f[..., 2]))


def _turn_world(m: Motion, rot: np.ndarray, j: int, rotvec: np.ndarray) -> None:
    """Turn joint ``j`` (and its subtree) by world rotation vectors (T×3) about its own position."""
    p = m.parents[j]
    turn = quat.from_axis_angle(rotvec)
    if p < 0:
        rot[:, j] = quat.mul(turn, rot[:, j])
        return
    gp = m.global_transforms(rot, m.root_translation)[0][:, p]
    rot[:, j] = quat.mul(quat.mul(quat.inv(gp), quat.mul(turn, gp)), rot[:, j])


def _about_y(angle: np.ndarray) -> np.ndarray:
    return np.stack([0 * angle, angle, 0 * angle], -1)


def _twist_torso(m: Motion, rot: np.ndarray, roles: dict, k: float) -> None:
    """Scale the chest bone's heading relative to its parent about its mean (Chest local.rotx:
    the thesis twisted that one bone, not the whole trunk above the pelvis)."""
    grot = m.global_transforms(rot, m.root_translation)[0]
    chest = roles["chest"]
    rel = _yaw(grot[:, chest]) - _yaw(grot[:, m.parents[chest]])
    _turn_world(m, rot, roles["chest"], _about_y((rel - rel.mean()) * (k - 1.0)))


def _lateral_bend(q: np.ndarray) -> np.ndarray:
    """Sideways tilt (rad, towards +x, the character's left) of the +y axis of rotations ``q``."""
    up = quat.rotate(q, np.array([0.0, 1.0, 0.0]))
    return np.arctan2(up[..., 0], up[..., 1])


def _sway_torso(m: Motion, rot: np.ndarray, roles: dict, k: float) -> None:
    """Scale the chest bone's lateral bend relative to its parent about its mean: torso swagger,
    Table 5-2's "Chest local.roty" ("its magnitude in the lateral y axis", §5.1; "thorax lateral
    rotation", §5.3.3). On the thesis's rig the chest's local.rotx is its twist (Table 4-1) and a
    spine bone's local.rotz its flexion-extension (spinal erectness, §4.4.2), so local.roty is the
    remaining axis: a rotation about the forward axis, the chest rolling from side to side in the
    frontal plane. It turns the chest about its parent's forward axis, which shifts the bend
    exactly: bend′ = (bend − mean)·k + mean."""
    grot = m.global_transforms(rot, m.root_translation)[0]
    chest = roles["chest"]
    parent = grot[:, m.parents[chest]]
    bend = _lateral_bend(quat.mul(quat.inv(parent), grot[:, chest]))
    forward = quat.rotate(parent, np.array([0.0, 0.0, 1.0]))
    # A turn about +forward by −Δ tilts +y towards +x by Δ.
    _turn_world(m, rot, chest, forward * (-(bend - bend.mean()) * (k - 1.0))[:, None])


def _twist_hips(m: Motion, rot: np.ndarray, roles: dict, k: float) -> np.ndarray:
    """Scale the pelvis heading about its mean (Hips local.roty); the legs are re-solved by IK so
    the feet stay where they were, as on the thesis rig, whose legs were IK chains."""
    grot, gpos = m.global_transforms(rot, m.root_translation)
    feet = {s: (gpos[:, roles[f"{s}_ankle"]].copy(), grot[:, roles[f"{s}_ankle"]].copy()) for s in "lr"}
    yaw = _yaw(grot[:, roles["pelvis"]])
    _turn_world(m, rot, roles["pelvis"], _about_y((yaw - yaw.mean()) * (k - 1.0)))
    for s, (target, keep) in feet.items():
        rot = two_bone_ik(m, rot, m.root_translation, s, target, keep)
    return rot


def _erect_spine(m: Motion, rot: np.ndarray, roles: dict, deg: float) -> None:
    """Extend the lower spine by ``deg`` (lean back; Lower Spine local.rotz, average position)."""
    # The character faces +z with +x its left: a negative turn about +x tips the trunk backwards.
    angle = np.full(m.n_frames, -np.radians(deg))
    _turn_world(m, rot, roles["spine"], np.stack([angle, 0 * angle, 0 * angle], -1))


def _curve_factor(strengths: dict[str, float], curve: str, default: float | None = None) -> float | None:
    """The product of the given rows acting on ``curve`` (``_SAME_CURVE``); ``default`` if none is."""
    given = [strengths[n] for n in _SAME_CURVE[curve] if n in strengths]
    return float(np.prod(given)) if given else default


def modify_strengths(motion: Motion, strengths: dict[str, float]) -> Motion:
    """Apply ``STRENGTH_ROWS`` rows (``table_strengths``) to a walk with the modifier's own
    operations: arm curves scaled about their mean or shifted, heels moved outwards, the whole walk
    retimed; hip and torso twist, torso swagger and spinal erectness extend the five-parameter
    modifier."""
    unknown = sorted(set(strengths) - set(STRENGTH_ROWS))
    if unknown:
        raise StimuliError(f"modifier: unknown Table 4-1/5-2 parameter(s) {unknown}; expected: "
                           f"{', '.join(STRENGTH_ROWS)}")
    roles = role_indices(motion)
    m, rot = motion, motion.rotations.copy()
    if "spinal_erectness" in strengths:
        _erect_spine(m, rot, roles, strengths["spinal_erectness"])
    torso = _curve_factor(strengths, "torso_twist")
    if torso is not None:
        _twist_torso(m, rot, roles, torso)
    if "torso_swagger" in strengths:
        _sway_torso(m, rot, roles, strengths["torso_swagger"])
    hips = _curve_factor(strengths, "hip_twist")
    if hips is not None:
        rot = _twist_hips(m, rot, roles, hips)
    bob = _curve_factor(strengths, "arm_bob", 1.0)
    swing = _curve_factor(strengths, "arm_swing", 1.0)
    offset = np.radians(strengths.get("arm_abduction", 0.0))
    rest = m.rest_positions()
    for s, sign in (("l", 1.0), ("r", -1.0)):
        if (bob, swing, offset) != (1.0, 1.0, 0.0) and f"{s}_shoulder" in roles and f"{s}_elbow" in roles:
            arm = rest[roles[f"{s}_elbow"]] - rest[roles[f"{s}_shoulder"]]
            _scale_arm(rot, roles[f"{s}_shoulder"], sign, bob, swing, offset, arm / np.linalg.norm(arm))
    rot = _widen_base(m, rot, strengths.get("walking_base", 0.0) * SI_UNIT_M)
    m = m.replace(rotations=rot)
    if abs(strengths.get("speed_cadence", 1.0) - 1.0) > 1e-12:
        m = retime(m, strengths["speed_cadence"])
    m.metadata.update(strengths={k: float(v) for k, v in strengths.items()},
                      source=f"{motion.metadata.get('source', '')}+table4-1")
    return m
