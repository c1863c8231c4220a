"""Balance: shift the pelvis horizontally so the zero-moment point stays over the feet.

A kinematic walk that keeps the pelvis still over a treadmill has its centre of mass (CoM)
nearly fixed, so its zero-moment point (ZMP) stays between the feet instead of following the
stance foot: it looks dynamically unstable (SPEC §1.4). With the cart-table (linear inverted
pendulum) model the ZMP is p = x − (h/g)·ẍ for CoM x at height h. For a looped clip this is
solved exactly in the frequency domain: X(ω) = P(ω) / (1 + h·ω²/g), where p is the wanted ZMP
— the centre of the feet in contact (interpolated through flight phases). The difference between
that CoM path and the present one moves the root; the foot clean-up then re-plants the feet.
This produces the familiar lateral sway towards the stance foot and the fore-aft surge.
"""

from __future__ import annotations

import numpy as np

from stimuli.motion.footfix import sole_points, sole_positions
from stimuli.motion.metrics import GRAVITY, segment_com
from stimuli.motion.motion import Motion


def support_centre(motion: Motion, contacts: dict[str, np.ndarray], floor_y: float | None = None,
                   points: dict | None = None) -> np.ndarray:
    """Per frame, the horizontal centre (T×2: x, z) of the sole points of the feet in contact;
    frames without contact are interpolated (periodically) from their neighbours."""
    grot, gpos = motion.global_transforms()
    pts = sole_points(motion, floor_y) if points is None else points
    acc = np.zeros((motion.n_frames, 2))
    cnt = np.zeros(motion.n_frames)
    for s in ("l", "r"):
        sole = sole_positions(grot, gpos, pts[s])[:, :, [0, 2]].mean(axis=1)
        acc += sole * contacts[s][:, None]
        cnt += contacts[s]
    have = cnt > 0
    centre = np.zeros_like(acc)
    centre[have] = acc[have] / cnt[have, None]
    if not have.all():
        idx = np.flatnonzero(have)
        t = np.arange(motion.n_frames)
        for k in range(2):
            centre[:, k] = np.interp(t, idx, centre[idx, k], period=motion.n_frames)
    return centre


def balanced_com(zmp: np.ndarray, height: float, fps: float) -> np.ndarray:
    """Periodic CoM path (T×k) whose cart-table ZMP is ``zmp``: X = P / (1 + h ω²/g)."""
    n = zmp.shape[0]
    omega = 2 * np.pi * np.fft.rfftfreq(n, d=1.0 / fps)
    gain = 1.0 / (1.0 + height * omega**2 / GRAVITY)
    return np.fft.irfft(np.fft.rfft(zmp, axis=0) * gain[:, None], n=n, axis=0)


def balance(motion: Motion, contacts: dict[str, np.ndarray], floor_y: float | None = None,
            strength: float = 1.0, points: dict | None = None) -> Motion:
    """Shift the root horizontally so the CoM follows the balanced path (looped clips only)."""
    pos = motion.positions()
    com = segment_com(motion, pos)
    want = balanced_com(support_centre(motion, contacts, floor_y, points), float(com[:, 1].mean()), motion.fps)
    shift = (want - com[:, [0, 2]]) * strength
    root = motion.root_translation.copy()
    root[:, 0] += shift[:, 0]
    root[:, 2] += shift[:, 1]
    out = motion.replace(root_translation=root)
    out.metadata["balanced"] = True
    return out
