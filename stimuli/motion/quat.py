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
    """Hamilton product a ⊗ b (apply b first, then a)."""
    aw, ax, ay, az = np.moveaxis(np.asarray(a, float), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, float), -1, 0)
    return np.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], axis=-1)


def inv(q: np.ndarray) -> np.ndarray:
    """Inverse of unit quaternions (the conjugate)."""
    return np.asarray(q, float) * np.array([1.0, -1.0, -1.0, -1.0])


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v`` (..., 3) by quaternions ``q`` (..., 4)."""
    q = np.asarray(q, float)
    v = np.asarray(v, float)
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * _cross(u, v)
    return v + w * t + _cross(u, t)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of (..., 3) arrays, written out: np.cross's axis handling dominated the foot
    clean-up's time on the small per-frame arrays it rotates."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


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
    """Flip signs along ``axis`` so consecutive quaternions lie in the same hemisphere."""
    q = np.array(q, float, copy=True)
    q = np.moveaxis(q, axis, 0)
    for t in range(1, q.shape[0]):
        flip = np.sum(q[t] * q[t - 1], axis=-1) < 0
        q[t][flip] *= -1
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
