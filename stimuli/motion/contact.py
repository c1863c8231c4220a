"""One foot-contact model: foot height above the floor and speed over the ground, with hysteresis.

A foot is **in contact** from the frame its lowest sole point comes within ``enter_height_m`` of the
floor while its slowest low point moves slower than ``enter_speed_mps`` over the ground, until that
point rises above ``leave_height_m`` or every low point moves faster than ``leave_speed_mps``
(hysteresis: a foot grazing the thresholds does not flicker). Contacts shorter than
``min_contact_s`` are dropped and gaps shorter than ``min_gap_s`` bridged. Speeds are taken
relative to the belt on a treadmill clip (the ground the feet stand on), from positions smoothed
over ``smooth_s`` seconds: every constant is in seconds or metres, so the same motion at 30, 60 or
120 fps gives the same contacts (to within a frame).

"Low points" are the sole points within :data:`LOW_BAND_M` of the foot's lowest one: the heel at
heel strike, heel and ball at foot flat, the ball and toes at push-off, so a foot rolling over its
ball stays in contact while its ankle moves. The floor is given, or estimated as the median lowest
point of the slow frames (a raw capture's floor is seldom y = 0: its feet stand 1–4 cm above it and
its rigid toes dip below the flat foot at push-off).

This replaces contacts from gait events (Zeni et al. 2008), which assume steady straight walking:
on a start–walk–stop capture one foot was "in contact" for 3.5 s while it travelled 3.4 m. It is a
plain function of a motion (and optionally the sole points of a body), used by the foot clean-up,
the retargeting, the metrics and the physics step alike.

Examples
--------
>>> import numpy as np
>>> fps, t = 60.0, np.arange(120) / 60.0
>>> z = np.where(t < 1.0, 0.0, (t - 1.0) * 1.2)      # stands 1 s, then slides off at 1.2 m/s
>>> y = np.where(t < 1.0, 0.0, 0.0)                  # on the floor all along
>>> pts = np.stack([np.zeros_like(t), y, z], 1)[:, None]
>>> down = contact_mask(pts, fps)
>>> bool(down[:55].all()), bool(down[-30:].any())
(True, False)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

SIDES = ("l", "r")
ENTER_HEIGHT_M = 0.03
LEAVE_HEIGHT_M = 0.05
ENTER_SPEED_MPS = 0.4
LEAVE_SPEED_MPS = 0.8
MIN_CONTACT_S = 0.06
MIN_GAP_S = 0.05
SMOOTH_S = 0.015
# Sole points this close to the foot's lowest one share its contact (heel and ball of a flat foot).
LOW_BAND_M = 0.02
# A foot is "slow" for the floor estimate below this speed over the ground.
FLOOR_SPEED_MPS = 0.25


@dataclass
class Contacts:
    """Foot contacts of one motion: per foot ("l", "r") a T boolean ``down``, the T×P×3 world
    positions of its sole ``points``, and ``pivot`` (T ints: the lowest sole point while down, −1
    otherwise); ``floor_y`` the floor used, ``belt_speed`` the belt it was measured against (m/s
    towards −z, 0 overground)."""

    down: dict[str, np.ndarray]
    points: dict[str, np.ndarray]
    pivot: dict[str, np.ndarray]
    floor_y: float
    fps: float
    belt_speed: float = 0.0

    def as_metadata(self) -> dict[str, list[int]]:
        """The ``contacts`` metadata entry: {"l": [0/1 per frame], "r": [...]}."""
        return {s: self.down[s].astype(int).tolist() for s in SIDES}


def smooth(x: np.ndarray, fps: float, sigma_s: float = SMOOTH_S, cyclic: bool = False) -> np.ndarray:
    """Gaussian smoothing along time with a width in seconds (the same at any frame rate).

    >>> smooth(np.array([0.0, 0.0, 1.0, 0.0, 0.0]), 30.0, 0.0).tolist()
    [0.0, 0.0, 1.0, 0.0, 0.0]
    """
    sigma = sigma_s * fps
    if sigma < 0.3:   # narrower than a third of a frame: nothing to smooth
        return np.asarray(x, float)
    return gaussian_filter1d(np.asarray(x, float), sigma, axis=0, mode="wrap" if cyclic else "nearest")


def ground_speed(points: np.ndarray, fps: float, belt_speed: float = 0.0, cyclic: bool = False) -> np.ndarray:
    """Horizontal speed (m/s, T×P) of points (T×P×3) over the ground: relative to a belt running
    towards −z at ``belt_speed``.

    >>> p = np.stack([np.zeros(5), np.zeros(5), -np.arange(5) / 30.0], 1)[:, None]   # carried at 1 m/s
    >>> ground_speed(p, 30.0, belt_speed=1.0).round(6).ravel().tolist()
    [0.0, 0.0, 0.0, 0.0, 0.0]
    """
    p = np.asarray(points, float)
    if cyclic and len(p) > 2:
        # The seam's neighbour is the clip's other end, moved on by the clip's own travel.
        travel = p[-1] - p[0] + (p[-1] - p[-2])
        vel = (np.roll(p, -1, axis=0) - np.roll(p, 1, axis=0)) * fps / 2.0
        vel[0] = (p[1] - (p[-1] - travel)) * fps / 2.0
        vel[-1] = ((p[0] + travel) - p[-2]) * fps / 2.0
    elif len(p) > 1:
        vel = np.gradient(p, 1.0 / fps, axis=0)
    else:
        vel = np.zeros_like(p)
    vel[..., 2] += belt_speed
    return np.linalg.norm(vel[..., [0, 2]], axis=-1)


def hysteresis(enter: np.ndarray, leave: np.ndarray, cyclic: bool = False) -> np.ndarray:
    """A state per frame that turns on where ``enter`` holds and off where ``leave`` holds
    (``enter`` wins on frames where both hold). A looped clip starts in the state its end leaves.

    >>> hysteresis(np.array([0, 1, 0, 0, 0, 1], bool), np.array([0, 0, 0, 1, 0, 0], bool)).astype(int).tolist()
    [0, 1, 1, 0, 0, 1]
    """
    state = False
    out = np.zeros(len(enter), bool)
    for _ in range(2 if cyclic else 1):
        for t in range(len(enter)):
            if enter[t]:
                state = True
            elif leave[t]:
                state = False
            out[t] = state
    return out


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) runs of True (not wrapping).

    >>> runs(np.array([1, 1, 0, 1], bool))
    [(0, 2), (3, 4)]
    """
    d = np.diff(np.concatenate([[0], np.asarray(mask).astype(int), [0]]))
    return [(int(a), int(b)) for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1))]


def min_durations(mask: np.ndarray, fps: float, min_on_s: float = MIN_CONTACT_S, min_off_s: float = MIN_GAP_S,
                  cyclic: bool = False) -> np.ndarray:
    """Bridge gaps shorter than ``min_off_s``, then drop runs shorter than ``min_on_s`` (seconds).
    A gap or run cut by a clip's end is left alone (its length is unknown); a looped clip wraps.

    >>> m = np.array([1, 1, 1, 0, 1, 1, 1, 0, 0, 0, 1, 0, 0, 0], bool)
    >>> min_durations(m, 30.0, min_on_s=0.05, min_off_s=0.05).astype(int).tolist()
    [1, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 0]
    """
    mask = np.asarray(mask, bool).copy()
    n = len(mask)
    if mask.all() or not mask.any():
        return mask
    shift = int(np.argmin(mask)) if cyclic else 0   # a looped clip is read from a frame out of contact
    m = np.roll(mask, -shift)
    for s, e in runs(~m):
        if (e - s) / fps < min_off_s and (cyclic or (s > 0 and e < n)):
            m[s:e] = True
    for s, e in runs(m):
        if (e - s) / fps < min_on_s and (cyclic or (s > 0 and e < n)):
            m[s:e] = False
    return np.roll(m, shift)


def contact_mask(points: np.ndarray, fps: float, belt_speed: float = 0.0, floor_y: float = 0.0,
                 cyclic: bool = False, enter_height_m: float = ENTER_HEIGHT_M,
                 leave_height_m: float = LEAVE_HEIGHT_M, enter_speed_mps: float = ENTER_SPEED_MPS,
                 leave_speed_mps: float = LEAVE_SPEED_MPS, min_contact_s: float = MIN_CONTACT_S,
                 min_gap_s: float = MIN_GAP_S, smooth_s: float = SMOOTH_S) -> np.ndarray:
    """Contact per frame (T bool) of one foot from its sole points (T×P×3); see the module docstring."""
    p = smooth(points, fps, smooth_s, cyclic)
    height = p[..., 1] - floor_y
    low = height <= height.min(axis=1, keepdims=True) + LOW_BAND_M
    speed = np.where(low, ground_speed(p, fps, belt_speed, cyclic), np.inf).min(axis=1)
    lowest = height.min(axis=1)
    enter = (lowest <= enter_height_m) & (speed <= enter_speed_mps)
    leave = (lowest > leave_height_m) | (speed > leave_speed_mps)
    return min_durations(hysteresis(enter, leave, cyclic), fps, min_contact_s, min_gap_s, cyclic)


def estimate_floor(points: dict[str, np.ndarray], fps: float, belt_speed: float = 0.0, cyclic: bool = False) -> float:
    """Floor height (m): the median lowest sole point over the frames a foot moves slower than
    :data:`FLOOR_SPEED_MPS` over the ground (the 5th percentile of all frames if none is slow).

    >>> t = np.arange(60) / 30.0
    >>> foot = np.stack([0 * t, 0.02 + 0.1 * (t > 1), np.where(t > 1, t, 1.0)], 1)[:, None]
    >>> round(estimate_floor({"l": foot}, 30.0), 3)
    0.02
    """
    lows, slows = [], []
    for pts in points.values():
        p = smooth(pts, fps, SMOOTH_S, cyclic)
        lows.append(p[..., 1].min(axis=1))
        slows.append(ground_speed(p, fps, belt_speed, cyclic).min(axis=1) < FLOOR_SPEED_MPS)
    low, slow = np.concatenate(lows), np.concatenate(slows)
    return float(np.median(low[slow])) if slow.any() else float(np.percentile(low, 5))


def foot_contacts(motion, points: dict | None = None, belt_speed: float | None = None,
                  floor_y: float | None = None, **thresholds) -> Contacts:
    """Foot contacts of a motion (see the module docstring).

    ``points``: the feet's sole points as ``footfix.sole_points`` gives them ({"l": [(joint,
    offset)], ...}; e.g. ``retarget.mesh_sole_points(body)``), by default from the skeleton.
    ``belt_speed``: m/s towards −z; by default the motion's ``belt_speed_mps`` on a treadmill clip,
    else 0. ``floor_y``: by default estimated (:func:`estimate_floor`). ``thresholds``: any of
    :func:`contact_mask`'s keyword arguments. A looped clip (metadata ``looped``) wraps.

    >>> from stimuli.motion.generate import GaitParams, generate
    >>> walk = generate(GaitParams(), 1.75)
    >>> c = foot_contacts(walk)
    >>> bool(0.5 < c.down["l"].mean() < 0.75), bool((c.down["l"] | c.down["r"]).all())
    (True, True)
    """
    from stimuli.motion.footfix import sole_points, sole_positions

    meta = motion.metadata
    if belt_speed is None:
        belt_speed = float(meta.get("belt_speed_mps", 0.0)) if meta.get("treadmill") else 0.0
    cyclic = bool(meta.get("looped"))
    pts = sole_points(motion) if points is None else points
    grot, gpos = motion.global_transforms()
    world = {s: sole_positions(grot, gpos, pts[s]) for s in SIDES}
    floor = estimate_floor(world, motion.fps, belt_speed, cyclic) if floor_y is None else float(floor_y)
    down, pivot = {}, {}
    for s in SIDES:
        down[s] = contact_mask(world[s], motion.fps, belt_speed, floor, cyclic, **thresholds)
        pivot[s] = np.where(down[s], np.argmin(world[s][..., 1], axis=1), -1)
    return Contacts(down=down, points=world, pivot=pivot, floor_y=floor, fps=float(motion.fps),
                    belt_speed=float(belt_speed))
