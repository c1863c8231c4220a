"""The one place where Anny's coordinate frame becomes the project's.

Anny: metres, **z up**, the body faces **−y**, +x is the body's left, origin near the pelvis.
Project (DESIGN.md): metres, **y up**, the body faces **+z**, +x is the body's left, ground at y = 0.

The change of axes is a proper rotation (−90° about x), so it maps rotations by conjugation and
keeps handedness. The ground shift (feet on y = 0) is applied on top, per body.

Examples
--------
>>> import numpy as np
>>> points_to_project(np.array([[0.0, -1.0, 2.0]]), ground_shift=0.5)  # forward, 2 m up
array([[0. , 2.5, 1. ]])
"""

from __future__ import annotations

import numpy as np

# p_project = ANNY_TO_PROJECT @ p_anny: x stays, Anny's up (z) becomes y, Anny's forward (−y) becomes +z.
ANNY_TO_PROJECT = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def points_to_project(points: np.ndarray, ground_shift: float = 0.0) -> np.ndarray:
    """Anny-frame points (..., 3) → project frame, then lifted by ``ground_shift`` along y."""
    out = np.asarray(points, dtype=float) @ ANNY_TO_PROJECT.T
    out[..., 1] += ground_shift
    return out


def rotations_to_project(rotations: np.ndarray) -> np.ndarray:
    """Anny-frame rotation matrices (..., 3, 3) → the same rotations written in project axes."""
    return ANNY_TO_PROJECT @ np.asarray(rotations, dtype=float) @ ANNY_TO_PROJECT.T


def ground_shift_for(anny_points: np.ndarray) -> float:
    """The lift that puts the lowest point (Anny's minimum z) on the project's ground y = 0."""
    return -float(np.min(np.asarray(anny_points)[..., 2]))
