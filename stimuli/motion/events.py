"""Gait events from foot kinematics.

Heel strike and toe off follow Zeni et al. (2008, Gait & Posture 27:710): heel strike at the
maxima of the ankle's forward distance from the pelvis, toe off at the minima of the toe's. This
works overground and on a treadmill alike because it only uses positions relative to the pelvis.
Ground contact (for the metrics and the foot clean-up) uses height and speed relative to the
ground/belt.

Examples
--------
>>> import numpy as np
>>> t = np.arange(200) / 100.0
>>> x = np.sin(2 * np.pi * t)            # one foot swinging fore and aft at 1 Hz
>>> local_maxima(x, min_gap=50).tolist()
[25, 125]
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.signal import find_peaks

from stimuli.errors import StimuliError
from stimuli.motion.skeleton import role_indices

UP = np.array([0.0, 1.0, 0.0])


def local_maxima(x: np.ndarray, min_gap: int) -> np.ndarray:
    """Indices of prominent local maxima at least ``min_gap`` frames apart."""
    prominence = 0.25 * float(np.ptp(x)) if np.ptp(x) > 0 else None
    peaks, _ = find_peaks(x, distance=max(int(min_gap), 1), prominence=prominence)
    return peaks


def facing(positions: np.ndarray, roles: dict[str, int]) -> np.ndarray:
    """Per-frame horizontal unit forward direction from the hips (left hip − right hip) × up."""
    left = positions[:, roles["l_hip"]] - positions[:, roles["r_hip"]]
    fwd = np.cross(left, UP)
    fwd[:, 1] = 0.0
    n = np.linalg.norm(fwd, axis=1, keepdims=True)
    return fwd / np.where(n > 1e-9, n, 1.0)


def gait_events(motion, positions: np.ndarray | None = None, cadence_hint_spm: float | None = None) -> dict:
    """Heel strikes and toe offs per foot (frame indices) and the mean forward direction.

    Returns ``{"l_hs", "r_hs", "l_to", "r_to", "forward"}``; raises StimuliError when fewer than
    two heel strikes of one foot are found (the clip is shorter than one gait cycle).
    """
    roles = role_indices(motion)
    pos = motion.positions() if positions is None else positions
    fwd = facing(pos, roles).mean(axis=0)
    fwd /= max(np.linalg.norm(fwd), 1e-9)
    pelvis = pos[:, roles["pelvis"]]
    # Shortest plausible step: 220 steps/min is a sprint; a cycle is two steps.
    min_gap = int(motion.fps * 60.0 / 220.0 * 2 * 0.6) if cadence_hint_spm is None else \
        int(motion.fps * 120.0 / cadence_hint_spm * 0.6)
    out: dict = {"forward": fwd}
    for side in ("l", "r"):
        heel = pos[:, roles[f"{side}_ankle"]]
        toe = pos[:, roles.get(f"{side}_toe", roles[f"{side}_ankle"])]
        heel_fwd = (heel - pelvis) @ fwd
        toe_fwd = (toe - pelvis) @ fwd
        out[f"{side}_hs"] = local_maxima(heel_fwd, min_gap)
        out[f"{side}_to"] = local_maxima(-toe_fwd, min_gap)
    return out


def cycle_starts(motion, side: str = "l", positions: np.ndarray | None = None) -> np.ndarray:
    """Heel strikes of one foot (cycle boundaries); StimuliError if the clip lacks a whole cycle."""
    hs = gait_events(motion, positions)[f"{side}_hs"]
    if len(hs) < 2:
        raise StimuliError(f"{motion.metadata.get('source', 'motion')}: clip of {motion.duration_s:.2f} s "
                           f"holds fewer than one whole gait cycle ({len(hs)} heel strike(s) found)")
    return hs


def foot_points(motion, positions: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Per foot, the T×2×3 positions of its ankle and toe joints (the foot's contact points)."""
    roles = role_indices(motion)
    pos = motion.positions() if positions is None else positions
    return {s: pos[:, [roles[f"{s}_ankle"], roles.get(f"{s}_toe", roles[f"{s}_ankle"])]] for s in ("l", "r")}


def contacts(points: np.ndarray, fps: float, belt_velocity: np.ndarray | None = None,
             height_tol: float = 0.05, speed_tol: float = 0.3) -> np.ndarray:
    """Ground contact per frame for one foot from its contact points (T×P×3).

    A point touches when it is within ``height_tol`` of its own lowest height in the clip and moves
    slower than ``speed_tol`` m/s relative to the belt (zero velocity overground). The foot is in
    contact when any of its points is. Contacts shorter than 3 frames are dropped as noise.
    """
    belt = np.zeros(3) if belt_velocity is None else np.asarray(belt_velocity, float)
    h = points[..., 1]
    low = h - h.min(axis=0, keepdims=True) < height_tol
    vel = np.gradient(points, 1.0 / fps, axis=0) - belt
    vel[..., 1] = 0.0
    slow = np.linalg.norm(vel, axis=-1) < speed_tol
    touch = np.any(low & slow, axis=1)
    touch = uniform_filter1d(touch.astype(float), 3, mode="wrap") > 0.5
    return touch


def stance_from_events(motion, positions: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Per foot, frames from each heel strike to the next toe off (Zeni events).

    A looped clip is analysed as three copies so that events at the seam are found.
    """
    from stimuli.motion.loop import repeat

    looped = bool(motion.metadata.get("looped"))
    rep = repeat(motion, 3) if looped else motion
    ev = gait_events(rep, None if looped else positions)
    n = rep.n_frames
    out = {}
    for s in ("l", "r"):
        mask = np.zeros(n, bool)
        hs, to = np.sort(ev[f"{s}_hs"]), np.sort(ev[f"{s}_to"])
        for h in hs:
            later = to[to > h]
            mask[h:(later[0] if len(later) else n)] = True
        if len(to) and (not len(hs) or to[0] < hs[0]):
            mask[:to[0]] = True  # the clip starts in stance
        out[s] = mask[motion.n_frames:2 * motion.n_frames] if looped else mask
    return out
