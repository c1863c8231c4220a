"""Per-actor gait parameters: anthropometric trends plus an individual style from a seed.

``params_for_actor`` starts from the gait defaults, applies the GAIT_TRENDS table of
``anthropometry.py`` (thesis regressions and BMI literature), then draws an individual style
from a generator seeded by (protocol seed, actor id) so that actors of the same sex and similar
shape still move recognisably differently (Exp 1's MOTION factor). Cadence and speed are the
protocol's (all actors of a gait share them) unless ``speed_mps`` is None, in which case the
speed follows the trends too.

Examples
--------
>>> p = params_for_actor("M_Hi2", 1.83, 35.8, "M", "walk", 112, 1.2, seed=7)
>>> p.cadence_spm, p.speed_mps
(112, 1.2)
"""

from __future__ import annotations

import zlib

import numpy as np

from stimuli.motion.anthropometry import predictors, trend_offsets
from stimuli.motion.generate import GaitParams

# Individual style: (parameter, kind, spread). "mul": × exp(N(0, spread)); "add": + N(0, spread).
STYLE = [
    ("arm_swing_ratio", "mul", 0.18), ("arm_abduction_deg", "add", 2.5), ("elbow_flexion_deg", "add", 7.0),
    ("trunk_lean_deg", "add", 2.0), ("pelvis_rotation_scale", "mul", 0.3), ("pelvis_obliquity_scale", "mul", 0.3),
    ("trunk_rotation_scale", "mul", 0.3), ("knee_flexion_scale", "mul", 0.06), ("toe_out_deg", "add", 3.0),
    ("walking_base_m", "mul", 0.2), ("arm_bob_ratio", "mul", 0.2), ("arm_phase", "add", 0.02),
    ("head_stabilisation", "add", 0.12), ("stance_fraction", "add", 0.01),
]
NORMATIVE_WALKING_BASE_M = 0.10  # adult stride width at comfortable speed (≈ 8–12 cm)


def actor_rng(seed: int, actor_id: str) -> np.random.Generator:
    """A generator that depends on the protocol seed and the actor, not on the actor's position."""
    return np.random.default_rng([int(seed), zlib.crc32(actor_id.encode())])


def params_for_actor(actor_id: str, height_m: float, bmi: float, sex: str, gait: str,
                     cadence_spm: float, speed_mps: float | None, seed: int = 0, style: bool = True,
                     **anthro) -> GaitParams:
    """Gait parameters for one actor (see the module docstring)."""
    p = GaitParams(gait=gait, cadence_spm=cadence_spm, speed_mps=speed_mps or 1.2).resolved()
    pred = predictors(height_m, bmi, sex, **anthro)
    trend = trend_offsets(pred)
    if speed_mps is None:
        base_speed = 1.2154 if gait == "walk" else 2.2
        p.speed_mps = max(0.3, base_speed + trend["speed_mps"] * (base_speed / 1.2154))
    p.walking_base_m = NORMATIVE_WALKING_BASE_M * (1.0 + trend["walking_base_ratio"])
    p.arm_abduction_deg += trend["arm_abduction_deg"]
    p.arm_bob_ratio *= 1.0 + trend["arm_bob_ratio"]
    p.arm_swing_ratio *= 1.0 + trend["arm_swing_ratio"]
    p.stance_fraction += trend["stance_fraction"]
    p.knee_flexion_scale *= float(np.clip(1.0 + trend["knee_flexion_scale"], 0.6, 1.2))
    p.pelvis_rotation_scale *= float(np.clip(1.0 + trend["pelvis_rotation_scale"], 0.5, 1.6))
    drawn = {}
    if style:
        rng = actor_rng(seed, f"{actor_id}:{gait}")
        for name, kind, spread in STYLE:
            z = float(rng.normal())
            old = getattr(p, name)
            new = old * float(np.exp(spread * z)) if kind == "mul" else old + spread * z
            setattr(p, name, new)
            drawn[name] = z
    p.head_stabilisation = float(np.clip(p.head_stabilisation, 0.0, 1.0))
    p.stance_fraction = float(np.clip(p.stance_fraction, 0.3, 0.7))
    p.walking_base_m = float(np.clip(p.walking_base_m, 0.02, 0.3))
    p.style = {"actor_id": actor_id, "seed": int(seed), "z": drawn, "predictors": pred}
    return p


def actor_gait(actor, gait: str, cadence_spm: float, speed_mps: float | None, seed: int, fps: float, cycles: int,
               style: bool = True):
    """An actor's own looped treadmill walk or jog from the generator (protocol cadence and speed,
    the actor's anthropometric trends and, unless ``style`` is False, individual style): the motion
    Exp 1's MOTION factor shows.

    ``actor`` is a :class:`stimuli.protocol.Actor` (or anything with its fields: ``id``, ``sex``,
    ``height_m``, ``bmi``, optional girths and body fat).
    """
    from stimuli.motion.generate import generate

    anthro = {k: getattr(actor, k) for k in ("body_fat_pct", "waist_m", "hip_m", "chest_m") if getattr(actor, k, None)}
    params = params_for_actor(actor.id, actor.height_m, actor.bmi, actor.sex, gait, cadence_spm, speed_mps,
                              seed=seed, style=style, **anthro)
    return generate(params, height_m=actor.height_m, fps=fps, cycles=cycles)
