"""The paper's controller: PD joint torques plus PD world force and torque on the root.

Joint torques ``τ = k_p (q̄ − q) − k_d q̇`` are MuJoCo position actuators (``kp``, ``kv``), one per
DoF. Per DoF the gains are ``k_p · I_j`` and ``k_d · I_j`` where ``I_j`` is the base character's
joint-space inertia at that DoF in the rest pose (diagonal of MuJoCo's mass matrix: what the DoF
has to swing), so that one pair of scalars suits hips and wrists alike. The root gets a world force
``F = k_pf (p̄ − p) + k_df (v̄ − v)`` and torque ``T = k_pr θ(R̄ Rᵀ) + k_dr (ω̄ − ω)`` on the
pelvis (the paper's k_pf, k_df; the velocity terms use the reference velocity because the root
travels at walking speed). All gains are found once for the base character
(:mod:`stimuli.physics.tune`), stored in ``gains.json`` as absolute values and then kept fixed for
every body, as the paper did: heavier or lighter segments then follow the same motion differently.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from stimuli.errors import StimuliError

GAINS_FILE = Path(__file__).with_name("gains.json")
# One gain set per gait, each tuned once on the base character and kept for every body: a jog's
# knee moves about twice as fast as a walk's, and the walking gains, whose damping lags fast
# motion (−k_d q̇), tracked the Exp-2 jogs at 3.4–4.0° (their reference bodies 3.6–3.7°).
GAITS = ("walk", "jog")
GAIT_ALIASES = {"run": "jog", "running": "jog", "jogging": "jog", "walking": "walk"}


@dataclasses.dataclass
class Gains:
    """Controller gains (SI units); ``profile`` is the base character's per-DoF inertia (kg·m²)."""

    k_p: float
    k_d: float
    k_pf: float
    k_df: float
    k_pr: float
    k_dr: float
    profile: dict[str, float]
    base: dict = dataclasses.field(default_factory=dict)
    tuning: dict = dataclasses.field(default_factory=dict)
    gait: str = "walk"

    def joint_gains(self, dof_names: list[str]) -> tuple[dict[str, float], dict[str, float]]:
        """Absolute kp, kd per DoF (N·m/rad, N·m·s/rad)."""
        missing = [d for d in dof_names if d not in self.profile]
        if missing:
            raise StimuliError(f"{GAINS_FILE}: no gain for DoF {', '.join(missing)}")
        return ({d: self.k_p * self.profile[d] for d in dof_names},
                {d: self.k_d * self.profile[d] for d in dof_names})

    @classmethod
    def load(cls, path: Path = GAINS_FILE, gait: str = "walk") -> "Gains":
        """The gain set of ``gait`` (``walk`` or ``jog``; ``run`` is a jog) from a gains file."""
        key = gait_key(gait)
        try:
            sets = json.loads(Path(path).read_text())
            return cls(**sets[key], gait=key)
        except KeyError:
            raise StimuliError(f"{path}: no controller gains for gait {key!r}; run `shapemotion physics tune`") from None
        except (OSError, ValueError, TypeError) as exc:
            raise StimuliError(f"{path}: cannot read controller gains ({exc}); run `shapemotion physics tune`") from None


def gait_key(gait: str | None) -> str:
    """``walk`` or ``jog`` for a gait name (``run`` → ``jog``); StimuliError otherwise.

    >>> gait_key("run"), gait_key("walk")
    ('jog', 'walk')
    """
    key = GAIT_ALIASES.get(str(gait).lower(), str(gait).lower())
    if key not in GAITS:
        raise StimuliError(f"controller gains exist for gaits {', '.join(GAITS)} (or run), not {gait!r}")
    return key


def motion_gait(motion) -> str:
    """The gait whose gains drive ``motion``: its metadata ``gait`` (generator, averages), else walk."""
    gait = motion.metadata.get("gait")
    return gait_key(gait) if gait else "walk"


def save_gains(gains: dict[str, Gains], path: Path = GAINS_FILE) -> Path:
    """Write the per-gait gain sets (``{"walk": Gains, "jog": Gains}``) as one JSON file."""
    payload = {gait: {k: v for k, v in dataclasses.asdict(g).items() if k != "gait"} for gait, g in gains.items()}
    Path(path).write_text(json.dumps(payload, indent=1, sort_keys=True) + "\n")
    return Path(path)


# Share of the rest of the body's inertia about a leg joint added to its own (stance support).
# The ankle gets a tenth of the hip's and knee's share: with 0.1 it was held at ~21 kN·m/rad
# (human walking quasi-stiffness is a few hundred), so every heel strike landed on a rigid lever
# and bounced the body off the floor — 14–18 % of a walk had no foot down (the reference: none).
# With 0.01 (≈ 2 kN·m/rad) a walk keeps a foot on the floor and the jog's landings stop pumping
# the pelvis (±9 cm on the heaviest man before); softer still (0.003) the heavy jog topples. The
# toes carry the body at push-off as the ankle does and get its share (with their own inertia
# alone, 0.01 kg·m², they lagged their bend: CMU 07_12's tracking 2.62° against 1.70°).
STANCE_WEIGHTS = {"hip": 0.1, "knee": 0.1, "ankle": 0.01, "toe": 0.01}


def inertia_profile(model, stance_weights: dict[str, float] | None = None) -> dict[str, float]:
    """Per-DoF inertia (kg·m²) the PD gains scale with, at the rest pose.

    Swing: the diagonal of the joint-space inertia matrix (what the DoF moves when the body is
    free). Legs also carry the body in stance: for hip, knee, ankle and toe DoFs the rest of the body's
    inertia about the joint (point masses of the segments not below it), times the joint's
    ``stance_weights`` entry (:data:`STANCE_WEIGHTS`), is added, otherwise gravity folds a stance
    leg whose own segments are light.
    """
    import mujoco

    weights = STANCE_WEIGHTS if stance_weights is None else stance_weights
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    out = {}
    for a in range(model.nu):
        joint = model.actuator_trnid[a, 0]
        name = model.actuator(a).name
        value = float(full[model.jnt_dofadr[joint], model.jnt_dofadr[joint]])
        kind = name.split(".")[0].split(":")[0]
        if kind in weights:
            below = _subtree(model, model.jnt_bodyid[joint])
            rest = [b for b in range(1, model.nbody) if b not in below]
            d2 = np.sum((data.xipos[rest] - data.xanchor[joint]) ** 2, axis=1)
            value += weights[kind] * float(np.sum(model.body_mass[rest] * d2))
        out[name] = value
    return out


def _subtree(model, body: int) -> set[int]:
    """Indices of ``body`` and all bodies below it."""
    out = {body}
    for b in range(body + 1, model.nbody):
        if model.body_parentid[b] in out:
            out.add(b)
    return out


def set_joint_gains(model, kp: dict[str, float], kd: dict[str, float]) -> None:
    """Write PD gains into a compiled model's position actuators (no recompilation)."""
    for a in range(model.nu):
        name = model.actuator(a).name
        model.actuator_gainprm[a, 0] = kp[name]
        model.actuator_biasprm[a, 1] = -kp[name]
        model.actuator_biasprm[a, 2] = -kd[name]


def set_root_damping(model, gains: Gains) -> None:
    """The velocity terms ``−k_df v`` and ``−k_dr ω`` of the root wrench as the free joint's damping.

    MuJoCo's implicitfast integrator treats DoF damping implicitly; applied explicitly through
    ``xfrc_applied`` (first version) the root's ``k_dr`` sat near the explicit stability limit
    of the light pelvis at a 1-ms step, and the chattering root pumped the ragdoll into hopping
    (about a third of each walk with no foot on the floor). The reference-velocity parts
    ``k_df v̄`` and ``k_dr ω̄`` do not depend on the state and stay in :class:`RootWrench`. The
    damping is isotropic, so the free joint's local angular velocity gives the same torque as
    the world one.
    """
    if model.jnt_type[0] != 0 or model.jnt_dofadr[0] != 0:  # mjJNT_FREE at DoF 0: the pelvis root
        raise ValueError("the ragdoll's first joint must be the free root joint")
    model.dof_damping[0:3] = gains.k_df
    model.dof_damping[3:6] = gains.k_dr


def apply_root_wrench(data, gains: Gains, target: dict, i: int, pelvis: int) -> None:
    """Write the root wrench into the free joint's generalised forces (``qfrc_applied[:6]``).

    A free joint's translational DoFs are the body origin's world position, so their generalised
    force is a world force at the origin — where the PD measures the position and where the
    implicit damping ``−k_df v`` acts; its rotational DoFs take the torque in the body frame.
    (``xfrc_applied`` would put the force at the segment's CoM, a few cm away: with the damping at
    the origin that leaves a spurious couple of about k_df·v̄·r ≈ 50 N·m.)
    """
    RootWrench(gains, target).apply(data, i, pelvis)


class RootWrench:
    """World force and torque (6,) on the pelvis at step ``i`` of one simulation's sampled targets.

    ``k_pf (p̄ − p) + k_df v̄`` and ``k_pr θ(R̄ Rᵀ) + k_dr ω̄``; the ``−k_df v``, ``−k_dr ω`` terms
    act through the free joint's implicit damping (:func:`set_root_damping`). Uses MuJoCo's
    quaternion and matrix helpers (scipy's are 20× slower, numpy's temporaries 2×). The
    simulation's compiled loop (:mod:`stimuli.physics.stepper`) makes the same MuJoCo calls in
    the same order on this object's targets and gains; :meth:`apply` is their plain Python form,
    which the tests hold the loop to. The returned array is this object's buffer, overwritten by
    the next call.
    """

    def __init__(self, gains: Gains, target: dict):
        import mujoco

        self.k_pf, self.k_df, self.k_pr, self.k_dr = gains.k_pf, gains.k_df, gains.k_pr, gains.k_dr
        self.pos, self.vel = target["root_pos"], target["root_vel"]
        self.quat, self.omega = target["root_quat"], target["root_omega"]
        self.inv, self.err_q, self.err = np.empty(4), np.empty(4), np.empty(3)
        self.wrench = np.empty(6)
        self.force, self.torque = self.wrench[:3], self.wrench[3:]
        self.neg, self.mul, self.to_vel = mujoco.mju_negQuat, mujoco.mju_mulQuat, mujoco.mju_quat2Vel
        self.sub, self.scale, self.add_scaled = mujoco.mju_sub3, mujoco.mju_scl3, mujoco.mju_addToScl3
        self.rotate_back = mujoco.mju_mulMatTVec3

    def __call__(self, pos, quat_wxyz, i: int) -> np.ndarray:
        self._wrench(self.force, self.torque, pos, quat_wxyz, i)
        return self.wrench

    def apply(self, data, i: int, pelvis: int) -> None:
        """:func:`apply_root_wrench` with this simulation's targets; the force goes straight into
        ``qfrc_applied``."""
        self._wrench(data.qfrc_applied[0:3], self.torque, data.qpos[:3], data.qpos[3:7], i)
        self.rotate_back(data.qfrc_applied[3:6], data.xmat[pelvis], self.torque)

    def _wrench(self, force, torque, pos, quat_wxyz, i: int) -> None:
        """The world force and torque at step ``i`` into ``force`` and ``torque`` (3-vectors)."""
        self.sub(force, self.pos[i], pos)
        self.scale(force, force, self.k_pf)
        self.add_scaled(force, self.vel[i], self.k_df)
        self.neg(self.inv, quat_wxyz)
        self.mul(self.err_q, self.quat[i], self.inv)
        self.to_vel(self.err, self.err_q, 1.0)
        self.scale(torque, self.err, self.k_pr)
        self.add_scaled(torque, self.omega[i], self.k_dr)


# Actuator torque limits (N·m), the same for every body (fat mass adds no muscle), per joint and
# Euler axis (X: flexion/extension, Z: ab-/adduction or inversion/eversion, Y: axial rotation). The
# actuators are symmetric, so each carries the larger direction of its pair where the source gives both.
# Every sourced limit is scaled to one normal-weight man, the base character (1.75 m, BMI 23: 70.4 kg).
#
# Hip, knee and ankle flexion/extension (X): Anderson, Madigan & Nussbaum (2007), J Biomech
# 40:3105–3113, Table 3, young men (18–25 years): the peak isometric torque c1 as a fraction of body
# weight × height. Extension c1 hip 0.161, knee 0.163, ankle (plantar flexion) 0.095; flexion 0.113,
# 0.087, 0.033 (young women: extension 0.181, 0.159, 0.104). Table 3 was read in RBDL's transcription
# (addons/muscle/Millard2016TorqueMuscle.cc, Anderson2007Table3Mean), not in the paper, which is not
# in ../shared/seeds: 195, 197 and 115 N·m.
# Hip ab-/adduction (Z): Sugimoto, Mattacola, Mullineaux, Palmer & Hewett (2014), Clin J Sport Med
# 24:422–428, abstract: peak hip abduction torque of 16 male collegiate athletes 1.29 ± 0.24 N·m/kg
# (concentric, 60°/s, standing; adduction is not given there): 91 N·m.
# Ankle inversion/eversion (Z): da Fonseca et al. (2025), World J Orthop 16(10):108858, abstract and
# Table 1: mean peak torque of 200 ankles (69 men, 31 women; Biodex 3, isokinetic) inversion 34.8,
# eversion 29.9 N·m: 35 N·m (not scaled: the paper gives no per-kg figure).
# Elbow flexion/extension: Lategan & Krüger (2003), Afr J Phys Health Educ Recreat Dance, special
# edition 165–172, abstract: 199 young men, concentric isokinetic (Cybex 340), flexion 78 % and
# extension 67 % of body mass (N·m per kg × 100): 55 N·m.
# Neck (X flexion/extension, Z lateral bending, Y axial rotation): "Prediction of three-dimensional
# maximum isometric neck strength", Ann Biomed Eng 2014, doi:10.1007/s10439-014-1046-0, abstract:
# 9 men (29 ± 9 years), maximum isometric moments flexion 30 ± 6, lateral bending 32 ± 9, extension
# 51 ± 11, axial rotation 13 ± 5 N·m: 51, 32 and 13 N·m.
# Shoulder flexion/extension (X): "Dynamic shoulder flexion strength for use in occupational risk
# analysis and clinical assessment", abstract: 26 young men, static flexion torque at 0° (anatomical
# position) 89.9 N·m (45°: 68.6; concentric at 50°/s: 46.9): 90 N·m. Extension is stronger than
# flexion by 5:4 ("Isokinetic testing of shoulder strength: normal values", Arch Phys Med Rehabil
# 1985;66:384–386, abstract), which this symmetric actuator does not carry.
# Shoulder ab-/adduction (Z): "Isokinetic muscle strength parameters for shoulder movements", Clin
# Biomech 1989, doi:10.1016/0268-0033(89)90046-6, abstract: 20 men (25 years), the adductors, the
# strongest group, 48.0 N·m peak (women 28.8): 48 N·m.
# Shoulder rotation (Y): Clinics (São Paulo) 2011;66(2):313–320, doi:10.1590/S1807-59322011000200022,
# Table 1: concentric internal rotation at 60°/s of the uninjured shoulders of 33 athletes treated for
# a shoulder injury, 59.5 (n = 15) and 65.3 N·m (n = 18), external 34.3 and 34.5: 63 N·m (the mean).
# Spine flexion/extension (X): Chaffin, Andersson & Martin, Occupational Biomechanics (3rd ed., 1999),
# Table 4.5, maximal torso extension of men at 20° of flexion, 288 N·m, as quoted in J Electromyogr
# Kinesiol 2012;22(6):814–820, Table 2 (doi:10.1016/j.jelekin.2012.04.006): 288 N·m.
# Toe flexion at the ball (the metatarsophalangeal joints): Goldmann & Brüggemann (2012), J Anat
# 221:187–194, abstract (PMC3406365): maximal voluntary isometric moments of 20 men's toe flexors
# 6.3 ± 2.6 to 14.2 ± 5.8 N·m over ankle and toe angles, the largest at 25–45° of toe dorsiflexion,
# the push-off's: 14.2 N·m (not scaled: the abstract gives no per-kg figure).
# Trunk lateral bending (Z): Huang et al. (2000), "Trunk muscle strength in eccentric and concentric
# lateral flexion", Eur J Appl Physiol 83(6):573–577 (doi:10.1007/s004210000307),
# abstract: 12 men, static lateral flexion torque 80–172 N·m over five positions from 20° to −20°
# (concentric 66–140, eccentric 211–218 N·m): 172 N·m, the largest static figure (not scaled: the
# abstract gives no per-kg figure).
# Hip rotation (Y): Johnson & Hoffman (2010), J Sport Rehabil 19:12–20: 15 young men (81.3 kg),
# average isometric torque over a 6-s contraction, normalised to body mass, external rotation 0.52
# and 0.535 N·m/kg at 10° and 40° of hip flexion (internal 0.385 and 0.47), the hip angles of gait;
# read as N·m for 81.3 kg (42.3, 43.5; 31.3, 38.2) in the AnyBody strength-studies compilation
# (github.com/AnyBody/strength-studies, convert-matlab-data/isometric.parquet, rows of study ids 58
# and 59), not in the paper: 0.535 × 70.4 kg = 38 N·m.
# The isokinetic figures (hip abduction, ankle inversion, elbow, shoulder rotation and adduction) are
# concentric peaks, below an isometric maximum; every figure was read in a reachable abstract or
# table (not the paper itself where only an abstract is named), none is in ../shared/seeds.
#
# Ankle rotation about the vertical (Y): no clinical test measures it, but the muscles that turn
# the foot about the vertical are the invertors and evertors, which act about the subtalar joint's
# axis, and that axis is oblique: 42° from the transverse plane and 16° from the sagittal plane in
# the most commonly used model, the mean of cadaver studies (Payne, Munteanu & Miller 2003, J Am
# Podiatr Med Assoc 93(2):131–135, introduction). A torque T about that axis reads T·cos 42°·cos 16°
# about the foot's long axis, where the dynamometer measures inversion (da Fonseca et al., above:
# 34.8 N·m), and T·sin 42° about the vertical, so the same muscles give 34.8 × tan 42° / cos 16° =
# 32.6 N·m about the vertical: 33 N·m. Derived, not measured: the axis varies from foot to foot,
# and 33°–51° of inclination would give 24–45 N·m; the talocrural axis's small tilt, which turns a
# part of the plantar flexors' torque about the vertical too, is not counted (it comes only with
# plantar flexion).
#
# PROVENANCE NOT CHECKED for the one remaining axis, the trunk's axial rotation: 100 N·m was written
# from memory and has no published figure behind it. It used to be put down to Harbo, Brincks &
# Andersen (2012), Eur J Appl Physiol 112:267–275, but their regressions (18 tests, transcribed with
# their coefficients in github.com/dambach/app_strength-Harbo, coeff_men.csv) cover the knee, ankle,
# hip, shoulder, elbow and wrist, and no trunk axis.
NORM_BODY_MASS_KG = 23.0 * 1.75**2                            # the base character
NORM_BODY_WEIGHT_HEIGHT_NM = 9.81 * NORM_BODY_MASS_KG * 1.75  # its weight (N) × height (m)
ANDERSON_2007_C1 = {"hip": 0.161, "knee": 0.163, "ankle": 0.095}
SUGIMOTO_2014_HIP_ABDUCTION_NM_PER_KG = 1.29
DA_FONSECA_2025_ANKLE_INVERSION_NM = 34.8
LATEGAN_2003_ELBOW_FLEXION_NM_PER_KG = 0.78
NECK_ISOMETRIC_2014_NM = {"X": 51.0, "Z": 32.0, "Y": 13.0}   # extension, lateral bending, axial rotation
SHOULDER_FLEXION_STATIC_NM = 89.9
SHOULDER_ADDUCTION_1989_NM = 48.0
SHOULDER_INTERNAL_ROTATION_2011_NM = (15 * 59.5 + 18 * 65.3) / 33
CHAFFIN_1999_TORSO_EXTENSION_NM = 288.0
GOLDMANN_2012_MTP_FLEXION_NM = 14.2
HUANG_2000_TRUNK_LATERAL_FLEXION_NM = 172.0
JOHNSON_2010_HIP_EXTERNAL_ROTATION_NM_PER_KG = 0.535
PAYNE_2003_SUBTALAR_AXIS_DEG = {"from_transverse": 42.0, "from_sagittal": 16.0}


def _about_the_vertical(inversion_nm: float) -> float:
    """Torque (N·m) about the vertical of the subtalar muscles that give ``inversion_nm`` about the
    foot's long axis (:data:`PAYNE_2003_SUBTALAR_AXIS_DEG`): their torque lies along the oblique axis.

    >>> round(_about_the_vertical(34.8), 1)
    32.6
    """
    up = np.radians(PAYNE_2003_SUBTALAR_AXIS_DEG["from_transverse"])
    medial = np.radians(PAYNE_2003_SUBTALAR_AXIS_DEG["from_sagittal"])
    return float(inversion_nm * np.tan(up) / np.cos(medial))


TORQUE_LIMITS_NM = {
    "spine": {"X": CHAFFIN_1999_TORSO_EXTENSION_NM, "Z": HUANG_2000_TRUNK_LATERAL_FLEXION_NM, "Y": 100.0},
    "neck": dict(NECK_ISOMETRIC_2014_NM),
    "shoulder": {"X": float(round(SHOULDER_FLEXION_STATIC_NM)), "Z": SHOULDER_ADDUCTION_1989_NM,
                 "Y": float(round(SHOULDER_INTERNAL_ROTATION_2011_NM))},
    "elbow": {"": float(round(LATEGAN_2003_ELBOW_FLEXION_NM_PER_KG * NORM_BODY_MASS_KG))},
    "hip": {"X": float(round(ANDERSON_2007_C1["hip"] * NORM_BODY_WEIGHT_HEIGHT_NM)),
            "Z": float(round(SUGIMOTO_2014_HIP_ABDUCTION_NM_PER_KG * NORM_BODY_MASS_KG)),
            "Y": float(round(JOHNSON_2010_HIP_EXTERNAL_ROTATION_NM_PER_KG * NORM_BODY_MASS_KG))},
    "knee": {"": float(round(ANDERSON_2007_C1["knee"] * NORM_BODY_WEIGHT_HEIGHT_NM))},
    "ankle": {"X": float(round(ANDERSON_2007_C1["ankle"] * NORM_BODY_WEIGHT_HEIGHT_NM)),
              "Z": float(round(DA_FONSECA_2025_ANKLE_INVERSION_NM)),
              "Y": float(round(_about_the_vertical(DA_FONSECA_2025_ANKLE_INVERSION_NM)))},
    "toe": {"": GOLDMANN_2012_MTP_FLEXION_NM},
}
# Where each limit comes from (above), short enough for a report; an axis without a published figure
# says so. The report gives this beside each peak.
LIMIT_SOURCES = {
    ("hip", "X"): "Anderson, Madigan & Nussbaum 2007, Table 3 (c1 0.161 × weight × height)",
    ("knee", ""): "Anderson, Madigan & Nussbaum 2007, Table 3 (c1 0.163 × weight × height)",
    ("ankle", "X"): "Anderson, Madigan & Nussbaum 2007, Table 3 (c1 0.095 × weight × height)",
    ("hip", "Z"): "Sugimoto et al. 2014 (1.29 N·m/kg × 70.4 kg)",
    ("hip", "Y"): "Johnson & Hoffman 2010 (0.535 N·m/kg × 70.4 kg)",
    ("ankle", "Z"): "da Fonseca et al. 2025, Table 1 (inversion 34.8 N·m)",
    ("ankle", "Y"): "derived: da Fonseca et al. 2025 inversion 34.8 N·m through the subtalar axis "
                    "(42° from transverse, 16° from sagittal; Payne et al. 2003): × tan 42° / cos 16°",
    ("elbow", ""): "Lategan & Krüger 2003 (0.78 N·m/kg × 70.4 kg)",
    ("neck", "X"): "Ann Biomed Eng 2014, doi:10.1007/s10439-014-1046-0 (extension 51 N·m)",
    ("neck", "Z"): "Ann Biomed Eng 2014, doi:10.1007/s10439-014-1046-0 (lateral bending 32 N·m)",
    ("neck", "Y"): "Ann Biomed Eng 2014, doi:10.1007/s10439-014-1046-0 (axial rotation 13 N·m)",
    ("shoulder", "X"): "Dynamic shoulder flexion strength (static flexion at 0°, 89.9 N·m)",
    ("shoulder", "Z"): "Clin Biomech 1989, doi:10.1016/0268-0033(89)90046-6 (adduction 48.0 N·m)",
    ("shoulder", "Y"): "Clinics 2011;66(2):313-320, Table 1 (internal rotation 59.5 / 65.3 N·m)",
    ("spine", "X"): "Chaffin, Andersson & Martin 1999, Table 4.5 (torso extension 288 N·m)",
    ("spine", "Z"): "Huang et al. 2000 (static lateral flexion, largest 172 N·m)",
    ("toe", ""): "Goldmann & Brüggemann 2012 (toe flexion 14.2 N·m)",
}
# The axes whose limit has a published figure behind it (read, or derived as the ankle's vertical
# axis is); the report says which these are.
SOURCED_LIMITS = frozenset(LIMIT_SOURCES)
UNSOURCED = "not checked: written from memory, no published figure found"


def torque_limit(dof: str) -> float:
    """Torque limit (N·m) of a ragdoll DoF name (``knee.L``, ``hip.R:X``).

    >>> torque_limit("knee.L"), torque_limit("hip.R:X"), torque_limit("hip.R:Z"), torque_limit("ankle.L:Z")
    (197.0, 195.0, 91.0, 35.0)
    """
    joint, axis = _joint_axis(dof)
    return TORQUE_LIMITS_NM[joint][axis]


def torque_limit_sourced(dof: str) -> bool:
    """Whether the limit of a ragdoll DoF has a published figure behind it (:data:`SOURCED_LIMITS`).

    >>> torque_limit_sourced("knee.L"), torque_limit_sourced("hip.R:Y"), torque_limit_sourced("spine:Y")
    (True, True, False)
    """
    return _joint_axis(dof) in SOURCED_LIMITS


def torque_limit_source(dof: str) -> str:
    """Where the limit of a ragdoll DoF comes from (:data:`LIMIT_SOURCES`), or that it is not checked.

    >>> torque_limit_source("hip.L:Y")
    'Johnson & Hoffman 2010 (0.535 N·m/kg × 70.4 kg)'
    >>> torque_limit_source("spine:Y").startswith("not checked")
    True
    """
    return LIMIT_SOURCES.get(_joint_axis(dof), UNSOURCED)


def _joint_axis(dof: str) -> tuple[str, str]:
    """``("hip", "X")`` of ``hip.R:X``, ``("knee", "")`` of ``knee.L``: the keys of the limit tables."""
    joint, _, axis = dof.partition(":")
    return joint.split(".")[0], axis


def set_torque_limits(model, limits: dict[str, float] | None = None) -> np.ndarray:
    """Clamp every actuator's total torque (PD + feed-forward) to its limit; returns the limits."""
    names = [model.actuator(a).name for a in range(model.nu)]
    lim = np.array([limits[n] if limits else torque_limit(n) for n in names])
    model.actuator_forcelimited[:] = 1
    model.actuator_forcerange[:, 0] = -lim
    model.actuator_forcerange[:, 1] = lim
    return lim
