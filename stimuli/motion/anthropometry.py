"""Anthropometry → skeleton proportions and gait parameters (one documented table).

Segment heights and widths are fractions of stature from Drillis & Contini (1966) as tabulated by
Winter (2009, *Biomechanics and Motor Control of Human Movement*, Fig. 4.1). Gait trends with body
shape combine the thesis's regressions (Shewhorak 2017, ch. 8 and Appendix D; SPEC §1.3) with
the obesity-gait literature (SPEC §4: higher BMI → slower, shorter steps, wider base, longer
stance, less knee flexion, more arm abduction). Where the thesis's absolute units are not
physical (its walking base is in Softimage units), only its *ratio* to the lean baseline is used.

Examples
--------
>>> round(body_fat_from_bmi(25.0, "M"), 2)
20.7
"""

from __future__ import annotations

import numpy as np

# Fractions of stature H (Winter 2009, Fig. 4.1; hip joint centre ≈ 0.5 H below the trochanter 0.53 H).
PROPORTIONS = {
    "hip_height": 0.500, "pelvis_height": 0.530, "knee_height": 0.285, "ankle_height": 0.039,
    "hip_half_width": 0.050, "foot_length": 0.152, "heel_back": 0.040, "ball_forward": 0.080,
    "spine_height": 0.620, "chest_height": 0.720, "neck_height": 0.818, "head_height": 0.870,
    "shoulder_height": 0.818, "shoulder_half_width": 0.1295, "clavicle_half_width": 0.020,
    "elbow_height": 0.630, "wrist_height": 0.485, "hand_end_height": 0.377,
}

# Gait trends per unit of anthropometric change: (parameter, predictor, slope, reference, source).
# Applied as value = default + slope · (predictor − reference), or as a ratio where noted.
GAIT_TRENDS = [
    ("speed_mps", "height_m", 1.3, 1.758, "thesis speed = −1.07 + 1.3·H (ratio to 1.2154 at H 1.758)"),
    ("speed_mps", "bmi", -0.0269, 22.0, "thesis literature trend speed = −0.0269·BMI + 2.3185"),
    ("walking_base_ratio", "wthr", 268.26 / 55.0658, 0.83, "thesis base = −167.59 + 268.26·WtHR, as ratio to 55.0658"),
    ("arm_abduction_deg", "chest_m", 39.98, 0.98, "thesis abduction = −31.424 + 39.98·chest (offset)"),
    ("arm_bob_ratio", "height_m", 12.04 / 7.97632, 1.758, "thesis bob = −13.19 + 12.04·H, ratio to 7.97632"),
    ("arm_swing_ratio", "body_fat_pct", 0.29 / 22.269, 12.1, "thesis swing = 18.76 + 0.29·BF, ratio to 22.269"),
    ("stance_fraction", "bmi", 0.0025, 22.0, "longer stance/double support with obesity (Spyropoulos 1991; Ko 2010)"),
    ("knee_flexion_scale", "bmi", -0.010, 22.0, "less stance knee flexion with obesity (DeVita & Hortobágyi 2003)"),
    ("pelvis_rotation_scale", "bmi", 0.015, 22.0, "more hip/trunk twist perceived for obese walkers (thesis ch. 4)"),
]


def body_fat_from_bmi(bmi: float, sex: str, age: float = 30.0) -> float:
    """Body-fat % from BMI (Deurenberg, Weststrate & Seidell 1991): 1.2·BMI + 0.23·age − 10.8·male − 5.4."""
    return 1.2 * bmi + 0.23 * age - 10.8 * (sex == "M") - 5.4


def thesis_t(body_fat_pct: float) -> float:
    """The thesis's body-fat interpolation factor t = (BF − 12)/(35 − 12), not clamped."""
    return (body_fat_pct - 12.0) / (35.0 - 12.0)


def estimated_wthr(body_fat_pct: float) -> float:
    """Waist-to-hip ratio interpolated as in the thesis: lerp(0.83, 0.95, t)."""
    t = thesis_t(body_fat_pct)
    return (1 - t) * 0.83 + t * 0.95


def estimated_chest(body_fat_pct: float) -> float:
    """Chest (m) interpolated as in the thesis: lerp(0.98, 1.14, t)."""
    t = thesis_t(body_fat_pct)
    return (1 - t) * 0.98 + t * 1.14


def predictors(height_m: float, bmi: float, sex: str, body_fat_pct: float | None = None,
               waist_m: float | None = None, hip_m: float | None = None, chest_m: float | None = None) -> dict:
    """The predictors GAIT_TRENDS uses, measured where given, else estimated as the thesis does."""
    bf = body_fat_from_bmi(bmi, sex) if body_fat_pct is None else body_fat_pct
    wthr = waist_m / hip_m if waist_m and hip_m else estimated_wthr(bf)
    chest = chest_m if chest_m else estimated_chest(bf)
    return {"height_m": height_m, "bmi": bmi, "body_fat_pct": bf, "wthr": wthr, "chest_m": chest}


def trend_offsets(pred: dict) -> dict[str, float]:
    """Per gait parameter, the summed trend offset (slope × (predictor − reference))."""
    out: dict[str, float] = {}
    for param, predictor, slope, ref, _ in GAIT_TRENDS:
        out[param] = out.get(param, 0.0) + slope * (pred[predictor] - ref)
    return out


def skeleton_points(height_m: float) -> dict[str, np.ndarray]:
    """Rest joint positions (y-up, +z forward, +x body left, ground y = 0) for a stature."""
    h = height_m
    p = PROPORTIONS
    pts = {
        "pelvis": [0, p["pelvis_height"], 0], "spine": [0, p["spine_height"], -0.01],
        "chest": [0, p["chest_height"], -0.01], "neck": [0, p["neck_height"], -0.015],
        "head": [0, p["head_height"], 0.0], "head_end": [0, 1.0, 0.01],
    }
    for s, sign in (("l", 1.0), ("r", -1.0)):
        pts.update({
            f"{s}_hip": [sign * p["hip_half_width"], p["hip_height"], 0],
            f"{s}_knee": [sign * p["hip_half_width"], p["knee_height"], 0.005],
            f"{s}_ankle": [sign * p["hip_half_width"], p["ankle_height"], 0],
            f"{s}_heel": [sign * p["hip_half_width"], 0.0, -p["heel_back"]],
            f"{s}_toe": [sign * p["hip_half_width"], 0.012, p["ball_forward"]],
            f"{s}_toe_end": [sign * p["hip_half_width"], 0.0, p["foot_length"] - p["heel_back"]],
            f"{s}_clavicle": [sign * p["clavicle_half_width"], p["shoulder_height"] - 0.01, -0.01],
            f"{s}_shoulder": [sign * p["shoulder_half_width"], p["shoulder_height"], -0.01],
            f"{s}_elbow": [sign * (p["shoulder_half_width"] + 0.01), p["elbow_height"], -0.01],
            f"{s}_wrist": [sign * (p["shoulder_half_width"] + 0.015), p["wrist_height"], 0.0],
            f"{s}_hand_end": [sign * (p["shoulder_half_width"] + 0.015), p["hand_end_height"], 0.01],
        })
    return {k: np.array(v, float) * h for k, v in pts.items()}
