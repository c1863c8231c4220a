"""Built-in walking and jogging generator driven by gait parameters.

The basis is real data: the normative adult walking kinematics of CGM2.3 (pelvis, hip, knee,
ankle, spine, shoulder, elbow angles over the cycle). A walk plays these curves time-warped to
the requested stance fraction. A jog's legs (thigh, knee, ankle in the sagittal plane) follow the
bundled CMU run capture (:mod:`stimuli.motion.running`: landing on a bent knee, 45–50° at
mid-stance, about 90° late in swing) warped to the requested stance with a flight phase; its
pelvis, trunk and arms keep the warped walking curves, with flexed elbows and a leaning trunk as
in the running literature (Novacheck 1998, *Gait & Posture* 7:77). Every curve is then shaped by the
:class:`GaitParams` (arm swing/bob/abduction scale about the curve's mean as in the thesis
modifier). The hip flexion amplitude is fitted so that the stance ankle travels as far back as
the foot clean-up's planted foot (:func:`_planted_travel`), the pelvis height keeps the stance foot
on the ground (ballistic in flight), and the foot clean-up pins planted feet to the treadmill belt.

Examples
--------
>>> m = generate(GaitParams(gait="walk", cadence_spm=112, speed_mps=1.3), height_m=1.75)  # doctest: +SKIP
>>> round(m.metadata["cadence_spm"])                                                         # doctest: +SKIP
112
"""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.ndimage import gaussian_filter1d

from stimuli.errors import StimuliError
from stimuli.motion import quat
from stimuli.motion.anthropometry import skeleton_points
from stimuli.motion.balance import balance
from stimuli.motion.footfix import clean_feet, contact_targets, flatten_feet, sole_points, sole_positions
from stimuli.motion.motion import Motion
from stimuli.motion.normative import TOE_OFF, curve
from stimuli.motion.running import run_curve, run_toe_off
from stimuli.protocol import CADENCE_RANGE_SPM, SPEED_RANGE_MPS

GRAVITY = 9.81
# The hip flexion amplitude is fitted to the planted foot's travel within this multiple of the
# basis curve's. At the cap the legs cannot cover the stance and the clean-up folds the knees (up
# to 150–180°); Exp 1/2's actors need at most 1.15× walking and 1.74× jogging.
HIP_SCALE_MAX = 2.5
# Peak height of the lowest point of a swinging foot (walking: toe clearance ~1.5 cm at its
# minimum, Winter 1992; the half-sine profile peaks mid-swing).
SWING_CLEARANCE_M = {"walk": 0.04, "jog": 0.08}

# Joint tree of the generator's skeleton: (name, parent). Names are the roles of skeleton.py.
TREE = [("pelvis", None)]
for _s in ("l", "r"):
    TREE += [(f"{_s}_hip", "pelvis"), (f"{_s}_knee", f"{_s}_hip"), (f"{_s}_ankle", f"{_s}_knee"),
             (f"{_s}_heel", f"{_s}_ankle"), (f"{_s}_toe", f"{_s}_ankle"), (f"{_s}_toe_end", f"{_s}_toe")]
TREE += [("spine", "pelvis"), ("chest", "spine"), ("neck", "chest"), ("head", "neck"), ("head_end", "head")]
for _s in ("l", "r"):
    TREE += [(f"{_s}_clavicle", "chest"), (f"{_s}_shoulder", f"{_s}_clavicle"), (f"{_s}_elbow", f"{_s}_shoulder"),
             (f"{_s}_wrist", f"{_s}_elbow"), (f"{_s}_hand_end", f"{_s}_wrist")]

# Highest point of a swinging wrist, below the shoulder, as a fraction of the arm's length (upper arm
# plus forearm), per gait. A jog's forward swing (a larger arm-swing ratio with body fat, the thesis's
# trend, times the actor's style) on 55° elbows otherwise brought the wrist to 2–5 cm below the
# shoulder on Exp 1's heavier bodies and 8–11 cm on the lean ones: the hands "waving" at shoulder
# height grew with body size. Runners' hands peak about chest height. The bound is on the generator's
# own skeleton (level trunk); on Exp 1's Anny bodies it gives 10.2–12.5 cm below the shoulder
# (tests/test_hands_arms.py), the trunk's lean and Anny's forearm raising the wrist a little.
WRIST_TOP_BELOW_SHOULDER = {"jog": 0.32}

# Cadence (steps/min) and speed (m/s) of a gait when neither a protocol nor an option gives them
# (the bundled protocols' values).
DEFAULT_PACE = {"walk": (112.0, 1.2), "jog": (138.0, 2.2)}

# Gait-specific defaults (walk: CGM2.3 normative; jog: Novacheck 1998 typical jogging values; the
# jog's leg curves are already running ones, so its knee gains and hip offset are neutral).
GAIT_DEFAULTS = {
    "walk": dict(stance_fraction=0.61, trunk_lean_deg=2.0, elbow_flexion_deg=0.0, arm_swing_ratio=1.0,
                 knee_stance_gain=1.0, knee_swing_gain=1.0, hip_flexion_offset_deg=0.0),
    "jog": dict(stance_fraction=0.40, trunk_lean_deg=7.0, elbow_flexion_deg=55.0, arm_swing_ratio=1.3,
                knee_stance_gain=1.0, knee_swing_gain=1.0, hip_flexion_offset_deg=0.0),
}


@dataclass
class GaitParams:
    """Parameters of a generated gait (angles in degrees, lengths in metres).

    ``None`` takes the gait's default from GAIT_DEFAULTS. Ratios scale a curve about its mean
    (1 = normative); offsets shift it.
    """

    gait: str = "walk"
    cadence_spm: float = 112.0
    speed_mps: float = 1.3
    stance_fraction: float | None = None
    walking_base_m: float = 0.10
    toe_out_deg: float = 7.0
    knee_flexion_scale: float = 1.0
    knee_stance_gain: float | None = None
    knee_swing_gain: float | None = None
    hip_flexion_offset_deg: float | None = None
    pelvis_rotation_scale: float = 1.0
    pelvis_obliquity_scale: float = 1.0
    trunk_lean_deg: float | None = None
    trunk_rotation_scale: float = 1.0
    arm_swing_ratio: float | None = None
    arm_abduction_deg: float = 3.0
    arm_bob_ratio: float = 1.0
    elbow_flexion_deg: float | None = None
    head_stabilisation: float = 0.7
    arm_phase: float = 0.0
    style: dict = field(default_factory=dict)

    def resolved(self) -> "GaitParams":
        """A copy with gait defaults filled in; StimuliError for an unknown gait or bad values."""
        if self.gait not in GAIT_DEFAULTS:
            raise StimuliError(f"gait must be one of {', '.join(GAIT_DEFAULTS)}, got {self.gait!r}")
        values = asdict(self)
        for k, v in GAIT_DEFAULTS[self.gait].items():
            if values[k] is None:
                values[k] = v
        out = GaitParams(**values)
        for name, (low, high), unit in (("cadence_spm", CADENCE_RANGE_SPM, "steps/min"),
                                        ("speed_mps", SPEED_RANGE_MPS, "m/s")):
            if not low <= getattr(out, name) <= high:
                raise StimuliError(f"{name} must be within {low:g}–{high:g} {unit}, got {getattr(out, name)}")
        if not 0.2 <= out.stance_fraction <= 0.8:
            raise StimuliError(f"stance_fraction must be within 0.2–0.8, got {out.stance_fraction}")
        return out

    @property
    def step_length_m(self) -> float:
        return self.speed_mps * 60.0 / self.cadence_spm


def canonical_skeleton(height_m: float) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Joint names, parents and rest offsets of the generator's skeleton for a stature."""
    pts = skeleton_points(height_m)
    names = [n for n, _ in TREE]
    parents = np.array([-1 if p is None else names.index(p) for _, p in TREE])
    offsets = np.stack([pts[n] - (pts[p] if p else np.zeros(3)) for n, p in TREE])
    offsets[0] = 0.0
    return names, parents, offsets


def loop_frames(cycles: int, cadence_spm: float, fps: float) -> int:
    """Frames of a generated loop of ``cycles`` gait cycles (two steps each), rounded to whole frames.

    >>> loop_frames(2, 112, 30.0)
    64
    """
    return int(round(cycles * 120.0 / cadence_spm * fps))


def generated_leg_length(height_m: float) -> float:
    """``skeleton.leg_length`` of the generator's gaits for a stature, without generating one: thigh +
    shank + the ankle's height over a flat foot, read on the skeleton's rest pose. A gait's own
    reading takes the 2nd percentile of its ankle height over the clip, within 0.07 % of this (Exp 1).

    >>> round(generated_leg_length(1.60), 4)
    0.8002
    """
    from stimuli.motion.skeleton import leg_length

    names, parents, offsets = canonical_skeleton(height_m)
    rest = np.zeros((1, len(names), 4))
    rest[..., 0] = 1.0
    return leg_length(Motion(30.0, names, parents, offsets, rest, np.zeros((1, 3))))


def _warp(phi: np.ndarray, stance: float, toe_off: float = TOE_OFF) -> np.ndarray:
    """Output cycle fraction → basis cycle fraction, mapping stance onto the basis's stance
    (``toe_off``: the basis's toe-off fraction, CGM2.3 walking by default)."""
    phi = np.mod(phi, 1.0)
    return np.where(phi < stance, phi / stance * toe_off,
                    toe_off + (phi - stance) / (1.0 - stance) * (1.0 - toe_off))


def _leg_basis(gait: str) -> tuple[dict, float]:
    """Sagittal leg curves (thigh-to-vertical ``hip``, ``knee``, ``ankle``) and their toe off."""
    if gait == "jog":
        return {k: run_curve(k) for k in ("hip", "knee", "ankle")}, run_toe_off()
    # Hip flexion is measured from a pelvis tilted forward ~7° (Plug-in-Gait); our pelvis is level,
    # so the thigh's angle to the vertical is hip flexion minus the mean pelvic tilt.
    tilt = float(np.mean(curve("PelvisAngles", "X")(np.linspace(0, 1, 100, endpoint=False))))
    hip = curve("HipAngles", "X")
    return {"hip": lambda psi: hip(psi) - tilt, "knee": curve("KneeAngles", "X"),
            "ankle": curve("AnkleAngles", "X")}, TOE_OFF


def _about_mean(f, psi: np.ndarray, ratio: float) -> np.ndarray:
    """Curve values scaled about the curve's cycle mean: (v − mean)·ratio + mean."""
    grid = np.linspace(0, 1, 100, endpoint=False)
    m = float(np.mean(f(grid)))
    return (f(psi) - m) * ratio + m


def _rx(a):
    return quat.from_axis_angle(np.stack([a, 0 * a, 0 * a], -1))


def _ry(a):
    return quat.from_axis_angle(np.stack([0 * a, a, 0 * a], -1))


def _rz(a):
    return quat.from_axis_angle(np.stack([0 * a, 0 * a, a], -1))


def _leg_angles(p: GaitParams, phi: np.ndarray, hip_scale: float, sign: float, adduction: float):
    """Hip, knee, ankle local quaternions for one leg at its own cycle fractions ``phi``."""
    d = np.radians
    basis, toe_off = _leg_basis(p.gait)
    psi = _warp(phi, p.stance_fraction, toe_off)
    hip_flex = _about_mean(basis["hip"], psi, hip_scale) + p.hip_flexion_offset_deg
    walk_psi = _warp(phi, p.stance_fraction)
    hip_add = _about_mean(curve("HipAngles", "Y"), walk_psi, 1.0) - np.mean(curve("HipAngles", "Y")(np.linspace(0, 1, 100)))
    # Knee gains: stance (a smooth bump over stance) and swing flexion relative to the basis.
    bump = np.where(psi < toe_off, np.sin(np.pi * psi / toe_off) ** 2, 0.0)
    gain = p.knee_swing_gain + (p.knee_stance_gain - p.knee_swing_gain) * bump
    gain = np.where(psi < toe_off, gain, p.knee_swing_gain)
    knee = np.maximum(basis["knee"](psi), 0.0) * gain * p.knee_flexion_scale
    ankle = basis["ankle"](psi)
    hip = quat.mul(_rx(-d(hip_flex)), quat.mul(_rz(-sign * d(hip_add + adduction)), _ry(sign * d(p.toe_out_deg))))
    return hip, _rx(d(knee)), _rx(-d(ankle))


def _pose(p: GaitParams, names: list[str], phi: np.ndarray, hip_scale: float, adduction: float) -> np.ndarray:
    """Local rotations (T×J×4) for cycle fractions ``phi`` of the left leg."""
    d = np.radians
    t = len(phi)
    rot = np.tile(quat.IDENTITY, (t, len(names), 1))
    psi = {"l": _warp(phi, p.stance_fraction), "r": _warp(phi + 0.5, p.stance_fraction)}
    for s, sign in (("l", 1.0), ("r", -1.0)):
        hip, knee, ankle = _leg_angles(p, np.mod(phi + (0.0 if s == "l" else 0.5), 1.0), hip_scale, sign, adduction)
        rot[:, names.index(f"{s}_hip")] = hip
        rot[:, names.index(f"{s}_knee")] = knee
        rot[:, names.index(f"{s}_ankle")] = ankle
        # Arms swing opposite to the legs: the normative shoulder curve is already of that side.
        pa = psi[s] + p.arm_phase
        flex = _about_mean(curve("ShoulderAngles", "X"), pa, p.arm_swing_ratio) - \
            np.mean(curve("ShoulderAngles", "X")(np.linspace(0, 1, 100)))
        abd = _about_mean(curve("ShoulderAngles", "Y"), pa, p.arm_bob_ratio) + p.arm_abduction_deg
        elbow = curve("ElbowAngles", "X")(pa) + p.elbow_flexion_deg
        if p.gait in WRIST_TOP_BELOW_SHOULDER:
            flex = cap_arm_flexion(flex, elbow, WRIST_TOP_BELOW_SHOULDER[p.gait])
        rot[:, names.index(f"{s}_shoulder")] = quat.mul(_rx(-d(flex)), _rz(sign * d(abd)))
        rot[:, names.index(f"{s}_elbow")] = _rx(-d(elbow))
    # Pelvis (left-side curves; left forward = negative yaw about +y).
    pl = psi["l"]
    yaw = -_about_mean(curve("PelvisAngles", "Z"), pl, p.pelvis_rotation_scale)
    yaw -= np.mean(yaw)
    roll = _about_mean(curve("PelvisAngles", "Y"), pl, p.pelvis_obliquity_scale)
    roll -= np.mean(roll)
    tilt = curve("PelvisAngles", "X")(pl)
    tilt -= np.mean(tilt)
    rot[:, 0] = quat.mul(_ry(d(yaw)), quat.mul(_rz(d(roll)), _rx(d(tilt))))
    # Trunk: thorax counter-rotation relative to the pelvis, split over spine and chest.
    tz = -_about_mean(curve("SpineAngles", "Z"), pl, p.trunk_rotation_scale)
    tz -= np.mean(tz)
    ty = curve("SpineAngles", "Y")(pl)
    ty -= np.mean(ty)
    half = quat.mul(_ry(d(tz) / 2), quat.mul(_rz(d(ty) / 2), _rx(d(p.trunk_lean_deg) / 2 - d(tilt) / 2)))
    rot[:, names.index("spine")] = half
    rot[:, names.index("chest")] = half
    return rot


@functools.lru_cache(maxsize=1)
def _arm_lengths() -> tuple[float, float]:
    """Upper arm and forearm length of the generator's skeleton as fractions of stature (constants of
    its proportions, asked for by every step of the arm-flexion bisection)."""
    pts = skeleton_points(1.0)
    return (float(np.linalg.norm(pts["l_elbow"] - pts["l_shoulder"])),
            float(np.linalg.norm(pts["l_wrist"] - pts["l_elbow"])))


def wrist_height(flex_deg, elbow_deg) -> np.ndarray:
    """Wrist height relative to the shoulder (fraction of the arm's length) of an arm in the sagittal
    plane: shoulder flexion ``flex_deg`` from hanging, elbow flexion ``elbow_deg``.

    >>> round(float(wrist_height(0.0, 0.0)), 3), round(float(wrist_height(0.0, 90.0)), 3)  # hanging; forearm level
    (-1.0, -0.564)
    """
    upper, fore = _arm_lengths()
    f, e = np.radians(flex_deg), np.radians(elbow_deg)
    return -(upper * np.cos(f) + fore * np.cos(f + e)) / (upper + fore)


def cap_arm_flexion(flex_deg, elbow_deg, below: float) -> np.ndarray:
    """Shoulder flexion (degrees) lowered, where needed, so the wrist stays ``below`` (fraction of the
    arm's length) under the shoulder; other frames are unchanged.

    >>> out = cap_arm_flexion(np.array([0.0, 70.0]), np.array([60.0, 60.0]), 0.22)
    >>> float(out[0]), bool(abs(wrist_height(out[1], 60.0) + 0.22) < 1e-6)
    (0.0, True)
    """
    flex = np.array(flex_deg, float)
    elbow = np.broadcast_to(np.asarray(elbow_deg, float), flex.shape)
    over = wrist_height(flex, elbow) > -below
    if not over.any():
        return flex
    # Bisection between a flexion that keeps the wrist low (the arm hanging back) and the curve's own.
    lo, hi = np.full(over.sum(), -45.0), flex[over]
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        high = wrist_height(mid, elbow[over]) > -below
        hi, lo = np.where(high, mid, hi), np.where(high, lo, mid)
    flex[over] = lo
    return flex


def _stabilise_head(names, parents, offsets, rot, root, amount: float) -> np.ndarray:
    """Turn the head towards upright/forward by ``amount`` (0 = follows the trunk, 1 = fixed)."""
    m = Motion(fps=1.0, joint_names=names, parents=parents, offsets=offsets, rotations=rot, root_translation=root)
    grot, _ = m.global_transforms()
    neck = names.index("neck")
    want = quat.slerp(grot[:, neck], np.tile(quat.IDENTITY, (len(rot), 1)), np.full(len(rot), amount))
    out = rot.copy()
    out[:, names.index("head")] = quat.mul(quat.inv(grot[:, neck]), want)
    return out


def _stance_travel(m: Motion, stance: np.ndarray, z: np.ndarray | None = None) -> float:
    """Mean backward travel (m) of the left ankle (or of the positions ``z``) relative to the pelvis
    during stance, extrapolated from the frames to the whole stance."""
    z = m.positions()[:, m.index("l_ankle"), 2] if z is None else z
    first = int(np.argmax(stance))
    last = first + int(np.argmin(stance[first:])) - 1 if not stance[first:].all() else len(stance) - 1
    return float(z[first] - z[last]) * (last - first + 1) / max(last - first, 1)


def _walking_base(m: Motion, stance: dict) -> float:
    """Mean lateral distance (m) between the two ankles, each averaged over its stance frames."""
    pos = m.positions()
    xs = [pos[stance[s], m.index(f"{s}_ankle"), 0].mean() for s in ("l", "r")]
    return float(xs[0] - xs[1])


def _planted_travel(m: Motion, stance: dict, belt_speed: float) -> float:
    """Backward travel (m) of the left ankle over its stance once the foot clean-up plants the foot
    on the belt (flat at mid-stance, pivoting on heel, then ball): the travel the raw leg swing has
    to match, or the clean-up stretches the legs and lowers the pelvis to reach the footprints.
    The ankle itself advances over the ground only while the foot rotates about its heel or ball,
    a few cm — not the whole heel-to-ball distance."""
    rot = flatten_feet(m, m.rotations, m.root_translation, stance)
    grot, gpos = m.global_transforms(rot, m.root_translation)
    sole = sole_positions(grot, gpos, sole_points(m, floor_y=-skeleton_floor(m))["l"])
    target, _, _ = contact_targets(sole, gpos[:, m.index("l_ankle")], stance["l"], np.array([0.0, 0.0, -belt_speed]),
                                   m.fps)
    return _stance_travel(m, stance["l"], target[:, 2])


def _root_height(m: Motion, stance: dict, fps: float) -> np.ndarray:
    """Pelvis height putting the lowest sole point of a stance foot on the ground; ballistic in flight."""
    grot, gpos = m.global_transforms()
    pts = sole_points(m, floor_y=0.0 - skeleton_floor(m))
    need = {s: -sole_positions(grot, gpos, pts[s])[:, :, 1].min(axis=1) for s in ("l", "r")}
    # In double support the lower requirement wins: the other knee bends a little more (IK),
    # whereas a pelvis too high would leave a foot floating out of reach.
    both = np.stack([np.where(stance[s], need[s], np.inf) for s in ("l", "r")])
    h = both.min(axis=0)
    flight = ~np.isfinite(h)
    if flight.any():
        h = _ballistic(h, flight, fps)
    return gaussian_filter1d(h, 1.0, mode="wrap")


def skeleton_floor(m: Motion) -> float:
    """Height of the root above the lowest rest joint (the rest pose stands on the ground)."""
    return float(-m.rest_positions()[:, 1].min())


def _ballistic(h: np.ndarray, flight: np.ndarray, fps: float) -> np.ndarray:
    """Fill flight frames with a parabola under gravity joining the neighbouring stance heights."""
    n = len(h)
    out = h.copy()
    shift = int(np.argmin(flight))
    hr, fr = np.roll(out, -shift), np.roll(flight, -shift)
    d = np.diff(np.concatenate([[0], fr.astype(int), [0]]))
    for s, e in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)):
        h0, h1 = hr[s - 1], hr[e % n]
        t0, t1 = (s - 1) / fps, e / fps
        t = np.arange(s, e) / fps
        hr[s:e] = h0 + (h1 - h0) * (t - t0) / (t1 - t0) + 0.5 * GRAVITY * (t - t0) * (t1 - t)
    return np.roll(hr, shift)


def _flatten_toes(m: Motion) -> np.ndarray:
    """Bend the toes up when the ball is near the ground and the foot pitches down (push-off)."""
    rot = m.rotations.copy()
    grot, gpos = m.global_transforms()
    for s in ("l", "r"):
        toe = m.index(f"{s}_toe")
        fwd = quat.rotate(grot[:, toe], np.array([0.0, 0.0, 1.0]))
        pitch = np.arctan2(-fwd[:, 1], np.linalg.norm(fwd[:, [0, 2]], axis=1))  # > 0: toes point down
        near = np.clip((0.04 - gpos[:, toe, 1]) / 0.03, 0.0, 1.0)
        bend = np.maximum(pitch, 0.0) * near
        rot[:, toe] = quat.mul(rot[:, toe], _rx(-bend))
    return rot


def generate(params: GaitParams, height_m: float = 1.75, fps: float = 30.0, cycles: int = 2,
             cleanup: bool = True) -> Motion:
    """A looped treadmill walk or jog of ``cycles`` gait cycles for a body of stature ``height_m``.

    The clip has a whole number of frames; the cycle time is rounded to fit (cadence error below
    one step/min at 30 fps for two cycles). Metadata records the gait parameters, cadence, speed,
    step length and belt speed.
    """
    p = params.resolved()
    if not 0.5 <= height_m <= 2.5:
        raise StimuliError(f"height_m must be within 0.5–2.5 m, got {height_m}")
    n = loop_frames(cycles, p.cadence_spm, fps)
    if n < 8:
        raise StimuliError(f"{cycles} cycle(s) at {p.cadence_spm} steps/min give only {n} frames at {fps} fps")
    cycle_s = n / fps / cycles
    cadence = 120.0 / cycle_s
    phi = (np.arange(n) / fps / cycle_s) % 1.0
    names, parents, offsets = canonical_skeleton(height_m)
    hip_w = 2 * offsets[names.index("l_hip"), 0]
    leg = np.linalg.norm(offsets[names.index("l_knee")]) + np.linalg.norm(offsets[names.index("l_ankle")])
    adduction = np.degrees(np.arcsin(np.clip((hip_w - p.walking_base_m) / 2 / leg, -0.5, 0.5)))
    stance = {"l": phi < p.stance_fraction, "r": ((phi + 0.5) % 1.0) < p.stance_fraction}
    zero = np.zeros((n, 3))
    # Fit the hip flexion amplitude so the stance ankle travels back as far as its planted foot.
    hip_scale = 1.0
    for _ in range(6):
        m = Motion(fps, names, parents, offsets, _pose(p, names, phi, hip_scale, adduction), zero)
        got = _stance_travel(m, stance["l"])
        want = _planted_travel(m, stance, p.speed_mps)
        hip_scale = float(np.clip(hip_scale * want / max(got, 1e-3), 0.3, HIP_SCALE_MAX))
        # Walking base: the lateral distance between the ankles at mid-stance.
        base = _walking_base(m, stance)
        adduction += np.degrees((base - p.walking_base_m) / 2 / leg)
    if hip_scale >= HIP_SCALE_MAX and want > 1.02 * got:
        raise StimuliError(
            f"gait {p.gait}: at speed_mps {p.speed_mps:g}, cadence_spm {p.cadence_spm:g} and stance_fraction "
            f"{p.stance_fraction:.2f} a planted foot travels {want:.2f} m under the body during each stance, more "
            f"than the legs of a {height_m:.2f} m body reach ({got:.2f} m with the hip swinging "
            f"{HIP_SCALE_MAX:g}× its basis curve's range); lower speed_mps or stance_fraction, or raise cadence_spm")
    rot = _pose(p, names, phi, hip_scale, adduction)
    m = Motion(fps, names, parents, offsets, rot, zero)
    root = zero.copy()
    root[:, 1] = _root_height(m, stance, fps)
    rot = _stabilise_head(names, parents, offsets, rot, root, p.head_stabilisation)
    m = Motion(fps, names, parents, offsets, rot, root)
    m = m.replace(rotations=_flatten_toes(m))
    meta = {"source": "generator", "gait": p.gait, "cadence_spm": cadence, "speed_mps": p.speed_mps,
            "belt_speed_mps": p.speed_mps, "step_length_m": p.speed_mps * 60.0 / cadence, "cycles": cycles,
            "stance_fraction": p.stance_fraction, "treadmill": True, "looped": True, "height_m": height_m,
            "hip_flexion_scale": hip_scale, "params": asdict(p), "naming": "canonical",
            "contacts": {s: stance[s].astype(int).tolist() for s in ("l", "r")}}
    m = m.replace(metadata=meta)
    if cleanup:
        floor = -skeleton_floor(m)
        # The swing clearance only in the last pass: each pass would turn the toes up again.
        m = clean_feet(m, stance, belt_speed=p.speed_mps, floor_y=floor, cyclic=True)
        planted = m
        m = balance(m, stance, floor_y=floor)
        m = clean_feet(m, stance, belt_speed=p.speed_mps, floor_y=floor, cyclic=True,
                       clearance_m=SWING_CLEARANCE_M[p.gait], reference=planted)
    return m
