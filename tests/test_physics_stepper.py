"""The compiled simulation loop (:mod:`stimuli.physics.stepper`) against the Python loop it replaced,
step for step and to the bit, on a ragdoll walking on the floor (contacts on both feet)."""

from __future__ import annotations

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")


@pytest.fixture(scope="module")
def setup():
    from stimuli.bodies import fit_body
    from stimuli.motion.generate import GaitParams, generate
    from stimuli.physics.controller import Gains, set_root_damping
    from stimuli.physics.retarget import prepare
    from stimuli.physics.simulate import _mujoco_warning, foot_geoms, ground_offset, steps_per_frame

    mujoco.set_mju_user_warning(_mujoco_warning)   # as simulate() does: no MUJOCO_LOG.TXT in the working directory
    body = fit_body("F", 1.61, 24.42)
    walk = generate(GaitParams(gait="walk", cadence_spm=112, speed_mps=1.2), height_m=1.61, fps=30, cycles=2)
    ref, _, model, gains = prepare(walk, body)
    dt = 1.0 / (ref.fps * steps_per_frame(ref.fps))
    model.opt.timestep = dt
    set_root_damping(model, gains)
    n = 1200                                     # 0.3 s: both feet land and push off
    target = ref.sample(np.arange(n) * dt)
    target["root_pos"][:, 1] += ground_offset(model, ref)
    side_of_geom = np.full(model.ngeom, -1)
    for side, geoms in enumerate(foot_geoms(model)):
        side_of_geom[geoms] = side
    rng = np.random.default_rng(7)
    tau_ff = rng.normal(0.0, 5.0, (n, model.nu))
    offset = rng.normal(0.0, 0.02, model.nu)
    return model, gains, target, side_of_geom, tau_ff, offset


def _start(model, target):
    from stimuli.physics.simulate import _initial_state
    from stimuli.physics.swing import actuator_qpos

    data = mujoco.MjData(model)
    _initial_state(model, data, target, actuator_qpos(model) - 1)
    return data


def _python_steps(model, data, target, gains, tau_ff, offset, side_of_geom, n):
    """The loop as it was written in Python before it was compiled."""
    from stimuli.physics.controller import RootWrench

    wrench, pelvis = RootWrench(gains, target), model.body("pelvis").id
    forces, contact = np.zeros((n, model.nu)), np.zeros((n, 2), bool)
    for i in range(n):
        np.add(target["q"][i], offset, out=data.ctrl)
        model.actuator_biasprm[:, 0] = tau_ff[i]
        wrench.apply(data, i, pelvis)
        mujoco.mj_step(model, data)
        forces[i] = data.actuator_force
        if data.ncon:
            sides = side_of_geom[data.contact.geom[:data.ncon]].ravel().tolist()
            contact[i] = (0 in sides, 1 in sides)
    model.actuator_biasprm[:, 0] = 0.0
    return forces, contact


def test_compiled_steps_are_the_python_loop_to_the_bit(setup):
    from stimuli.physics.controller import RootWrench
    from stimuli.physics.stepper import Stepper

    model, gains, target, side_of_geom, tau_ff, offset = setup
    n = len(tau_ff)
    plain = _start(model, target)
    forces, contact = _python_steps(model, plain, target, gains, tau_ff, offset, side_of_geom, n)

    data = _start(model, target)
    got_forces, got_contact = np.zeros((n, model.nu)), np.zeros((n, 2), bool)
    stepper = Stepper(model, data, target["q"], tau_ff, RootWrench(gains, target), model.body("pelvis").id,
                      got_forces, got_contact, side_of_geom)
    lo = 0
    for hi in (1, 17, 300, 301, n):              # uneven runs, as between the loop's Python events
        assert stepper.run(lo, hi, offset) == (hi - 1, False)
        lo = hi
    model.actuator_biasprm[:, 0] = 0.0
    assert contact[:, 0].any() and contact[:, 1].any() and not contact.all()
    assert np.array_equal(got_contact, contact)
    assert np.array_equal(got_forces, forces)
    for field in ("qpos", "qvel", "qacc_warmstart", "qfrc_applied", "ctrl", "xpos"):
        assert np.array_equal(getattr(data, field), getattr(plain, field)), field


def test_contact_count_and_geoms_are_read_where_mujoco_keeps_them(setup):
    from stimuli.physics.controller import RootWrench
    from stimuli.physics.stepper import Stepper

    model, gains, target, side_of_geom, _, _ = setup
    data = _start(model, target)
    stepper = Stepper(model, data, target["q"], None, RootWrench(gains, target), model.body("pelvis").id,
                      np.zeros((len(target["q"]), model.nu)), np.zeros((len(target["q"]), 2), bool), side_of_geom)
    seen = set()
    for i in range(0, 600, 50):
        stepper.run(i, i + 50)
        assert stepper._ncon[0] == data.ncon
        seen.add(data.ncon)
        geoms = stepper._args[-3]
        assert np.array_equal(geoms[:data.ncon], data.contact.geom[:data.ncon])
    assert len(seen) > 1                          # the count changed under the loop's eyes


def test_a_diverging_step_is_reported_and_not_recorded(setup):
    from stimuli.physics.controller import RootWrench
    from stimuli.physics.stepper import Stepper

    model, gains, target, side_of_geom, _, _ = setup
    data = _start(model, target)
    n = 50
    wild = np.full((n, model.nu), 1e30)          # a feed-forward no body survives
    forces = np.full((n, model.nu), -1.0)
    stepper = Stepper(model, data, target["q"], wild, RootWrench(gains, target), model.body("pelvis").id,
                      forces, np.zeros((n, 2), bool), side_of_geom)
    try:
        last, diverged = stepper.run(0, n)
    finally:
        model.actuator_biasprm[:, 0] = 0.0
    assert diverged and last == 0
    assert data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number == 1
    assert (forces == -1.0).all()
