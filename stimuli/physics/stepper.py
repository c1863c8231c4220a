"""The simulation's inner loop, compiled: the steps between two Python-side events in one call.

A 4-s walk is 17 000 MuJoCo steps, and around each ``mj_step`` (40–55 µs here) the Python loop
spent another 25–45 µs setting the targets, the feed-forward and the root wrench and reading the
forces and the foot contacts back: more than the physics itself. :meth:`Stepper.run` does that
work in machine code (numba), calling MuJoCo's own C functions (``mj_step`` and the same ``mju_*``
helpers :class:`stimuli.physics.controller.RootWrench` calls), so every number is the same to the
bit as the Python loop's; ``tests/test_physics_stepper.py`` checks it against that loop.

The loop reads three things that the Python bindings give only as copies: the contact count, the
contacts' geoms and (for the step's divergence check) the warning counters. Their places in
MuJoCo's ``mjData`` (which differ between MuJoCo versions) are found once per process on a probe
model and checked there against the bindings' own values (:func:`layout`); :class:`Stepper`
checks the contact count again at every return to Python, so a MuJoCo whose layout differs fails
loudly instead of recording wrong contacts.
MuJoCo's warnings reach the Python handler as before; a MuJoCo *error* inside a compiled run (none
of the ragdolls raises one: a full arena, say, is a warning) would end the process, not raise.

Example:
    >>> from stimuli.physics.stepper import layout
    >>> layout().contact_stride > 0
    True
"""

from __future__ import annotations

import ctypes
import dataclasses
import functools
from pathlib import Path

import numpy as np
from numba import njit, types
from numba.core.types import ExternalFunction


def _load_library() -> None:
    """Make the MuJoCo library the Python bindings loaded (the same copy, so the same global state,
    such as the warning handler) visible to the compiled code, which calls its functions by name."""
    import llvmlite.binding
    import mujoco

    folder = Path(mujoco.__file__).parent
    found = [path for pattern in ("libmujoco.so*", "libmujoco*.dylib", "mujoco.dll") for path in sorted(folder.glob(pattern))]
    if not found:
        raise RuntimeError(f"no MuJoCo library next to {mujoco.__file__}")
    llvmlite.binding.load_library_permanently(str(found[0]))


_load_library()
# MuJoCo's C functions; their pointer arguments are passed as addresses (uint64). Named, not bound
# to an address, so the compiled loop can be cached on disk.
_ADDRESS = types.uint64
_mj_step = ExternalFunction("mj_step", types.void(_ADDRESS, _ADDRESS))
_sub3 = ExternalFunction("mju_sub3", types.void(_ADDRESS, _ADDRESS, _ADDRESS))
_scl3 = ExternalFunction("mju_scl3", types.void(_ADDRESS, _ADDRESS, types.float64))
_add_to_scl3 = ExternalFunction("mju_addToScl3", types.void(_ADDRESS, _ADDRESS, types.float64))
_neg_quat = ExternalFunction("mju_negQuat", types.void(_ADDRESS, _ADDRESS))
_mul_quat = ExternalFunction("mju_mulQuat", types.void(_ADDRESS, _ADDRESS, _ADDRESS))
_quat2vel = ExternalFunction("mju_quat2Vel", types.void(_ADDRESS, _ADDRESS, types.float64))
_mul_mat_t_vec3 = ExternalFunction("mju_mulMatTVec3", types.void(_ADDRESS, _ADDRESS, _ADDRESS))


@dataclasses.dataclass(frozen=True)
class Layout:
    """Where the loop finds what the bindings only copy out of an ``mjData`` (bytes)."""

    ncon_offset: int        # ``ncon``, from the ``mjData`` address
    arena_offset: int       # the ``arena`` pointer, from the ``mjData`` address
    contact_stride: int     # ``sizeof(mjContact)``
    geom_offset: int        # ``mjContact.geom``, from the contact's start


# The probe: a box and a ball over a plane. Posed at these heights (box, ball) they touch the floor
# with 5, 1, 4 and 0 contacts, an order no other counter in mjData follows (its maximum-use
# statistics keep 5, its constraint rows are 4 per contact).
_PROBE = ('<mujoco><worldbody><geom type="plane" size="2 2 .1"/>'
          '<body><freejoint/><geom type="box" size=".1 .1 .1"/></body>'
          '<body><freejoint/><geom type="sphere" size=".1"/></body></worldbody></mujoco>')
_PROBE_HEIGHTS = ((0.09, 0.09), (1.0, 0.09), (0.09, 1.0), (1.0, 1.0))


@functools.cache
def layout() -> Layout:
    """This MuJoCo's :class:`Layout`, found and checked on a probe model.

    ``arena`` is the pointer field before ``qpos`` (``mjdata.h``), found as the field holding the
    bindings' ``qpos`` address followed by their ``qvel``'s; ``ncon`` is the one int before it that
    equals the bindings' contact count in four poses of the probe (its place differs between
    MuJoCo versions); contacts start at the arena (``mj_clearEfc``), which the bindings' own contact
    array is checked against.
    """
    import mujoco

    model = mujoco.MjModel.from_xml_string(_PROBE)
    data = mujoco.MjData(model)
    base = data._address
    arena_offset = _pointer_pair(base, _address(data.qpos), _address(data.qvel)) - 8
    header = _view(base, np.int32, arena_offset // 4)     # the counters and statistics before the pointers
    candidates, counts = None, []
    for box, ball in _PROBE_HEIGHTS:
        data.qpos[:] = [0, 0, box, 1, 0, 0, 0, 0.5, 0, ball, 1, 0, 0, 0]
        mujoco.mj_forward(model, data)
        counts.append(data.ncon)
        matches = set(np.flatnonzero(header == data.ncon).tolist())
        candidates = matches if candidates is None else candidates & matches
        if data.ncon == 5:
            geoms = data.contact.geom
            arena = ctypes.c_uint64.from_address(base + arena_offset).value
            contact_stride, geom_offset = int(geoms.strides[0]), _address(geoms) - arena
    if counts != [5, 1, 4, 0] or len(candidates) != 1 or not 0 <= geom_offset < contact_stride:
        raise RuntimeError(f"MuJoCo {mujoco.__version__}: its mjData is not laid out as the compiled loop reads it")
    return Layout(4 * candidates.pop(), arena_offset, contact_stride, geom_offset)


def _pointer_pair(base: int, first: int, second: int, limit: int = 1 << 22) -> int:
    """Offset from ``base`` of the first 8-byte field holding ``first`` followed by ``second``."""
    chunk = 128
    for start in range(0, limit, 8 * (chunk - 1)):
        words = _view(base + start, np.uint64, chunk)
        hits = np.flatnonzero((words[:-1] == first) & (words[1:] == second))
        if len(hits):
            return start + 8 * int(hits[0])
    raise RuntimeError("the bindings' qpos pointer is not in their mjData")


def _address(array: np.ndarray) -> int:
    return int(array.__array_interface__["data"][0])


def _view(address: int, dtype, count: int) -> np.ndarray:
    """``count`` items of ``dtype`` at ``address`` (memory owned by MuJoCo), without a copy."""
    return np.frombuffer((ctypes.c_byte * (count * np.dtype(dtype).itemsize)).from_address(address), dtype)


class Stepper:
    """One simulation's compiled steps: :meth:`run` advances from step ``lo`` to ``hi``.

    The arrays are those of :func:`stimuli.physics.simulate.simulate`: per-step joint targets
    ``q_target`` (steps × nu), feed-forward ``tau_ff`` (steps × nu, or None), the root wrench's
    targets and gains (a :class:`stimuli.physics.controller.RootWrench`), and the outputs it fills
    at each step, ``forces`` (steps × nu) and ``contact`` (steps × 2, by ``side_of_geom``).
    """

    def __init__(self, model, data, q_target, tau_ff, root_wrench, pelvis: int, forces, contact, side_of_geom):
        import mujoco

        where = layout()
        arena = ctypes.c_uint64.from_address(data._address + where.arena_offset).value
        capacity = (model.narena - where.geom_offset - 8) // where.contact_stride
        words = where.contact_stride // 4
        first = where.geom_offset // 4
        geoms = _view(arena, np.int32, capacity * words).reshape(capacity, words)[:, first:first + 2]   # each contact's geom pair
        self._ncon = _view(data._address + where.ncon_offset, np.int32, 1)
        self._model, self._data = model, data   # the loop holds their raw addresses: keep them alive
        no_ff = np.zeros((0, model.nu))
        w = root_wrench
        self._args = (
            model._address, data._address, data.ctrl, np.ascontiguousarray(q_target),
            no_ff if tau_ff is None else np.ascontiguousarray(tau_ff), model.actuator_biasprm,
            np.ascontiguousarray(w.pos), np.ascontiguousarray(w.vel), np.ascontiguousarray(w.quat),
            np.ascontiguousarray(w.omega), np.array([w.k_pf, w.k_df, w.k_pr, w.k_dr], float),
            np.zeros(4), np.zeros(4), np.zeros(3), np.zeros(3),
            data.qpos, data.qfrc_applied, data.xmat[pelvis], data.actuator_force, forces, contact,
            np.ascontiguousarray(side_of_geom, dtype=np.int64), self._ncon, geoms,
            data.warning.number, int(mujoco.mjtWarning.mjWARN_BADQACC))
        self.run(0, 0)   # compiles the loop, or loads it from numba's cache, before any timing

    def run(self, lo: int, hi: int, offset: np.ndarray | None = None) -> tuple[int, bool]:
        """Steps ``lo`` … ``hi − 1`` (joint targets ``q_target[i] + offset`` when given).

        Returns the step it stopped after and whether that step diverged (MuJoCo's bad-acceleration
        warning: then that step's forces and contacts are not recorded).
        """
        has_offset = offset is not None
        last, diverged = _run(lo, hi, offset if has_offset else np.zeros(0), has_offset, *self._args)
        if self._ncon[0] != self._data.ncon:
            raise RuntimeError("the compiled loop read a contact count MuJoCo does not report")
        return last, diverged


@njit(cache=True)
def _run(lo, hi, offset, has_offset, model, data, ctrl, q_target, tau_ff, bias, pos, vel, quat, omega,
         k, inv, err_q, err, torque, qpos, qfrc, xmat, actuator_force, forces, contact, side_of_geom,
         ncon, geoms, warnings, bad_qacc):
    nu = ctrl.shape[0]
    has_ff = tau_ff.shape[0] > 0
    for i in range(lo, hi):
        for j in range(nu):
            ctrl[j] = q_target[i, j] + offset[j] if has_offset else q_target[i, j]
        if has_ff:
            for j in range(nu):
                bias[j, 0] = tau_ff[i, j]
        _root_wrench(pos[i], vel[i], quat[i], omega[i], k, inv, err_q, err, torque, qpos, qfrc, xmat)
        _mj_step(model, data)
        if warnings[bad_qacc] != 0:
            return i, True
        forces[i, :] = actuator_force
        for c in range(ncon[0]):
            for g in range(2):
                side = side_of_geom[geoms[c, g]]
                if side >= 0:
                    contact[i, side] = True
    return hi - 1, False


@njit(cache=True)
def _root_wrench(pos, vel, quat, omega, k, inv, err_q, err, torque, qpos, qfrc, xmat):
    """:meth:`stimuli.physics.controller.RootWrench.apply`, call for call."""
    force, q = qfrc.ctypes.data, qpos.ctypes.data
    _sub3(force, pos.ctypes.data, q)
    _scl3(force, force, k[0])
    _add_to_scl3(force, vel.ctypes.data, k[1])
    _neg_quat(inv.ctypes.data, q + 24)
    _mul_quat(err_q.ctypes.data, quat.ctypes.data, inv.ctypes.data)
    _quat2vel(err.ctypes.data, err_q.ctypes.data, 1.0)
    _scl3(torque.ctypes.data, err.ctypes.data, k[2])
    _add_to_scl3(torque.ctypes.data, omega.ctypes.data, k[3])
    _mul_mat_t_vec3(force + 24, xmat.ctypes.data, torque.ctypes.data)
