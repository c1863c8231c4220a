"""Motion-quality metrics: gait figures and HUMOS-style physical plausibility (SPEC §1.4).

Gait: cadence, speed, step length, walking base, stance %, double support and flight %, number of
cycles, knee flexion range. Plausibility, after Tripathi et al. (HUMOS) and Yuan et al. (PhysDiff):

* **Penetrate** (cm): mean over frames of how far the lowest point lies below the ground.
* **Float** (cm): mean, over frames in which a foot should touch (it is planted: slow relative to
  the ground/belt and within 5 cm of the lowest it comes), of the height of that foot's lowest point.
* **Skate** (%): share of adjacent frame pairs in which a foot in contact (points within 1 cm of
  the ground in both frames) slides: every touching point moves horizontally faster than 0.1 m/s
  relative to the belt (a foot rolling about a planted heel or ball does not skate).
* **Dynamically unstable** (%): frames whose zero-moment point (from the centre of mass and its
  acceleration, flat ground) lies outside the base of support (convex hull of the contact points
  of the feet in contact, padded by the foot's width); a frame without contact (flight) counts as
  unstable, as in HUMOS.

The points can be skeleton sole points (:func:`plausibility_from_joints`) or mesh vertices of a
skinned body (:func:`plausibility_from_mesh`).
"""

from __future__ import annotations

import numpy as np
from matplotlib.path import Path as _MplPath
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import ConvexHull, QhullError

from stimuli.motion import quat
from stimuli.motion.events import gait_events
from stimuli.motion.footfix import sole_points, sole_positions
from stimuli.motion.loop import repeat
from stimuli.motion.skeleton import role_indices

CONTACT_HEIGHT_M = 0.01
SHOULD_TOUCH_HEIGHT_M = 0.05
PLANTED_SPEED_MPS = 0.25
SKATE_SPEED_MPS = 0.10
FOOT_HALF_WIDTH_M = 0.045
GRAVITY = 9.81
# Segment mass fractions (Winter 2009, Table 4.1) on joint-to-joint segments, CoM at the midpoint
# weighted by the proximal fraction given.
SEGMENT_MASS = [("pelvis", "chest", 0.578, 0.5), ("chest", "head", 0.081, 0.5),
                ("l_hip", "l_knee", 0.100, 0.433), ("r_hip", "r_knee", 0.100, 0.433),
                ("l_knee", "l_ankle", 0.0465, 0.433), ("r_knee", "r_ankle", 0.0465, 0.433),
                ("l_ankle", "l_toe", 0.0145, 0.5), ("r_ankle", "r_toe", 0.0145, 0.5),
                ("l_shoulder", "l_elbow", 0.028, 0.436), ("r_shoulder", "r_elbow", 0.028, 0.436),
                ("l_elbow", "l_wrist", 0.022, 0.682), ("r_elbow", "r_wrist", 0.022, 0.682)]


def _periodic(motion):
    """Three copies of a looped clip (events at the seam are found), else the clip itself."""
    return (repeat(motion, 3), 3) if motion.metadata.get("looped") else (motion, 1)


def knee_angles(motion, positions=None) -> dict[str, np.ndarray]:
    """Knee flexion (degrees, 0 = straight) per side from hip, knee and ankle positions."""
    roles = role_indices(motion)
    pos = motion.positions() if positions is None else positions
    out = {}
    for s in ("l", "r"):
        thigh = pos[:, roles[f"{s}_knee"]] - pos[:, roles[f"{s}_hip"]]
        shank = pos[:, roles[f"{s}_ankle"]] - pos[:, roles[f"{s}_knee"]]
        c = np.sum(thigh * shank, 1) / np.linalg.norm(thigh, axis=1) / np.linalg.norm(shank, axis=1)
        out[s] = np.degrees(np.arccos(np.clip(c, -1, 1)))
    return out


def foot_contacts(sole: dict[str, np.ndarray], height: float = CONTACT_HEIGHT_M) -> dict[str, np.ndarray]:
    """Per foot, frames whose lowest sole point is within ``height`` of the ground."""
    return {s: pts[:, :, 1].min(axis=1) <= height for s, pts in sole.items()}


def gait_metrics(motion, points: dict | None = None) -> dict:
    """Cadence (steps/min), speed (m/s), step length (m), walking base (m), stance/double-support/
    flight (%), cycles, knee flexion range (°)."""
    rep, k = _periodic(motion)
    ev = gait_events(rep)
    # Strides of the same foot (two steps each): robust to left/right step asymmetry.
    strides = np.concatenate([np.diff(ev["l_hs"]), np.diff(ev["r_hs"])])
    cadence = 120.0 * motion.fps / float(np.median(strides)) if len(strides) else float("nan")
    if motion.metadata.get("treadmill"):
        speed = float(motion.metadata.get("belt_speed_mps", 0.0))
    else:
        disp = motion.root_translation[-1] - motion.root_translation[0]
        speed = float(np.linalg.norm(disp[[0, 2]]) / max((motion.n_frames - 1) / motion.fps, 1e-9))
    grot, gpos = rep.global_transforms()
    pts = sole_points(rep) if points is None else points
    sole = {s: sole_positions(grot, gpos, pts[s]) for s in ("l", "r")}
    # Contact within 1 cm of the level each foot stands at, not of y = 0: a raw capture's floor is
    # where its rigid toes dip at push-off, 1–2 cm below the flat foot, and from y = 0 a CMU walk
    # read as 9 % stance and 82 % flight. Generated and retargeted clips stand at 0 (unchanged).
    level = {s: stance_level(sole[s][:, :, 1].min(axis=1), ev[f"{s}_hs"], ev[f"{s}_to"]) for s in ("l", "r")}
    contact = foot_contacts({s: sole[s] - [0.0, level[s], 0.0] for s in sole})
    stance = 100.0 * np.mean([contact[s].mean() for s in ("l", "r")])
    both = 100.0 * float(np.mean(contact["l"] & contact["r"]))
    none = 100.0 * float(np.mean(~contact["l"] & ~contact["r"]))
    # Walking base: lateral distance between the heel lines (the heel is sole point 0).
    mid = {s: sole[s][contact[s], 0].mean(axis=0) if contact[s].any() else np.full(3, np.nan) for s in ("l", "r")}
    base = float(abs(mid["l"][0] - mid["r"][0]))
    knees = knee_angles(rep, gpos)
    knee_range = float(np.mean([np.ptp(knees[s]) for s in ("l", "r")]))
    cycles = motion.metadata.get("cycles")
    if cycles is None:
        cycles = max(len(ev["l_hs"]) - 1, 0)
    return {"cadence_spm": float(cadence), "speed_mps": speed,
            "step_length_m": float(speed * 60.0 / cadence) if np.isfinite(cadence) and cadence > 0 else float("nan"),
            "walking_base_m": base, "stance_pct": float(stance), "double_support_pct": both,
            "flight_pct": none, "stance_height_cm": 100.0 * float(np.mean(list(level.values()))),
            "cycles": int(cycles), "knee_flexion_range_deg": knee_range,
            "knee_flexion_max_deg": float(max(knees["l"].max(), knees["r"].max()))}


def stance_level(low: np.ndarray, heel_strikes: np.ndarray, toe_offs: np.ndarray) -> float:
    """Height (m) a foot stands at: the median of its lowest point from heel strike to toe off.

    0 when there are no events (then contact is judged from the ground itself).

    >>> low = np.array([0.02, 0.02, 0.02, 0.10, 0.20, 0.10])
    >>> stance_level(low, np.array([0]), np.array([3]))
    0.02
    """
    mask = np.zeros(len(low), bool)
    for h in heel_strikes:
        later = toe_offs[toe_offs > h]
        mask[h:later.min() if len(later) else len(low)] = True
    return round(float(np.median(low[mask])), 6) if mask.any() else 0.0


def _widen(points: np.ndarray, lateral: np.ndarray) -> np.ndarray:
    """Add points ± half a foot width sideways (a sole is not a line)."""
    return np.concatenate([points + lateral * FOOT_HALF_WIDTH_M, points - lateral * FOOT_HALF_WIDTH_M])


def _inside(point: np.ndarray, pts: np.ndarray) -> bool:
    """Whether a 2-D point lies in the convex hull of 2-D points."""
    if len(pts) < 3:
        return False
    try:
        hull = ConvexHull(pts)
    except QhullError:
        return False
    return bool(_MplPath(pts[hull.vertices]).contains_point(point, radius=1e-9))


def zmp(com: np.ndarray, fps: float) -> np.ndarray:
    """Zero-moment point (T×3, on y = 0) of a point-mass body from its CoM path (flat ground).

    x_zmp = x_G − y_G·a_x/(a_y + g), likewise z. On a treadmill the belt is an inertial frame too
    (constant velocity), so the same formula holds in belt or lab coordinates.
    """
    dt = 1.0 / fps
    # A light low-pass (σ = 1/30 s) keeps frame-to-frame jitter from dominating the acceleration.
    com = gaussian_filter1d(com, max(fps / 30.0, 0.5), axis=0, mode="wrap")
    acc = (np.roll(com, -1, 0) - 2 * com + np.roll(com, 1, 0)) / dt**2
    denom = acc[:, 1] + GRAVITY
    out = com.copy()
    out[:, 0] = com[:, 0] - com[:, 1] * acc[:, 0] / denom
    out[:, 2] = com[:, 2] - com[:, 1] * acc[:, 2] / denom
    out[:, 1] = 0.0
    return out


def plausibility(sole: dict[str, np.ndarray], lowest_y: np.ndarray, com: np.ndarray, fps: float,
                 belt_speed: float = 0.0, lateral: dict[str, np.ndarray] | None = None,
                 periodic: bool = True, skate_points: dict[str, np.ndarray] | None = None) -> dict:
    """Penetrate/Float (cm), Skate and dynamically unstable (%) from contact points and the CoM.

    ``sole``: per foot, T×P×3 points that can touch the ground (sole points or foot vertices);
    ``lowest_y``: T lowest height of the whole body; ``com``: T×3 centre of mass; ``lateral``: per
    foot, T×3 unit sideways axis used to pad a thin sole into a foot-wide base of support.
    """
    belt = np.array([0.0, 0.0, -belt_speed])
    dt = 1.0 / fps
    penetrate = 100.0 * float(np.mean(np.maximum(0.0, -lowest_y)))
    contact = foot_contacts(sole)
    skate_points = sole if skate_points is None else skate_points
    float_vals, skate_pairs = [], np.zeros(len(lowest_y) - 1, bool)
    for s, pts in skate_points.items():
        after = np.roll(pts, -1, 0) if periodic else np.concatenate([pts[1:], pts[-1:]])
        vel = (after - pts) / dt - belt
        speed = np.linalg.norm(vel[:, :, [0, 2]], axis=2)
        touching = np.maximum(pts[:, :, 1], after[:, :, 1]) <= CONTACT_HEIGHT_M
        # A foot slides only if none of its touching points stays put: rolling about a planted
        # heel or ball is not skating.
        still = np.where(touching, speed, np.inf).min(axis=1)
        skate_pairs |= (touching.any(axis=1) & (still > SKATE_SPEED_MPS))[:-1]
    for s, pts in sole.items():
        after = np.roll(pts, -1, 0) if periodic else np.concatenate([pts[1:], pts[-1:]])
        # The point that touches in both frames of the pair: lowest by its higher of the two heights.
        k = np.argmin(np.maximum(pts[:, :, 1], after[:, :, 1]), axis=1)
        low = pts[np.arange(len(pts)), k]
        nxt = after[np.arange(len(pts)), k]
        vel = (nxt - low) / dt - belt
        speed = np.linalg.norm(vel[:, [0, 2]], axis=1)
        # Near the ground: within 5 cm of the lowest this foot comes, not of y = 0 — a clip floating
        # 10 cm over the floor had no planted frame at all and read Float 0.
        near = low[:, 1] < max(0.0, float(low[:, 1].min())) + SHOULD_TOUCH_HEIGHT_M
        planted = (speed < PLANTED_SPEED_MPS) & near
        float_vals.append(np.where(planted, np.maximum(low[:, 1], 0.0), np.nan))
    fv = np.concatenate(float_vals)
    floating = 100.0 * float(np.nanmean(fv)) if np.isfinite(fv).any() else 0.0
    z = zmp(com, fps)
    unstable = 0
    for t in range(len(com)):
        pts = []
        for s, p in sole.items():
            touching = p[t][p[t, :, 1] <= CONTACT_HEIGHT_M]
            if len(touching):
                pts.append(_widen(touching, lateral[s][t]) if lateral is not None else touching)
        if not pts or not _inside(z[t, [0, 2]], np.concatenate(pts)[:, [0, 2]]):
            unstable += 1
    return {"penetrate_cm": penetrate, "float_cm": floating,
            "skate_pct": 100.0 * float(skate_pairs.mean()) if len(skate_pairs) else 0.0,
            "dynamically_unstable_pct": 100.0 * unstable / len(com),
            "contact_frames_pct": 100.0 * float(np.mean(contact["l"] | contact["r"]))}


def segment_com(motion, positions: np.ndarray | None = None) -> np.ndarray:
    """Whole-body centre of mass (T×3) from joint positions and Winter's segment masses."""
    roles = role_indices(motion)
    pos = motion.positions() if positions is None else positions
    total, acc = 0.0, np.zeros((pos.shape[0], 3))
    for a, b, mass, frac in SEGMENT_MASS:
        if a in roles and b in roles:
            acc += mass * (pos[:, roles[a]] + frac * (pos[:, roles[b]] - pos[:, roles[a]]))
            total += mass
    return acc / total


def plausibility_from_joints(motion) -> dict:
    """Plausibility on the skeleton's sole points (no mesh needed)."""
    grot, gpos = motion.global_transforms()
    pts = sole_points(motion)
    roles = role_indices(motion)
    sole = {s: sole_positions(grot, gpos, pts[s]) for s in ("l", "r")}
    lowest = np.minimum(gpos[:, :, 1].min(axis=1), np.min([v[:, :, 1].min(axis=1) for v in sole.values()], axis=0))
    lateral = {s: quat.rotate(grot[:, roles[f"{s}_ankle"]], np.array([1.0, 0.0, 0.0])) for s in ("l", "r")}
    return plausibility(sole, lowest, segment_com(motion, gpos), motion.fps,
                        float(motion.metadata.get("belt_speed_mps", 0.0)) if motion.metadata.get("treadmill") else 0.0,
                        lateral, periodic=bool(motion.metadata.get("looped")))


def plausibility_from_mesh(vertices: np.ndarray, foot_vertices: dict[str, np.ndarray], com: np.ndarray,
                           fps: float, belt_speed: float = 0.0, periodic: bool = True,
                           skate_points: dict[str, np.ndarray] | None = None) -> dict:
    """Plausibility on a skinned mesh: T×V×3 vertices, per-foot vertex index arrays, T×3 CoM;
    ``skate_points`` as in :func:`plausibility` (the feet's anatomical sole points on the mesh)."""
    lowest = vertices[:, :, 1].min(axis=1)
    sole = {s: vertices[:, idx] for s, idx in foot_vertices.items()}
    return plausibility(sole, lowest, com, fps, belt_speed, None, periodic, skate_points)
