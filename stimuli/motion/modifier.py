"""The thesis's five-parameter walk modifier (Shewhorak 2017, ch. 8 and Appendix D; SPEC §1.3).

Inputs: height H (m), body-fat BF (%), optionally chest (m) and waist-to-hip ratio (otherwise
interpolated from BF between the lean baseline and 35 % as the thesis script does). Outputs, in
order of perceptual dominance: a speed ratio (retime: cadence and speed scale, step length kept),
an arm abduction offset (°, mean shift), a walking-base offset (cm, added to each foot
laterally — the thesis's Softimage script offsets each heel by it), an arm-bob ratio and an
arm-swing ratio (arm curves scaled about their mean: v′ = (v − mean)·ratio + mean), plus the
height scale H / 1.758.

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
            "base_cm": base, "bob_deg": bob, "swing_deg": swing,
            "speed_ratio": speed / LEAN["speed"], "abduction_offset_deg": abduction - LEAN["abduction"],
            "base_offset_cm": base - LEAN["base"], "bob_ratio": bob / LEAN["bob"],
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
    rot = _widen_base(m, rot, p["base_offset_cm"] / 100.0 * base_scale)
    m = m.replace(rotations=rot)
    if abs(p["speed_ratio"] - 1.0) > 1e-12:
        m = retime(m, p["speed_ratio"])
    m.metadata.update(modifier={k: float(v) for k, v in p.items()}, source=f"{motion.metadata.get('source', '')}+thesis")
    return m
