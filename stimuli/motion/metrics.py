"""Motion-quality metrics: gait figures and physical plausibility as papers report them (SPEC §1.4).

Gait: cadence, speed, step length, walking base, stance %, double support and flight %, number of
cycles, knee flexion range. Plausibility, each under the name and definition of the work it is
compared with (the floor is y = 0 of the project frame; on a treadmill every horizontal speed and
slip is taken relative to the belt, the ground the feet stand on):

* **Skate, HUMOS** (``skate_humos_pct``, % of frame pairs): Tripathi et al., "HUMOS: Human Motion
  Model Conditioned on Body Shape", ECCV 2024, report foot skating as GMD defines it
  (Karunratanakul et al., "Guided Motion Diffusion", ICCV 2023; code: ``calculate_skating_ratio`` in
  ``data_loaders/humanml/utils/metrics.py`` of korrawe/guided-motion-diffusion): the motion at
  20 fps (HumanML3D's rate), the two foot joints (SMPL ``L_Foot``/``R_Foot``, the ball of the
  foot: here the ``toe`` role, the ankle on a toe-less skeleton); a pair of frames skates when a
  foot joint is below 5 cm in both frames and moves horizontally faster than 0.5 m/s (2.5 cm per
  frame) both in that pair and in the 5-pair moving average (zero-padded at the clip's ends).
* **Skate, PhysDiff/PHC** (``skate_phc_mm``): mean horizontal slip (mm per frame at 20 fps) of the
  points touching the floor (within 1 cm) in two consecutive frames, over the pairs that have such
  points. PhysDiff (Yuan et al., ICCV 2023) and the PHC/SimPoE line measure foot sliding as the
  displacement of the body-mesh vertices in contact between adjacent frames; the 1 cm contact
  height and the 20 fps are this project's choice (HumanML3D's rate, on which PhysDiff reports).
* **Penetrate** (``penetrate_mm``, ``penetrate_max_mm``): how far the lowest point lies below the
  floor, mean over all frames and the largest (PhysDiff's Penetrate, in mm).
* **Float** (``float_mm``): mean, over the frames in which a foot should touch (it is planted:
  slower than 0.25 m/s and within 5 cm of the lowest it comes), of the height of that foot's lowest
  point above the floor (PhysDiff's Float, measured where a foot should be in contact).
* **Dynamically unstable** (``unstable_pct``): frames whose zero-moment point lies more than 2 cm
  outside the base of support, % of the frames that have support. The ZMP is the multi-body one of
  Winter's segment masses (point masses at the segments' centres of mass, so the change of their
  angular momentum counts): x_zmp = Σ mᵢ[(ÿᵢ+g)xᵢ − yᵢẍᵢ] / Σ mᵢ(ÿᵢ+g), from positions low-passed
  at 6 Hz (4th-order zero-lag Butterworth, as gait labs filter marker data; a looped clip is
  filtered as a loop). The base of support is the convex hull of the contact patches: a foot is
  down while its lowest point is within 2 cm of the level it stands at (a raw capture's feet stand
  1–4 cm above its y = 0) or stays put (slower than 0.25 m/s); its patch is its whole sole (sole
  points; every sole vertex on a mesh) while it stays put, else its points within 2 cm of its
  lowest point that move slower than 1 m/s. Frames without support are flight
  (``stability_flight_pct``, % of all frames), never "unstable".

The points can be skeleton sole points (:func:`plausibility_from_joints`) or mesh vertices of a
skinned body (:func:`plausibility_from_mesh`). ``skate_pct``, ``penetrate_cm``, ``float_cm``,
``dynamically_unstable_pct`` and ``contact_frames_pct`` are the same figures under their earlier
names (``skate_humos_pct``, ``penetrate_mm``/10, ``float_mm``/10, ``unstable_pct`` and the share of
frames with support).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.signal import butter, sosfiltfilt
from scipy.spatial import ConvexHull, QhullError

from stimuli.motion.events import gait_events
from stimuli.motion.footfix import sole_points, sole_positions
from stimuli.motion.loop import repeat
from stimuli.motion.skeleton import role_indices

CONTACT_HEIGHT_M = 0.01
SHOULD_TOUCH_HEIGHT_M = 0.05
PLANTED_SPEED_MPS = 0.25
FOOT_HALF_WIDTH_M = 0.045
GRAVITY = 9.81
# HUMOS / GMD foot skating: at HumanML3D's 20 fps, a foot joint below 5 cm, faster than 0.5 m/s in
# the pair and in the 5-pair moving average.
EVAL_FPS = 20.0
HUMOS_HEIGHT_M = 0.05
HUMOS_SPEED_MPS = 0.5
HUMOS_WINDOW = 5
# Dynamic stability: a sole point supports when this low and this slow; the ZMP may lie this far
# outside the hull (soft tissue and shoe edge; a mesh sole is a few mm thick); 6 Hz low-pass.
SUPPORT_HEIGHT_M = 0.02
SUPPORT_SPEED_MPS = 1.0
ZMP_TOLERANCE_M = 0.02
LOWPASS_HZ = 6.0
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


def signed_knee_angles(motion, positions=None) -> dict[str, np.ndarray]:
    """Knee flexion (degrees) per side, negative where the knee bends backwards (hyperextension).

    :func:`knee_angles` reads a knee bent 20° backwards as 20° of flexion; here the side comes from
    the hips' left–right axis (a shank turned back from its thigh, seen from the body's left, is flexion).

    >>> from stimuli.motion.motion import Motion
    >>> names = ["pelvis", "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle"]
    >>> m = Motion(fps=30.0, joint_names=names, parents=np.array([-1, 0, 1, 2, 0, 4, 5]),
    ...            offsets=np.zeros((7, 3)), rotations=np.tile([1.0, 0, 0, 0], (1, 7, 1)),
    ...            root_translation=np.zeros((1, 3)))
    >>> pos = np.array([[[0, 1, 0], [0.1, 1, 0], [0.1, 0.5, 0], [0.1, 0, -0.1],     # left: ankle behind
    ...                  [-0.1, 1, 0], [-0.1, 0.5, 0], [-0.1, 0, 0.1]]], float)      # right: ahead
    >>> {s: round(float(a[0]), 1) for s, a in signed_knee_angles(m, pos).items()}
    {'l': 11.3, 'r': -11.3}
    """
    roles = role_indices(motion)
    pos = motion.positions() if positions is None else positions
    left = pos[:, roles["l_hip"]] - pos[:, roles["r_hip"]]
    out = {}
    for s, unsigned in knee_angles(motion, pos).items():
        thigh = pos[:, roles[f"{s}_knee"]] - pos[:, roles[f"{s}_hip"]]
        shank = pos[:, roles[f"{s}_ankle"]] - pos[:, roles[f"{s}_knee"]]
        out[s] = np.where(np.sum(np.cross(thigh, shank) * left, axis=1) < 0, -unsigned, unsigned)
    return out


def knee_hyperextension(motion, positions=None) -> float:
    """How far (degrees) either knee bends backwards past straight at most; negative: never straight
    (the least flexion of :func:`signed_knee_angles`, sign turned)."""
    return -min(float(k.min()) for k in signed_knee_angles(motion, positions).values())


def foot_contacts(sole: dict[str, np.ndarray], height: float = CONTACT_HEIGHT_M) -> dict[str, np.ndarray]:
    """Per foot, frames whose lowest sole point is within ``height`` of the ground."""
    return {s: pts[:, :, 1].min(axis=1) <= height for s, pts in sole.items()}


def gait_metrics(motion, points: dict | None = None) -> dict:
    """Cadence (steps/min), speed (m/s), step length (m), walking base (m), stance/double-support/
    flight (%), cycles, knee flexion range and maximum (°), and how far a knee bends backwards past
    straight at most (°, negative: never straight; :func:`signed_knee_angles`)."""
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
            "knee_flexion_max_deg": float(max(knees["l"].max(), knees["r"].max())),
            "knee_hyperextension_deg": knee_hyperextension(rep, gpos)}


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


def resample_points(points: np.ndarray, fps: float, target_fps: float = EVAL_FPS) -> np.ndarray:
    """Points (T×…×3) linearly interpolated at ``target_fps`` over the same time span.

    >>> p = np.arange(7.0)[:, None, None] * np.array([1.0, 0.0, 0.0])   # 1 m per frame at 60 fps
    >>> resample_points(p, 60.0)[:, 0, 0]                                # 3 m per frame at 20 fps
    array([0., 3., 6.])
    """
    points = np.asarray(points, float)
    n = int(np.floor((len(points) - 1) / fps * target_fps + 1e-9)) + 1
    f = np.arange(n) * fps / target_fps
    i0 = np.minimum(np.floor(f).astype(int), len(points) - 1)
    i1 = np.minimum(i0 + 1, len(points) - 1)
    a = (f - i0).reshape((-1,) + (1,) * (points.ndim - 1))
    return points[i0] * (1.0 - a) + points[i1] * a


def on_belt(points: np.ndarray, fps: float, belt_speed: float = 0.0) -> np.ndarray:
    """Points (T×…×3) in the frame of a belt running towards −z at ``belt_speed`` (m/s): a foot
    planted on the belt stands still there. On ground (speed 0) the points themselves."""
    if not belt_speed:
        return np.asarray(points, float)
    shift = np.zeros((len(points),) + (1,) * (np.ndim(points) - 2) + (3,))
    shift[..., 2] = (np.arange(len(points)) / fps * belt_speed).reshape(shift.shape[:-1])
    return np.asarray(points, float) + shift


def skate_humos(foot_joints: np.ndarray, fps: float, belt_speed: float = 0.0) -> float:
    """HUMOS/GMD foot skating (% of frame pairs at 20 fps) of the foot joints (T×F×3).

    A pair skates when a foot joint is below 5 cm in both frames and moves horizontally faster than
    0.5 m/s, in the pair and in the 5-pair moving average (GMD's ``calculate_skating_ratio``).

    >>> t = np.arange(31) / 30.0                                   # 1 s at 30 fps
    >>> sliding = np.stack([np.zeros(31), np.full(31, 0.03), t], 1)[:, None]   # 1 m/s, 3 cm up
    >>> skate_humos(sliding, 30.0)
    100.0
    >>> carried = sliding * [1.0, 1.0, -1.0]                         # back at 1 m/s …
    >>> skate_humos(carried, 30.0, belt_speed=1.0)                   # … standing on a 1 m/s belt
    0.0
    """
    p = resample_points(on_belt(foot_joints, fps, belt_speed), fps)
    if len(p) < 2:
        return 0.0
    speed = np.linalg.norm(np.diff(p[..., [0, 2]], axis=0), axis=-1) * EVAL_FPS        # (T−1)×F
    mean = uniform_filter1d(speed, size=HUMOS_WINDOW, axis=0, mode="constant", origin=0)
    low = p[..., 1] < HUMOS_HEIGHT_M
    skating = low[:-1] & low[1:] & (speed > HUMOS_SPEED_MPS) & (mean > HUMOS_SPEED_MPS)
    return 100.0 * float(skating.any(axis=1).mean())


def skate_slip_mm(points: np.ndarray, fps: float, belt_speed: float = 0.0,
                  contact_height: float = CONTACT_HEIGHT_M) -> float:
    """PhysDiff/PHC-style skate: mean horizontal slip (mm per frame at 20 fps) of the points
    (T×P×3) that touch the floor in two consecutive frames, over the pairs with such points.

    >>> t = np.arange(21) / 20.0
    >>> sliding = np.stack([np.zeros(21), np.zeros(21), 0.4 * t], 1)[:, None]   # 0.4 m/s on the floor
    >>> round(skate_slip_mm(sliding, 20.0), 6)
    20.0
    """
    p = resample_points(on_belt(points, fps, belt_speed), fps)
    if len(p) < 2:
        return 0.0
    slip = np.linalg.norm(np.diff(p[..., [0, 2]], axis=0), axis=-1)
    touching = (p[:-1, :, 1] <= contact_height) & (p[1:, :, 1] <= contact_height)
    pairs = touching.any(axis=1)
    if not pairs.any():
        return 0.0
    per_pair = (slip * touching).sum(axis=1)[pairs] / touching.sum(axis=1)[pairs]
    return 1000.0 * float(per_pair.mean())


def penetration_mm(lowest_y: np.ndarray) -> tuple[float, float]:
    """Mean and largest depth (mm) of the lowest point below the floor, over all frames.

    >>> penetration_mm(np.array([-0.01, -0.01, 0.02, 0.0]))
    (5.0, 10.0)
    """
    depth = np.maximum(0.0, -np.asarray(lowest_y, float))
    return 1000.0 * float(depth.mean()), 1000.0 * float(depth.max())


def float_mm(sole: dict[str, np.ndarray], fps: float, belt_speed: float = 0.0, periodic: bool = True) -> float:
    """Mean height (mm) above the floor of a planted foot's lowest point (NaN: never planted).

    ``sole``: per foot, T×P×3 points that can touch the floor. Per pair of frames the point lowest
    in both is followed; the foot is planted while that point moves slower than 0.25 m/s (relative
    to the belt) within 5 cm of the lowest the foot comes — not of y = 0: a clip floating 10 cm
    over the floor must read 100 mm, not 0.

    >>> still = np.zeros((10, 3, 3)); still[..., 1] = 0.02            # a foot held 2 cm up
    >>> round(float_mm({"l": still}, 30.0), 6)
    20.0
    """
    values = []
    for pts in sole.values():
        pts = on_belt(pts, fps, belt_speed)
        after = np.roll(pts, -1, 0) if periodic else np.concatenate([pts[1:], pts[-1:]])
        k = np.argmin(np.maximum(pts[:, :, 1], after[:, :, 1]), axis=1)
        low, nxt = pts[np.arange(len(pts)), k], after[np.arange(len(pts)), k]
        speed = np.linalg.norm((nxt - low)[:, [0, 2]], axis=1) * fps
        near = low[:, 1] < max(0.0, float(low[:, 1].min())) + SHOULD_TOUCH_HEIGHT_M
        values.append(np.where((speed < PLANTED_SPEED_MPS) & near, np.maximum(low[:, 1], 0.0), np.nan))
    v = np.concatenate(values)
    return 1000.0 * float(np.nanmean(v)) if np.isfinite(v).any() else float("nan")


def lowpass(x: np.ndarray, fps: float, cutoff_hz: float = LOWPASS_HZ, periodic: bool = False) -> np.ndarray:
    """Zero-lag 4th-order Butterworth low-pass along time (a 2nd-order filter run both ways);
    a periodic clip is filtered as a loop. Unchanged when the cutoff is at or above Nyquist.

    >>> t = np.arange(120) / 120.0
    >>> smooth = lowpass(np.sin(2 * np.pi * t) + 0.01 * np.sin(2 * np.pi * 40 * t), 120.0, periodic=True)
    >>> bool(np.abs(smooth - np.sin(2 * np.pi * t)).max() < 1e-3)
    True
    """
    wn = cutoff_hz / (0.5 * fps)
    if wn >= 1.0 or len(x) < 3:
        return np.asarray(x, float)
    sos = butter(2, wn, output="sos")
    if periodic:
        n = len(x)
        return sosfiltfilt(sos, np.concatenate([x, x, x]), axis=0)[n:2 * n]
    return sosfiltfilt(sos, x, axis=0, padlen=min(3 * (2 * len(sos) + 1), len(x) - 1))


def _second_derivative(x: np.ndarray, fps: float, periodic: bool) -> np.ndarray:
    if periodic:
        return (np.roll(x, -1, 0) - 2 * x + np.roll(x, 1, 0)) * fps**2
    if len(x) < 3:
        return np.zeros_like(x)
    return np.gradient(np.gradient(x, axis=0), axis=0) * fps**2


def zmp_multibody(points: np.ndarray, masses: np.ndarray, fps: float, periodic: bool = False) -> np.ndarray:
    """Zero-moment point (T×3, on the floor y = 0) of point masses (T×S×3 positions, S masses).

    x_zmp = Σ mᵢ[(ÿᵢ+g)xᵢ − yᵢẍᵢ] / Σ mᵢ(ÿᵢ+g), likewise z, from positions low-passed at 6 Hz. On a
    treadmill the belt is an inertial frame too, so the formula holds in belt or lab coordinates.

    >>> still = np.tile([[0.1, 1.0, 0.2], [0.3, 0.5, 0.0]], (10, 1, 1))
    >>> zmp_multibody(still, np.array([1.0, 1.0]), 30.0)[0].round(6).tolist()
    [0.2, 0.0, 0.1]
    """
    p = lowpass(points, fps, periodic=periodic)
    acc = _second_derivative(p, fps, periodic)
    w = masses * (acc[..., 1] + GRAVITY)
    denom = w.sum(axis=1)
    out = np.zeros((len(p), 3))
    for axis in (0, 2):
        out[:, axis] = ((w * p[..., axis]).sum(axis=1) - (masses * p[..., 1] * acc[..., axis]).sum(axis=1)) / denom
    return out


def distance_outside(point: np.ndarray, pts: np.ndarray) -> float:
    """Distance (m) from a 2-D point to the convex hull of 2-D points; 0 inside.

    >>> square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    >>> distance_outside(np.array([0.5, 0.5]), square), distance_outside(np.array([1.5, 0.5]), square)
    (0.0, 0.5)
    """
    pts = np.unique(np.asarray(pts, float), axis=0)
    edges = []
    if len(pts) >= 3:
        try:
            hull = ConvexHull(pts)
            if np.all(hull.equations[:, :2] @ point + hull.equations[:, 2] <= 1e-12):
                return 0.0
            ring = pts[hull.vertices]
            edges = list(zip(ring, np.roll(ring, -1, 0)))
        except QhullError:   # collinear points: their hull is the segment between the extremes
            pass
    if not edges:
        if len(pts) == 1:
            return float(np.linalg.norm(point - pts[0]))
        axis = pts[-1] - pts[0]
        order = np.argsort(pts @ axis)
        edges = [(pts[order[0]], pts[order[-1]])]
    best = np.inf
    for a, b in edges:
        ab = b - a
        t = np.clip(np.dot(point - a, ab) / max(np.dot(ab, ab), 1e-18), 0.0, 1.0)
        best = min(best, float(np.linalg.norm(point - (a + t * ab))))
    return best


def standing_level(points: np.ndarray, fps: float, belt_speed: float = 0.0) -> float:
    """Height (m) a foot stands at: the median of its lowest point (T×P×3 points) over the frames in
    which that point is slower than 0.25 m/s relative to the belt; 0 if it never is. A raw capture's
    feet stand 1–4 cm above its y = 0 (its floor is the toes' push-off dip, or the markers' height).

    >>> foot = np.zeros((10, 2, 3)); foot[..., 1] = [0.03, 0.08]
    >>> standing_level(foot, 30.0)
    0.03
    """
    pts = on_belt(points, fps, belt_speed)
    k = np.argmin(pts[..., 1], axis=1)
    low = pts[np.arange(len(pts)), k]
    speed = np.linalg.norm(np.gradient(low[:, [0, 2]], axis=0), axis=1) * fps if len(low) > 1 else np.zeros(len(low))
    slow = speed < PLANTED_SPEED_MPS
    return round(float(np.median(low[slow, 1])), 6) if slow.any() else 0.0


def support_points(feet: dict[str, np.ndarray], fps: float, belt_speed: float = 0.0) -> np.ndarray:
    """T×P bool: the sole points (per foot T×P×3, concatenated) that support the body.

    A foot is on the floor while its lowest point is within 2 cm of the level it stands at
    (:func:`standing_level`) or is planted (slower than 0.25 m/s: a capture's floor is not always
    level, and a foot that stays put bears weight). Its contact patch is its whole sole while it
    stays put, else its points within 2 cm of its lowest point (the heel at heel strike, the ball
    and toes at push-off) that move slower than 1 m/s relative to the belt (a swinging foot
    skimming the floor carries no weight).
    """
    out = []
    for p in feet.values():
        q = on_belt(p, fps, belt_speed)
        vel = np.gradient(q[..., [0, 2]], axis=0) * fps if len(q) > 1 else np.zeros(q[..., [0, 2]].shape)
        k = np.argmin(q[..., 1], axis=1)
        low = q[np.arange(len(q)), k, 1][:, None]
        planted = np.linalg.norm(vel[np.arange(len(q)), k], axis=-1)[:, None] < PLANTED_SPEED_MPS
        down = (low <= standing_level(p, fps, belt_speed) + SUPPORT_HEIGHT_M) | planted
        patch = planted | ((q[..., 1] <= low + SUPPORT_HEIGHT_M) & (np.linalg.norm(vel, axis=-1) <= SUPPORT_SPEED_MPS))
        out.append(down & patch)
    return np.concatenate(out, axis=1)


def dynamic_stability(feet: dict[str, np.ndarray], segments: np.ndarray, masses: np.ndarray, fps: float,
                      belt_speed: float = 0.0, periodic: bool = False) -> dict:
    """``unstable_pct`` (ZMP more than 2 cm outside the base of support, % of the frames with
    support) and ``stability_flight_pct`` (frames without support, % of all frames).

    ``feet``: per foot, T×P×3 sole points or foot vertices; ``segments``/``masses``: point masses
    for the ZMP (:func:`segment_points`)."""
    z = zmp_multibody(segments, masses, fps, periodic)[:, [0, 2]]
    pts = np.concatenate(list(feet.values()), axis=1)[..., [0, 2]]
    support = support_points(feet, fps, belt_speed)
    supported = support.any(axis=1)
    unstable = sum(distance_outside(z[t], pts[t][support[t]]) > ZMP_TOLERANCE_M for t in np.flatnonzero(supported))
    n = int(supported.sum())
    return {"unstable_pct": 100.0 * unstable / n if n else float("nan"),
            "stability_flight_pct": 100.0 * float((~supported).mean())}


def plausibility(sole: dict[str, np.ndarray], lowest_y: np.ndarray, foot_joints: np.ndarray,
                 segments: np.ndarray, masses: np.ndarray, fps: float, belt_speed: float = 0.0,
                 periodic: bool = True) -> dict:
    """Every plausibility figure of the module docstring.

    ``sole``: per foot, T×P×3 points that can touch the floor (sole points or foot vertices);
    ``lowest_y``: T lowest height of the whole body; ``foot_joints``: T×2×3 HUMOS foot joints;
    ``segments``/``masses``: point masses for the ZMP.
    """
    penetrate, penetrate_max = penetration_mm(lowest_y)
    floating = float_mm(sole, fps, belt_speed, periodic)
    skate = skate_humos(foot_joints, fps, belt_speed)
    stability = dynamic_stability(sole, segments, masses, fps, belt_speed, periodic)
    return {"skate_humos_pct": skate,
            "skate_phc_mm": skate_slip_mm(np.concatenate(list(sole.values()), axis=1), fps, belt_speed),
            "penetrate_mm": penetrate, "penetrate_max_mm": penetrate_max, "float_mm": floating, **stability,
            # The earlier names of the same figures (tests, the benchmark and users' scripts read them).
            "skate_pct": skate, "penetrate_cm": penetrate / 10.0, "float_cm": floating / 10.0,
            "dynamically_unstable_pct": stability["unstable_pct"],
            "contact_frames_pct": 100.0 - stability["stability_flight_pct"]}


def segment_points(motion, positions: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Centres of mass (T×S×3) and mass fractions (S) of Winter's segments present on the skeleton."""
    roles = role_indices(motion)
    pos = motion.positions() if positions is None else positions
    pts, masses = [], []
    for a, b, mass, frac in SEGMENT_MASS:
        if a in roles and b in roles:
            pts.append(pos[:, roles[a]] + frac * (pos[:, roles[b]] - pos[:, roles[a]]))
            masses.append(mass)
    return np.stack(pts, axis=1), np.array(masses)


def foot_joints(motion, positions: np.ndarray | None = None) -> np.ndarray:
    """T×2×3 HUMOS foot joints (SMPL's L_Foot/R_Foot, the ball of the foot): the toe role, the ankle
    on a skeleton without toes."""
    roles = role_indices(motion)
    pos = motion.positions() if positions is None else positions
    return np.stack([pos[:, roles.get(f"{s}_toe", roles[f"{s}_ankle"])] for s in ("l", "r")], axis=1)


def segment_com(motion, positions: np.ndarray | None = None) -> np.ndarray:
    """Whole-body centre of mass (T×3) from joint positions and Winter's segment masses."""
    pts, masses = segment_points(motion, positions)
    return (pts * masses[:, None]).sum(axis=1) / masses.sum()


def _belt(motion) -> float:
    return float(motion.metadata.get("belt_speed_mps", 0.0)) if motion.metadata.get("treadmill") else 0.0


def flat_sole(points: np.ndarray, half_width: float = FOOT_HALF_WIDTH_M) -> np.ndarray:
    """A skeleton's sole (T×P×3 points along the foot, heel first, toe tip last) widened into a flat
    plate: each point also ± ``half_width`` sideways, horizontally and at its own height (a foot
    bearing weight stands on its whole width; turning the width with the ankle's roll left one
    edge of the capture's feet in the air in most of their stance).

    >>> line = np.array([[[0.0, 0.0, 0.0], [0.0, 0.0, 0.2]]])        # heel to toe along +z
    >>> flat_sole(line)[0].round(3).tolist()
    [[0.045, 0.0, 0.0], [0.045, 0.0, 0.2], [-0.045, 0.0, 0.0], [-0.045, 0.0, 0.2]]
    """
    fwd = points[:, -1] - points[:, 0]
    lateral = np.stack([fwd[:, 2], np.zeros(len(fwd)), -fwd[:, 0]], axis=1)
    lateral /= np.maximum(np.linalg.norm(lateral, axis=1, keepdims=True), 1e-9)
    side = lateral[:, None] * half_width
    return np.concatenate([points + side, points - side], axis=1)


def plausibility_from_joints(motion) -> dict:
    """Plausibility on the skeleton alone: its sole points (heel, ball, toe tip; for the base of
    support a foot-wide flat plate, :func:`flat_sole`) and its joints."""
    grot, gpos = motion.global_transforms()
    pts = sole_points(motion)
    sole = {s: flat_sole(sole_positions(grot, gpos, pts[s])) for s in ("l", "r")}
    lowest = np.minimum(gpos[:, :, 1].min(axis=1), np.min([v[:, :, 1].min(axis=1) for v in sole.values()], axis=0))
    segments, masses = segment_points(motion, gpos)
    return plausibility(sole, lowest, foot_joints(motion, gpos), segments, masses, motion.fps, _belt(motion),
                        periodic=bool(motion.metadata.get("looped")))


def plausibility_from_mesh(vertices: np.ndarray, foot_vertices: dict[str, np.ndarray], motion) -> dict:
    """Plausibility of ``motion`` skinned on a body: T×V×3 ``vertices``, per-foot vertex index arrays
    (every vertex of the sole region); the HUMOS foot joints and Winter's segments from the rig's
    joints (``motion`` is on the body's rig)."""
    gpos = motion.positions()
    segments, masses = segment_points(motion, gpos)
    sole = {s: vertices[:, idx] for s, idx in foot_vertices.items()}
    return plausibility(sole, vertices[:, :, 1].min(axis=1), foot_joints(motion, gpos), segments, masses,
                        motion.fps, _belt(motion), periodic=bool(motion.metadata.get("looped")))
