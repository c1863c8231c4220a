"""World-space swing-foot placement: the contact-aware part of the walking controller.

Joint-space PD tracking places a swinging foot relative to the *simulated* pelvis. When the pelvis
runs low or pitched (a few millimetres of contact penetration, a degree of lean), the swing foot
lands early, while the reference still swings it forward; the stiff leg then drags it along the
floor or pushes the body up, the body trails its target, the root spring tows it forward, the tow
pitches it further forward, and the next foot lands earlier still. On real captures this loop
settled at a 6–10° lean, a 7–9 cm trail and 3–20 % of each walk with no foot on the floor (the
reference: none); the generator's walks never entered it (docs/physics_log.md).

During the reference's swing (the shared contact model, :func:`stimuli.motion.contact.foot_contacts`)
the swing leg's joint targets are therefore solved by inverse kinematics on the simulated body so
that the foot follows the reference foot's *world* pose (the reference posed on the ragdoll,
low-passed at :data:`CUTOFF_HZ`, never below the floor), and blended back to the joint reference
over :data:`RAMP_S` after touchdown. Stance legs keep the joint reference, so the posture, the
feed-forward and the mass effects the COM method measures are untouched in stance.

It is used for walks only: on runs it raised flight above the reference's (CMU 35_17: 0.43 →
0.59) and made the Bandai dash drift off its target (readme).

Example
-------
>>> import numpy as np
>>> w = swing_weights(np.array([[1, 0], [1, 0], [0, 1], [0, 1], [0, 1], [1, 1]], bool), fps=30.0, ramp_s=0.05)
>>> w.round(2).tolist()
[[0.33, 1.0], [0.0, 1.0], [1.0, 0.67], [1.0, 0.33], [1.0, 0.0], [0.67, 0.0]]
"""

from __future__ import annotations

import dataclasses

import numpy as np

# After touchdown the placement fades out over this long (s): long enough that the joint reference
# takes over without a jolt, short enough that the stance leg carries the reference's posture.
RAMP_S = 0.1
# The reference foot path is low-passed at this frequency (Hz, periodic, zero-phase), as gait
# kinematics are (Winter): a 30-fps capture's heel bounces 2–3 cm between frames at heel strike.
CUTOFF_HZ = 6.0
# Simulation steps between two solves (the targets are held in between): 250 Hz at 4 kHz.
UPDATE_STEPS = 16
IK_ITERATIONS = 8
IK_DAMPING = 1e-4
IK_TOLERANCE_M = 2e-4
LEG_JOINTS = ("hip", "knee", "ankle")


def swing_weights(stance: np.ndarray, fps: float, ramp_s: float = RAMP_S) -> np.ndarray:
    """Frame × 2 weights of the placement: 1 in the reference's swing, fading linearly to 0 over
    ``ramp_s`` after each touchdown, 0 in the rest of stance (the clip repeats)."""
    stance = np.asarray(stance, bool)
    n = len(stance)
    out = (~stance).astype(float)
    ramp = max(1, int(round(ramp_s * fps)))
    for side in range(2):
        down = stance[:, side]
        for f in np.flatnonzero(down & ~np.roll(down, 1)):
            for j in range(ramp):
                k = (f + j) % n
                if not down[k]:
                    break
                out[k, side] = max(out[k, side], 1.0 - (j + 1) / (ramp + 1))
    return out


@dataclasses.dataclass
class SwingPlacement:
    """Per reference frame: placement weights and the reference feet's world poses (treadmill frame)."""

    fps: float
    weights: np.ndarray       # frame × 2
    foot_pos: np.ndarray      # frame × 2 × 3, without the belt's progression
    foot_quat: np.ndarray     # frame × 2 × 4 (w, x, y, z)
    root_z: np.ndarray        # frame: the root target's forward position without progression

    @property
    def n_frames(self) -> int:
        return len(self.weights)

    def weight(self, t: float, side: int) -> float:
        """The placement's weight at time ``t`` (linear), as :meth:`at` gives it."""
        x = t * self.fps
        f0 = int(np.floor(x))
        a = x - f0
        return (1 - a) * self.weights[f0 % self.n_frames, side] + a * self.weights[(f0 + 1) % self.n_frames, side]

    def at(self, t: float, side: int) -> tuple[float, np.ndarray, np.ndarray, float]:
        """(weight, foot position, foot quaternion, root forward offset) at time ``t`` (linear)."""
        x = t * self.fps
        f0 = int(np.floor(x))
        a = x - f0
        i0, i1 = f0 % self.n_frames, (f0 + 1) % self.n_frames
        q0, q1 = self.foot_quat[i0, side], self.foot_quat[i1, side]
        if q0 @ q1 < 0:
            q1 = -q1
        q = (1 - a) * q0 + a * q1
        return ((1 - a) * self.weights[i0, side] + a * self.weights[i1, side],
                (1 - a) * self.foot_pos[i0, side] + a * self.foot_pos[i1, side],
                q / np.linalg.norm(q), (1 - a) * self.root_z[i0] + a * self.root_z[i1])


def swing_placement(model, ref, stance: np.ndarray, lift: float) -> SwingPlacement:
    """The placement of ``ref`` (a :class:`stimuli.physics.reference.Reference`) on ``model``, the
    reference's feet ``lift`` metres up (the simulation's ground offset), never below the floor."""
    import mujoco

    from stimuli.physics.feedforward import periodic_lowpass
    from stimuli.physics.simulate import foot_geoms, lowest_corner

    data = mujoco.MjData(model)
    qadr = actuator_qpos(model)
    bodies = [model.body(f"foot.{s}").id for s in "LR"]
    geoms = foot_geoms(model)
    n = ref.n_frames
    pos, rot = np.zeros((n, 2, 3)), np.zeros((n, 2, 4))
    for f in range(n):
        data.qpos[:3] = ref.root_pos[f] + [0.0, lift, 0.0]
        data.qpos[3:7] = ref.root_quat[f]
        data.qpos[qadr] = ref.q[f]
        mujoco.mj_kinematics(model, data)
        for side in range(2):
            pos[f, side] = data.xpos[bodies[side]]
            rot[f, side] = data.xquat[bodies[side]]
            pos[f, side, 1] -= min(0.0, *(lowest_corner(model, data, g) for g in geoms[side]))
    pos = periodic_lowpass(pos.reshape(n, 6), ref.fps, CUTOFF_HZ).reshape(n, 2, 3)
    return SwingPlacement(float(ref.fps), swing_weights(stance, ref.fps), pos, rot, ref.root_pos[:, 2].copy())


def actuator_qpos(model) -> np.ndarray:
    """qpos address of each actuator's joint."""
    return np.array([model.jnt_qposadr[model.actuator_trnid[a, 0]] for a in range(model.nu)])


class SwingController:
    """Solves the swing legs' joint targets on the simulated body (see the module docstring)."""

    def __init__(self, model, placement: SwingPlacement):
        import mujoco

        self.model, self.placement = model, placement
        self.scratch = mujoco.MjData(model)
        self.qadr = actuator_qpos(model)
        self.legs, self.dofs = leg_dofs(model)
        self.bodies = [model.body(f"foot.{s}").id for s in "LR"]
        self.solvers = [LegSolver(model, self.scratch, self.qadr[leg], dofs, body)
                        for leg, dofs, body in zip(self.legs, self.dofs, self.bodies)]

    def targets(self, data, t: float, q_ref: np.ndarray, root_ref: np.ndarray) -> np.ndarray:
        """Joint targets at time ``t``: ``q_ref`` with each swinging leg blended towards its IK solution."""
        out = q_ref.copy()
        for side in range(2):
            if self.placement.weight(t, side) <= 0.0:   # stance: most of the time, and no pose to look up
                continue
            w, pos, rot, root_z = self.placement.at(t, side)
            goal = pos.copy()
            goal[2] += root_ref[2] - root_z          # the belt's progression since the clip's frame
            solved = self._solve(data, q_ref, side, goal, rot)
            out[self.legs[side]] = (1.0 - w) * q_ref[self.legs[side]] + w * solved
        return out

    def _solve(self, data, q_ref, side, goal, rot) -> np.ndarray:
        d, leg = self.scratch, self.legs[side]
        d.qpos[:] = data.qpos
        d.qpos[self.qadr[leg]] = q_ref[leg]
        self.solvers[side].solve(goal, rot)
        return d.qpos[self.qadr[leg]].copy()


def leg_dofs(model) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per side (L, R): the actuator indices of the leg's joints (:data:`LEG_JOINTS`) and their dof addresses."""
    names = [model.actuator(a).name for a in range(model.nu)]
    legs = [np.array([a for a, nm in enumerate(names) if nm.split(":")[0] in {f"{j}.{s}" for j in LEG_JOINTS}])
            for s in "LR"]
    return legs, [np.array([model.jnt_dofadr[model.actuator_trnid[a, 0]] for a in leg]) for leg in legs]


def solve_leg(model, data, qadr, dofs, body: int, goal: np.ndarray, rot: np.ndarray,
              iterations: int = IK_ITERATIONS, tolerance_m: float = IK_TOLERANCE_M) -> float:
    """Damped least-squares IK in place on ``data.qpos[qadr]`` (one leg) so that ``body`` reaches
    the world position ``goal`` and orientation ``rot`` (w, x, y, z); returns the last position error (m)."""
    return LegSolver(model, data, qadr, dofs, body).solve(goal, rot, iterations, tolerance_m)


class LegSolver:
    """:func:`solve_leg` for one leg of one MjData, with its buffers and views bound once.

    The simulation solves up to 500 times a second, and each solve takes 3–4 iterations; per
    iteration the buffer allocations and fancy indexing cost more than MuJoCo's kinematics, so
    they are done once here. The Jacobian buffer is Fortran-ordered like the fancy-indexed copy
    it replaces, so that the matrix products take the same BLAS paths and the solved joints are
    the same to the bit (with a C-ordered one, most IK steps differed in their last bits).
    """

    def __init__(self, model, data, qadr, dofs, body: int):
        import mujoco

        self.model, self.data, self.body = model, data, body
        self.kinematics, self.com_pos, self.jac_body = mujoco.mj_kinematics, mujoco.mj_comPos, mujoco.mj_jacBody
        self.sub_quat = mujoco.mju_subQuat
        self.qadr, self.dofs = np.asarray(qadr), np.asarray(dofs)
        self.jac_full = np.zeros((6, model.nv))
        self.jacp, self.jacr = self.jac_full[:3], self.jac_full[3:]
        self.jac = np.empty((6, len(self.dofs)), order="F")
        self.normal = np.empty((6, 6))
        self.err, self.err_rot = np.zeros(6), np.zeros(3)
        self.damping = IK_DAMPING * np.eye(6)
        self.xpos, self.xquat, self.xmat = data.xpos[body], data.xquat[body], data.xmat[body].reshape(3, 3)
        # Views where the leg's DoFs are consecutive (the ragdoll's are); fancy indexing otherwise.
        self.dof_cols, leg = _as_slice(self.dofs), _as_slice(self.qadr)
        self.leg_qpos = data.qpos[leg] if isinstance(leg, slice) else None

    def solve(self, goal: np.ndarray, rot: np.ndarray, iterations: int = IK_ITERATIONS,
              tolerance_m: float = IK_TOLERANCE_M) -> float:
        """Iterate from the pose in ``data.qpos``; returns the last position error (m)."""
        model, data, err, err_pos, jac, normal = self.model, self.data, self.err, self.err[:3], self.jac, self.normal
        error = 0.0
        for _ in range(iterations):
            self.kinematics(model, data)
            self.com_pos(model, data)
            np.subtract(goal, self.xpos, out=err_pos)
            self.sub_quat(self.err_rot, rot, self.xquat)
            np.matmul(self.xmat, self.err_rot, out=err[3:])
            self.jac_body(model, data, self.jacp, self.jacr, self.body)
            np.copyto(jac, self.jac_full[:, self.dof_cols])
            np.matmul(jac, jac.T, out=normal)
            normal += self.damping
            step = np.linalg.solve(normal, err)
            if self.leg_qpos is None:
                data.qpos[self.qadr] += jac.T @ step
            else:
                self.leg_qpos += jac.T @ step
            error = max(map(abs, err_pos.tolist()))
            if error < tolerance_m:
                break
        return error


def _as_slice(index: np.ndarray):
    """``index`` as a slice when it is a run of consecutive integers (a view, no copy), else itself.

    >>> _as_slice(np.array([3, 4, 5])), _as_slice(np.array([3, 5]))
    (slice(3, 6, None), array([3, 5]))
    """
    if len(index) and np.array_equal(index, np.arange(index[0], index[0] + len(index))):
        return slice(int(index[0]), int(index[0]) + len(index))
    return index
