"""Inverse-dynamics feed-forward of the reference motion, computed on the *reference* body.

The paper's PD controller only reacts to tracking error, so every stance phase starts with the
body sagging until the error builds the torque that carries it, and a swinging heel that lands
early is driven into the floor by a knee still extending towards its target (readme: Known
limits). The feed-forward adds, at every instant, the joint torques that would make the
reference body perform the reference motion exactly: MuJoCo's inverse dynamics (``mj_inverse``)
of the reference's joint angles, velocities and accelerations, with the ground reaction put on
the feet that are in contact in the reference (:func:`stimuli.motion.contact.foot_contacts`: the
shared contact model). The PD then only corrects the remainder.

Contacts: ``mj_inverse`` runs with MuJoCo's contacts disabled, which leaves a residual wrench on
the free root (``qfrc_inverse[:6]``: what an external agent would have to apply to the pelvis for
the motion to happen). On the reference that wrench is the ground's, acting through the stance
feet: per frame we solve ``J_rootᵀ w = residual`` for the wrench(es) ``w`` at the stance feet's
sole centre (one foot: exact, 6 unknowns; two feet: the least-norm split) and subtract ``Jᵀ w``
from the joint torques, so the stance leg carries the body from the first instant of stance. In
flight (no reference foot down) the residual is left to the root guide.

The torques belong to the reference body and are applied unchanged to every target body (the
paper's rule of one controller for all bodies; a heavier body gets the reference body's muscles'
torques and must make up the difference through its PD error): the same fixed-gain reading as the
paper's, not a per-body inverse dynamics.

Example
-------
>>> from stimuli.bodies import fit_body
>>> from stimuli.motion.generate import GaitParams, generate
>>> walk = generate(GaitParams(gait="walk", cadence_spm=112, speed_mps=1.2), height_m=1.60, fps=30, cycles=2)
>>> ff = reference_feedforward(walk, fit_body("F", 1.60, 28.1))
>>> ff.torque.shape[1], bool(abs(ff.sample([0.0, 0.5])).max() > 10)    # 30 DoF, N·m
(30, True)
"""

from __future__ import annotations

import collections
import dataclasses
import hashlib
import json

import numpy as np

# Finite-difference step (s) for the reference's accelerations (its splines are C², the root's
# orientation is a rotation-vector spline sampled through quaternions).
DIFF_STEP_S = 1e-3
# Accelerations are low-passed at this frequency (periodic, zero-phase) before inverse dynamics,
# as force-plate gait data are: a 30-fps capture's spline accelerations imply ground forces of
# ±200–460 N sideways and centres of pressure up to 1.5 m outside the feet (CMU 35_01 on the
# base body), which the feed-forward would otherwise turn into 400-N·m ankle torques.
ACCEL_CUTOFF_HZ = 6.0


@dataclasses.dataclass
class Feedforward:
    """Per-frame feed-forward joint torques (N·m, frame × DoF) over one period of the clip."""

    fps: float
    dof_names: list[str]
    torque: np.ndarray
    stance: np.ndarray          # frame × 2 (L, R): the reference contacts used
    root_residual: np.ndarray   # frame × 6: root wrench left unexplained (flight, non-physical capture)

    @property
    def period(self) -> float:
        return self.torque.shape[0] / self.fps

    def sample(self, t) -> np.ndarray:
        """Torques at times ``t`` (s; the clip repeats): linear between frames, periodic."""
        t = np.asarray(t, float)
        n = self.torque.shape[0]
        x = np.mod(t * self.fps, n)
        i0 = np.floor(x).astype(int) % n
        i1 = (i0 + 1) % n
        w = (x - np.floor(x))[..., None]
        return (1 - w) * self.torque[i0] + w * self.torque[i1]


def reference_states(ref, times: np.ndarray, h: float = DIFF_STEP_S) -> dict[str, np.ndarray]:
    """Generalised positions, velocities and accelerations of the reference at ``times``.

    Root linear terms in world coordinates, angular ones in the pelvis frame (MuJoCo's free joint).
    """
    from stimuli.motion import quat

    s0, sm, sp = ref.sample(times), ref.sample(times - h), ref.sample(times + h)
    local = [quat.rotate(quat.inv(s["root_quat"]), s["root_omega"]) for s in (sm, s0, sp)]
    return {
        "root_pos": s0["root_pos"], "root_quat": s0["root_quat"],
        "root_vel": s0["root_vel"], "root_acc": (sp["root_vel"] - sm["root_vel"]) / (2 * h),
        "root_omega_local": local[1], "root_alpha_local": (local[2] - local[0]) / (2 * h),
        "q": s0["q"], "qd": s0["qd"], "qdd": (sp["qd"] - sm["qd"]) / (2 * h),
    }


def periodic_lowpass(x: np.ndarray, fps: float, cutoff_hz: float = ACCEL_CUTOFF_HZ) -> np.ndarray:
    """Zero-phase low-pass of a periodic series (frames on axis 0): Fourier terms above ``cutoff_hz`` dropped.

    >>> t = np.arange(60) / 30.0
    >>> y = periodic_lowpass(np.sin(2 * np.pi * 1.0 * t) + np.sin(2 * np.pi * 10.0 * t), 30.0)
    >>> bool(np.allclose(y, np.sin(2 * np.pi * 1.0 * t)))
    True
    """
    spec = np.fft.rfft(x, axis=0)
    freq = np.fft.rfftfreq(x.shape[0], 1.0 / fps)
    spec[freq > cutoff_hz] = 0.0
    return np.fft.irfft(spec, n=x.shape[0], axis=0)


def inverse_torques(model, states: dict, stance: np.ndarray, foot_bodies: tuple[int, int],
                    foot_points: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Joint torques (frame × actuator) and root residual (frame × 6) by inverse dynamics.

    ``stance`` (frame × 2) says which feet take the root residual; ``foot_points`` (2 × 3, in each
    foot's body frame) is where their wrench acts (default: the foot body's centre of mass).
    """
    import mujoco

    data = mujoco.MjData(model)
    saved_flags = int(model.opt.disableflags)
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    saved_damping = model.dof_damping.copy()
    model.dof_damping[:] = 0.0
    act_dof = np.array([model.jnt_dofadr[model.actuator_trnid[a, 0]] for a in range(model.nu)])
    act_qpos = np.array([model.jnt_qposadr[model.actuator_trnid[a, 0]] for a in range(model.nu)])
    n = len(states["q"])
    torque, residual = np.zeros((n, model.nu)), np.zeros((n, 6))
    jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
    try:
        for i in range(n):
            data.qpos[:3] = states["root_pos"][i]
            data.qpos[3:7] = states["root_quat"][i]
            data.qpos[act_qpos] = states["q"][i]
            data.qvel[:3] = states["root_vel"][i]
            data.qvel[3:6] = states["root_omega_local"][i]
            data.qvel[act_dof] = states["qd"][i]
            data.qacc[:3] = states["root_acc"][i]
            data.qacc[3:6] = states["root_alpha_local"][i]
            data.qacc[act_dof] = states["qdd"][i]
            mujoco.mj_inverse(model, data)
            tau = data.qfrc_inverse.copy()
            feet = [f for f in range(2) if stance[i, f]]
            if feet:
                cols = []
                for f in feet:
                    body = foot_bodies[f]
                    point = (data.xipos[body] if foot_points is None
                             else data.xpos[body] + data.xmat[body].reshape(3, 3) @ foot_points[f])
                    mujoco.mj_jac(model, data, jacp, jacr, point, body)
                    cols.append(np.vstack([jacp, jacr]).T.copy())      # nv × 6: generalised force per unit wrench
                jt = np.hstack(cols)
                wrench = np.linalg.lstsq(jt[:6], tau[:6], rcond=None)[0]
                tau = tau - jt @ wrench
            residual[i] = tau[:6]
            torque[i] = tau[act_dof]
    finally:
        model.opt.disableflags = saved_flags
        model.dof_damping[:] = saved_damping
    return torque, residual


def reference_stance(motion, n_frames: int) -> np.ndarray:
    """Frame × 2 (left, right) foot contacts of the reference motion (the shared contact model)."""
    from stimuli.motion.contact import foot_contacts

    c = foot_contacts(motion)
    down = np.stack([c.down["l"], c.down["r"]], axis=1).astype(bool)
    if len(down) != n_frames:
        raise ValueError(f"contacts have {len(down)} frames, the reference {n_frames}")
    return down


def reference_feedforward(motion, reference_body, rate_hz: float | None = None, toes: bool = False,
                          toe_segment: bool = True) -> Feedforward:
    """Feed-forward torques of ``motion`` performed by the ragdoll of ``reference_body`` (with toe
    segments or not: ``toe_segment``, as the simulated ragdoll); with ``toes``, of the reference
    whose foot boxes stand on their ball where the motion stands on its toes
    (:func:`stimuli.physics.toes.stand_on_toes`), the one the controller then tracks.

    The result is kept for the process's next calls with the same motion and body (by content):
    every actor of a protocol step shares its NoCOM motion's, which took 0.4–0.5 s a jog clip to
    make again. It is shared, so it must not be changed.
    """
    key = (_content_key(motion, reference_body), rate_hz, bool(toes), bool(toe_segment))
    if key in _KEPT:
        _KEPT.move_to_end(key)
        return _KEPT[key]
    _KEPT[key] = _reference_feedforward(motion, reference_body, toes, toe_segment)
    if len(_KEPT) > KEPT_FEEDFORWARDS:
        _KEPT.popitem(last=False)
    return _KEPT[key]


# A protocol step has one NoCOM motion per sex × gait, each on its own reference body.
KEPT_FEEDFORWARDS = 4
_KEPT: collections.OrderedDict = collections.OrderedDict()


def _content_key(motion, body) -> str:
    """A digest of what the feed-forward depends on: the motion's skeleton and frames, and the
    reference body's mesh, rig and measured mass and height (from which its ragdoll is built)."""
    digest = hashlib.sha256()
    for array in (motion.rotations, motion.root_translation, motion.offsets, motion.parents,
                  body.vertices, body.rig.rest_heads, body.rig.rest_tails, body.rig.rest_rotations):
        digest.update(np.ascontiguousarray(array).tobytes())
    digest.update(json.dumps([motion.fps, motion.joint_names, motion.metadata, body.sex, body.rig.names,
                              body.anthropometry.mass_kg, body.anthropometry.height_m], sort_keys=True,
                             default=str).encode())
    return digest.hexdigest()


def _reference_feedforward(motion, reference_body, toes: bool, toe_segment: bool) -> Feedforward:
    """:func:`reference_feedforward`, computed."""
    from stimuli.physics.ragdoll import build_ragdoll, compile_model
    from stimuli.physics.reference import build_reference

    ref, ragdoll = build_reference(motion, reference_body,
                                   lambda axes: build_ragdoll(reference_body, None, axes, toes=toe_segment))
    ones = {d: 1.0 for d in ragdoll.dof_names}
    model = compile_model(ragdoll, 1e-3, ones, ones)
    stance = reference_stance(motion, ref.n_frames)
    if toes:
        from stimuli.physics.toes import stand_on_toes

        ref, _ = stand_on_toes(ref, model, stance)
    times = np.arange(ref.n_frames) / ref.fps
    feet = (model.body("foot.L").id, model.body("foot.R").id)
    sole = np.array([model.geom_pos[model.geom(f"foot.{s}").id] - [0, model.geom_size[model.geom(f"foot.{s}").id][1], 0]
                     for s in "LR"])
    states = reference_states(ref, times)
    for key in ("root_acc", "root_alpha_local", "qdd"):
        states[key] = periodic_lowpass(states[key], ref.fps)
    torque, residual = inverse_torques(model, states, stance, feet, sole)
    return Feedforward(float(ref.fps), list(ragdoll.dof_names), torque, stance, residual)
