"""The skeleton of a body (project frame) and posing it: forward kinematics and skinning.

Pose convention (BVH-like, the rest pose is all identities): ``local_rotations[t, j]`` rotates
bone j relative to its parent, in the world axes of the rest pose. Global rotations chain as
``G_j = G_parent · q_j`` (root: ``G_root = q_root``); posed heads as
``p_j = p_parent + G_parent · offset_j`` with ``p_root = root_translation[t]``; each bone's
skinning transform is ``[G_j | p_j − G_j · rest_head_j]``, applied by Anny's linear-blend skinning.

Examples
--------
>>> import numpy as np
>>> rig = Rig(names=["root", "a"], parents=np.array([-1, 0]), rest_heads=np.array([[0, 1.0, 0], [0, 2.0, 0]]),
...           rest_tails=np.array([[0, 2.0, 0], [0, 3.0, 0]]), rest_rotations=np.tile(np.eye(3), (2, 1, 1)))
>>> quarter = np.array([[[np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)], [1.0, 0, 0, 0]]])  # root: 90° about z
>>> np.round(rig.forward_kinematics(quarter, np.array([[0, 1.0, 0]]))[1][0], 6).tolist()
[[0.0, 1.0, 0.0], [-1.0, 1.0, 0.0]]
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np


@dataclasses.dataclass(frozen=True)
class Rig:
    """Bone names, parents (−1 for the root; parents precede children) and rest transforms (project frame)."""

    names: list[str]
    parents: np.ndarray
    rest_heads: np.ndarray
    rest_tails: np.ndarray
    rest_rotations: np.ndarray

    @property
    def n_bones(self) -> int:
        return len(self.names)

    @property
    def offsets(self) -> np.ndarray:
        """Head minus parent head (J, 3); the root's entry is its rest head."""
        out = self.rest_heads.copy()
        child = self.parents >= 0
        out[child] -= self.rest_heads[self.parents[child]]
        return out

    @property
    def rest_transforms(self) -> np.ndarray:
        """(J, 4, 4) world rest pose of each bone: [rest_rotations | rest_heads]."""
        out = np.tile(np.eye(4), (self.n_bones, 1, 1))
        out[:, :3, :3] = self.rest_rotations
        out[:, :3, 3] = self.rest_heads
        return out

    @functools.cached_property
    def depth(self) -> np.ndarray:
        """Number of ancestors of each bone (the root has 0)."""
        depth = np.zeros(self.n_bones, dtype=int)
        for j, p in enumerate(self.parents):
            depth[j] = 0 if p < 0 else depth[p] + 1
        return depth

    def index(self, name: str) -> int:
        """Position of a bone by name (ValueError naming the bone if unknown)."""
        try:
            return self.names.index(name)
        except ValueError:
            raise ValueError(f"unknown bone {name!r}; the rig has {self.n_bones} bones, e.g. {self.names[:6]}") from None

    def forward_kinematics(self, local_rotations, root_translation):
        """Global rotations (T, J, 3, 3) and posed heads (T, J, 3) for a batch of poses (numpy)."""
        rotations = as_matrices(local_rotations, self.n_bones)
        root = np.asarray(root_translation, dtype=float).reshape(-1, 3)
        if root.shape[0] != rotations.shape[0]:
            raise ValueError(f"root_translation has {root.shape[0]} frames, local_rotations {rotations.shape[0]}")
        glob = np.empty_like(rotations)
        heads = np.empty(rotations.shape[:2] + (3,))
        glob[:, 0] = rotations[:, 0]
        heads[:, 0] = root
        offsets = self.offsets
        # Level by level: every bone of a depth at once (parents are one level up).
        for level in range(1, int(self.depth.max()) + 1):
            bones = np.flatnonzero(self.depth == level)
            par = self.parents[bones]
            glob[:, bones] = glob[:, par] @ rotations[:, bones]
            heads[:, bones] = heads[:, par] + np.einsum("tbij,bj->tbi", glob[:, par], offsets[bones])
        return glob, heads

    def skinning_transforms(self, local_rotations, root_translation) -> np.ndarray:
        """(T, J, 4, 4) transforms mapping rest-pose points to the pose, per bone."""
        glob, heads = self.forward_kinematics(local_rotations, root_translation)
        out = np.zeros(glob.shape[:2] + (4, 4))
        out[..., :3, :3] = glob
        out[..., :3, 3] = heads - np.einsum("tbij,bj->tbi", glob, self.rest_heads)
        out[..., 3, 3] = 1.0
        return out


def as_matrices(local_rotations, n_bones: int) -> np.ndarray:
    """(T, J, 4) w-first quaternions or (T, J, 3, 3) matrices → (T, J, 3, 3) rotation matrices."""
    r = np.asarray(local_rotations, dtype=float)
    if r.ndim >= 2 and r.shape[-2:] == (3, 3):
        out = r.reshape(-1, n_bones, 3, 3) if r.size % (n_bones * 9) == 0 else None
    elif r.shape[-1] == 4:
        out = quaternions_to_matrices(r).reshape(-1, n_bones, 3, 3) if r.size % (n_bones * 4) == 0 else None
    else:
        out = None
    if out is None:
        raise ValueError(f"local_rotations must be (T, {n_bones}, 4) w-first quaternions or (T, {n_bones}, 3, 3) "
                         f"matrices, got shape {r.shape}")
    return out


def quaternions_to_matrices(q: np.ndarray) -> np.ndarray:
    """w-first quaternions (..., 4) → rotation matrices (..., 3, 3); normalises, zero → identity."""
    q = np.asarray(q, dtype=float)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    q = np.where(n > 1e-12, q / np.where(n > 1e-12, n, 1.0), np.array([1.0, 0.0, 0.0, 0.0]))
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)
