"""Run the ragdoll in MuJoCo: PD tracking of the reference, fall detection, recorded trajectories.

The simulation step is an integer fraction of the clip's frame period (≥ 4 kHz by default,
never below 500 Hz), so recorded frames fall exactly on the clip's frames. The clip is looped:
``warmup_loops`` passes let the start transient die out, then one more pass is recorded (plus the
frame that closes it, so the output loop can be made seamless).
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time

import numpy as np

from stimuli.physics.controller import Gains, RootWrench, set_root_damping
from stimuli.physics.stepper import Stepper
from stimuli.physics.swing import UPDATE_STEPS, SwingController, actuator_qpos, swing_placement

MIN_RATE_HZ = 500.0
# 4 kHz: the stiff PD legs on soft contacts are not converged at 1 kHz — from 1 to 2 to 4 to
# 8 kHz a walk's vertical root drift went 4.0 → 1.5 → 1.5 → 1.5 cm and the share of steps with no
# foot on the floor 0.28 → 0.21 → 0.17 → 0.13 (F_Hi1); still 4–7× faster than real time.
DEFAULT_RATE_HZ = 4000.0
# A fall: pelvis below this fraction of its target height, pelvis or trunk tilted beyond this
# angle, or the root this far (m) from its target horizontally. The trunk is checked on its own:
# the root wrench can hold the pelvis upright while the trunk folds over it (a ragdoll whose
# actuators were limited to a lighter body's torques folded its spine 160° without a "fall").
FALL_HEIGHT_FRACTION = 0.6
FALL_TILT_DEG = 60.0
FALL_DRIFT_M = 0.5


@dataclasses.dataclass
class SimResult:
    """Recorded trajectories of the last (recorded) loop, one row per clip frame (+1 closing frame)."""

    fps: float
    timestep: float
    times: np.ndarray
    qpos: np.ndarray
    q: np.ndarray
    qref: np.ndarray
    xquat: np.ndarray
    xpos: np.ndarray
    root_target: np.ndarray
    root_target_quat: np.ndarray   # the pelvis's target orientation (w, x, y, z) per recorded frame
    pelvis_com: np.ndarray
    actuator_force: np.ndarray   # every simulation step of the recorded pass × actuator (N·m)
    foot_contact: np.ndarray
    step_times: np.ndarray
    fell: bool
    fall_time_s: float | None
    fall_reason: str
    simulated_s: float
    wall_s: float
    body_names: list[str]
    dof_names: list[str]

    @property
    def knee_torque(self) -> np.ndarray:
        """Left and right knee actuator torques (N·m) at every step of the recorded pass."""
        return self.actuator_force[:, [self.dof_names.index("knee.L"), self.dof_names.index("knee.R")]]


def steps_per_frame(fps: float, rate_hz: float = DEFAULT_RATE_HZ) -> int:
    """Simulation steps per clip frame so that the rate is at least ``rate_hz`` (and ≥ 500 Hz)."""
    return max(1, math.ceil(max(rate_hz, MIN_RATE_HZ) / fps))


def _initial_state(model, data, target: dict, dof_adr: np.ndarray) -> None:
    import mujoco

    data.qpos[:3] = target["root_pos"][0]
    data.qpos[3:7] = target["root_quat"][0]
    data.qvel[:3] = target["root_vel"][0]
    data.qvel[3:6] = _to_local(target["root_quat"][0], target["root_omega"][0])
    data.qpos[dof_adr + 1] = target["q"][0]
    data.qvel[dof_adr] = target["qd"][0]
    data.ctrl[:] = target["q"][0]
    mujoco.mj_forward(model, data)


def _to_local(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    from stimuli.motion import quat

    return quat.rotate(quat.inv(q), v)


def ground_offset(model, ref, n: int = 60) -> float:
    """Vertical shift (m) that puts the lowest foot points over the clip on the floor.

    Poses the model kinematically at ``n`` instants of the reference and takes, per instant, the
    lowest corner of the feet's boxes (feet and toes); the 10th percentile of those minima goes to y = 0. A
    reference that carries the floor in its root already (``ref.grounded``, :mod:`stimuli.physics.toes`)
    needs no shift.
    """
    import mujoco

    if getattr(ref, "grounded", False):
        return 0.0

    data = mujoco.MjData(model)
    dof_adr = actuator_qpos(model) - 1
    feet = [g for side in foot_geoms(model) for g in side]
    target = ref.sample(np.linspace(0, ref.period, n, endpoint=False))
    lows = []
    for i in range(n):
        data.qpos[:3] = target["root_pos"][i]
        data.qpos[3:7] = target["root_quat"][i]
        data.qpos[dof_adr + 1] = target["q"][i]
        mujoco.mj_kinematics(model, data)
        lows.append(min(lowest_corner(model, data, g) for g in feet))
    return -float(np.percentile(lows, 10))


def foot_geoms(model) -> list[list[int]]:
    """Per side (L, R): the geoms of the foot and of its toes where it has them, the ragdoll's only
    shapes that touch the floor."""
    import mujoco

    ids = [[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{part}.{side}") for part in ("foot", "toes")]
           for side in "LR"]
    return [[g for g in side if g >= 0] for side in ids]


def lowest_corner(model, data, geom: int) -> float:
    """Height (m) of the lowest corner of a box geom in the posed ``data``."""
    return float((data.geom_xpos[geom][1] + box_corners(model, geom) @ data.geom_xmat[geom].reshape(3, 3)[1]).min())


def box_corners(model, geom: int) -> np.ndarray:
    """The 8 corners (8 × 3, m) of a box geom in its own frame."""
    return np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * model.geom_size[geom]


def simulate(model, ref, gains: Gains, warmup_loops: int = 1, rate_hz: float = DEFAULT_RATE_HZ,
             duration_s: float | None = None, feedforward=None, swing_stance: np.ndarray | None = None) -> SimResult:
    """Track ``ref`` with the ragdoll ``model``; record the loop after ``warmup_loops`` passes.

    ``duration_s`` (optional) records that long instead of one loop (benchmarks, tests).
    ``feedforward`` (a :class:`stimuli.physics.feedforward.Feedforward` of the same DoFs): its
    torques are added to the PD's inside each actuator (its constant bias term), so the
    actuator's force range, when set, limits the sum.
    ``swing_stance`` (frame × 2, the reference's stance per foot): place each swinging foot in the
    world as the reference does (:mod:`stimuli.physics.swing`; walks).
    """
    import mujoco

    mujoco.set_mju_user_warning(_mujoco_warning)
    k = steps_per_frame(ref.fps, rate_hz)
    dt = 1.0 / (ref.fps * k)
    model.opt.timestep = dt
    set_root_damping(model, gains)
    data = mujoco.MjData(model)
    n_rec = ref.n_frames + 1 if duration_s is None else int(round(duration_s * ref.fps)) + 1
    start_frame = warmup_loops * ref.n_frames
    n_steps = (start_frame + n_rec - 1) * k + 1
    lift = ground_offset(model, ref)
    target = ref.sample(np.arange(n_steps) * dt)
    target["root_pos"][:, 1] += lift
    dof_adr = actuator_qpos(model) - 1
    pelvis = model.body("pelvis").id
    trunk = model.body("spine").id
    side_of_geom = np.full(model.ngeom, -1)      # 0 left foot or toes, 1 right, -1 neither
    for side, geoms in enumerate(foot_geoms(model)):
        side_of_geom[geoms] = side
    _initial_state(model, data, target, dof_adr)
    tau_ff = None
    if feedforward is not None:
        if list(feedforward.dof_names) != [model.actuator(a).name for a in range(model.nu)]:
            raise ValueError("the feed-forward's DoFs are not the model's actuators")
        # The PD damps the absolute joint velocity (the paper's −k_d q̇): at exact tracking it
        # still brakes with −k_d q̄̇, so the feed-forward carries +k_d q̄̇ (with it, a floating
        # ragdoll at 1 % of the gains follows the reference to 0.1° over a second; without, 20°+).
        tau_ff = feedforward.sample(np.arange(n_steps) * dt) - model.actuator_biasprm[:, 2] * target["qd"]
    swing = None
    if swing_stance is not None:
        swing = SwingController(model, swing_placement(model, ref, swing_stance, lift))
    rec = {key: [] for key in ("qpos", "q", "qref", "xquat", "xpos", "root_target", "root_target_quat", "pelvis_com")}
    forces = np.zeros((n_steps, model.nu))
    contact = np.zeros((n_steps, 2), bool)
    target_height = target["root_pos"][:, 1]
    fell, fall_time, reason = False, None, ""
    stepper = Stepper(model, data, target["q"], tau_ff, RootWrench(gains, target), pelvis, forces, contact, side_of_geom)
    offset = None
    update_steps = UPDATE_STEPS if swing is not None else n_steps
    wall = time.perf_counter()
    i = 0
    while i < n_steps:
        # Python between the compiled runs: a recorded frame, a swing-foot solve, a fall check.
        if i % k == 0 and i // k >= start_frame:
            _record(rec, data, target, i, dof_adr, pelvis)
        if swing is not None and i % UPDATE_STEPS == 0:
            offset = swing.targets(data, i * dt, target["q"][i], target["root_pos"][i]) - target["q"][i]
        end = i + 1 if i % k == 0 else min((i // k + 1) * k, (i // update_steps + 1) * update_steps, n_steps)
        i, diverged = stepper.run(i, end, offset)
        if diverged:
            fell, fall_time, reason = True, (i + 1) * dt, "the simulation diverged (gains unstable for this body)"
            break
        if i % k == 0:
            reason = _fall_reason(data, pelvis, trunk, target, i, target_height[i])
            if reason:
                fell, fall_time = True, (i + 1) * dt
                break
        i += 1
    i = min(i, n_steps - 1)
    wall = time.perf_counter() - wall
    model.actuator_biasprm[:, 0] = 0.0
    simulated = (i + 1) * dt
    out = {key: np.array(v) for key, v in rec.items()}
    if not rec["qpos"]:  # fell during the warm-up: empty arrays of the right shapes
        shapes = {"qpos": model.nq, "q": model.nu, "qref": model.nu, "xquat": (model.nbody, 4),
                  "xpos": (model.nbody, 3), "root_target": 3, "root_target_quat": 4, "pelvis_com": 3}
        out = {key: np.zeros((0, *np.atleast_1d(shape))) for key, shape in shapes.items()}
    first = start_frame * k
    return SimResult(
        fps=ref.fps, timestep=dt, times=(np.arange(len(out["qpos"])) + start_frame) / ref.fps, **out,
        actuator_force=forces[first:i + 1], foot_contact=contact[first:i + 1],
        step_times=np.arange(first, i + 1) * dt, fell=fell, fall_time_s=fall_time, fall_reason=reason,
        simulated_s=simulated, wall_s=wall, body_names=[model.body(b).name for b in range(model.nbody)],
        dof_names=[model.actuator(a).name for a in range(model.nu)])


def _mujoco_warning(message: str) -> None:
    """MuJoCo's warnings on stderr. Its own handler prints them on stdout and appends them to a
    ``MUJOCO_LOG.TXT`` it creates in the user's working directory."""
    print(f"warning: MuJoCo: {message}", file=sys.stderr)


def _record(rec: dict, data, target: dict, i: int, dof_adr: np.ndarray, pelvis: int) -> None:
    rec["qpos"].append(data.qpos.copy())
    rec["q"].append(data.qpos[dof_adr + 1].copy())
    rec["qref"].append(target["q"][i].copy())
    rec["xquat"].append(data.xquat.copy())
    rec["xpos"].append(data.xpos.copy())
    rec["root_target"].append(target["root_pos"][i].copy())
    rec["root_target_quat"].append(target["root_quat"][i].copy())
    rec["pelvis_com"].append(data.xipos[pelvis].copy())


def _fall_reason(data, pelvis: int, trunk: int, target: dict, i: int, target_height: float) -> str:
    """Why the ragdoll counts as fallen at this step ('' when it stands)."""
    height = data.xpos[pelvis][1]
    if height < FALL_HEIGHT_FRACTION * target_height:
        return f"pelvis at {height:.2f} m, below {FALL_HEIGHT_FRACTION:.0%} of its target height {target_height:.2f} m"
    for name, body in (("pelvis", pelvis), ("trunk", trunk)):
        up = data.xmat[body].reshape(3, 3)[:, 1]   # the segment's rest-pose up axis, in the world
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, up[1]))))
        if tilt > FALL_TILT_DEG:
            return f"{name} tilted {tilt:.0f}° from vertical (limit {FALL_TILT_DEG:.0f}°)"
    drift = float(np.linalg.norm((data.xpos[pelvis] - target["root_pos"][i])[[0, 2]]))
    if drift > FALL_DRIFT_M:
        return f"pelvis {drift:.2f} m away from its target horizontally (limit {FALL_DRIFT_M} m)"
    return ""
