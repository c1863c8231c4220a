"""Quaternion helpers on numpy arrays, w-first (the Motion ``.npz`` convention).

Everything is vectorised over leading axes. scipy's ``Rotation`` (x, y, z, w order) does the
Euler and axis-angle conversions; the hot paths (product, rotate a vector) are written here because
they run per frame and per joint inside forward kinematics.

Examples
--------
>>> import numpy as np
>>> q = from_axis_angle(np.array([0.0, 1.0, 0.0]) * np.pi / 2)
>>> np.round(rotate(q, np.array([1.0, 0.0, 0.0])), 6)
array([ 0.,  0., -1.])
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def to_scipy(q: np.ndarray) -> Rotation:
    """scipy Rotation from w-first quaternions of any leading shape (flattened)."""
    q = np.asarray(q, dtype=float).reshape(-1, 4)
    return Rotation.from_quat(q[:, [1, 2, 3, 0]])


def from_scipy(r: Rotation, shape: tuple = ()) -> np.ndarray:
    """w-first quaternions from a scipy Rotation, reshaped to ``shape + (4,)``."""
    q = np.atleast_2d(r.as_quat())[:, [3, 0, 1, 2]]
    return q.reshape(tuple(shape) + (4,))


def normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternions (a zero quaternion becomes the identity)."""
    q = np.asarray(q, dtype=float)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    out = np.where(n > 1e-12, q / np.where(n > 1e-12, n, 1.0), IDENTITY)
    return out


def mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a ⊗ b (apply b first, then a).

    Written into one preallocated array (the components' products as before): ``np.moveaxis`` and
    ``np.stack`` took half of its time on the per-joint arrays forward kinematics passes it.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = aw * bw - ax * bx - ay * by - az * bz
    out[..., 1] = aw * bx + ax * bw + ay * bz - az * by
    out[..., 2] = aw * by - ax * bz + ay * bw + az * bx
    out[..., 3] = aw * bz + ax * by - ay * bx + az * bw
    return out


def inv(q: np.ndarray) -> np.ndarray:
    """Inverse of unit quaternions (the conjugate)."""
    return np.asarray(q, float) * np.array([1.0, -1.0, -1.0, -1.0])


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v`` (..., 3) by quaternions ``q`` (..., 4).

    ``v + w t + u × t`` with ``t = 2 u × v``, written out per component into one array (forward
    kinematics calls it per joint on small arrays, where stacking the cross products cost more
    than the arithmetic).
    """
    q = np.asarray(q, float)
    v = np.asarray(v, float)
    w, u0, u1, u2 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    v0, v1, v2 = v[..., 0], v[..., 1], v[..., 2]
    t0 = 2.0 * (u1 * v2 - u2 * v1)
    t1 = 2.0 * (u2 * v0 - u0 * v2)
    t2 = 2.0 * (u0 * v1 - u1 * v0)
    out = np.empty(np.broadcast_shapes(q.shape[:-1] + (3,), v.shape))
    out[..., 0] = v0 + w * t0 + (u1 * t2 - u2 * t1)
    out[..., 1] = v1 + w * t1 + (u2 * t0 - u0 * t2)
    out[..., 2] = v2 + w * t2 + (u0 * t1 - u1 * t0)
    return out


def from_axis_angle(rotvec: np.ndarray) -> np.ndarray:
    """Quaternions from rotation vectors (axis × angle in radians), shape (..., 3)."""
    rotvec = np.asarray(rotvec, float)
    return from_scipy(Rotation.from_rotvec(rotvec.reshape(-1, 3)), rotvec.shape[:-1])


def to_axis_angle(q: np.ndarray) -> np.ndarray:
    """Rotation vectors from quaternions, shape (..., 3)."""
    q = np.asarray(q, float)
    return to_scipy(q).as_rotvec().reshape(q.shape[:-1] + (3,))


def from_euler(angles: np.ndarray, order: str, degrees: bool = True) -> np.ndarray:
    """Quaternions from intrinsic Euler angles as BVH writes them.

    ``order`` is the channel order, e.g. ``"ZYX"``: the rotation is R = Rz · Ry · Rx with each
    angle about the joint's *rotating* axes (BVH channels are intrinsic, applied left to right).
    """
    angles = np.asarray(angles, float)
    r = Rotation.from_euler(order.upper(), angles.reshape(-1, 3), degrees=degrees)
    return from_scipy(r, angles.shape[:-1])


def to_euler(q: np.ndarray, order: str, degrees: bool = True) -> np.ndarray:
    """Intrinsic Euler angles (inverse of :func:`from_euler`)."""
    q = np.asarray(q, float)
    return to_scipy(q).as_euler(order.upper(), degrees=degrees).reshape(q.shape[:-1] + (3,))


def between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Smallest rotation taking direction ``u`` to direction ``v`` (both (..., 3))."""
    u = np.asarray(u, float)
    v = np.asarray(v, float)
    u = u / np.linalg.norm(u, axis=-1, keepdims=True)
    v = v / np.linalg.norm(v, axis=-1, keepdims=True)
    d = np.sum(u * v, axis=-1, keepdims=True)
    c = np.cross(u, v)
    q = np.concatenate([1.0 + d, c], axis=-1)
    # Opposite vectors: rotate by pi about any axis perpendicular to u.
    opposite = (1.0 + d[..., 0]) < 1e-9
    if np.any(opposite):
        alt = np.cross(u, np.array([1.0, 0.0, 0.0]))
        small = np.linalg.norm(alt, axis=-1) < 1e-6
        alt[small] = np.cross(u[small] if u.ndim > 1 else u, np.array([0.0, 1.0, 0.0]))
        q[opposite] = np.concatenate([np.zeros(alt.shape[:-1] + (1,)), alt], axis=-1)[opposite]
    return normalize(q)


def unroll(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip signs along ``axis`` so consecutive quaternions lie in the same hemisphere.

    Frame t is flipped when its dot product with frame t−1 *as already flipped* is negative. A
    flip negates a dot product exactly, so frame t's sign is the parity of the negative dot
    products of the unflipped neighbours since the last zero (or NaN) one, after which a frame
    keeps its sign: computed for all frames at once (the frame loop was a share of every reference's set-up).

    >>> unroll(np.array([[1.0, 0, 0, 0], [-1.0, 0, 0, 0], [1.0, 0, 0, 0]]))[:, 0].tolist()
    [1.0, 1.0, 1.0]
    """
    q = np.moveaxis(np.array(q, float, copy=True), axis, 0)
    if q.shape[0] > 1:
        dots = np.sum(q[1:] * q[:-1], axis=-1)
        negative = dots < 0
        kept = ~(negative | (dots > 0))                       # zero or NaN: this frame is never flipped
        count = np.cumsum(negative, axis=0)
        frame = np.arange(len(dots)).reshape((-1,) + (1,) * (dots.ndim - 1))
        last_kept = np.maximum.accumulate(np.where(kept, frame, -1), axis=0)
        since = count - np.where(last_kept >= 0, np.take_along_axis(count, np.maximum(last_kept, 0), axis=0), 0)
        q[1:][since % 2 == 1] *= -1
    return np.moveaxis(q, 0, axis)


def slerp(a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Spherical interpolation between ``a`` and ``b`` at fraction ``t`` (broadcast)."""
    a = normalize(a)
    b = normalize(b)
    t = np.asarray(t, float)[..., None]
    d = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(d < 0, -b, b)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    s = np.sin(theta)
    near = s < 1e-6
    wa = np.where(near, 1.0 - t, np.sin((1.0 - t) * theta) / np.where(near, 1.0, s))
    wb = np.where(near, t, np.sin(t * theta) / np.where(near, 1.0, s))
    return normalize(wa * a + wb * b)


def mean(q: np.ndarray, weights: np.ndarray | None = None, axis: int = 0) -> np.ndarray:
    """Weighted quaternion mean along ``axis`` (Markley et al. 2007: top eigenvector of Σ w q qᵀ).

    Sign-invariant, unlike averaging Euler angles or raw components.
    """
    q = np.moveaxis(np.asarray(q, float), axis, 0)
    n = q.shape[0]
    w = np.ones(n) if weights is None else np.asarray(weights, float)
    m = np.einsum("n,n...i,n...j->...ij", w, q, q)
    _, vecs = np.linalg.eigh(m)
    out = vecs[..., :, -1]
    # Keep the hemisphere of the first sample for continuity over time.
    sign = np.sign(np.sum(out * q[0], axis=-1, keepdims=True))
    return normalize(out * np.where(sign == 0, 1.0, sign))


def angle(q: np.ndarray) -> np.ndarray:
    """Rotation angle in radians (0…π) of each quaternion."""
    w = np.abs(np.clip(normalize(q)[..., 0], -1.0, 1.0))
    return 2.0 * np.arccos(np.clip(w, 0.0, 1.0))
