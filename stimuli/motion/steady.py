"""Where an overground capture walks or runs steadily and straight: the time ranges a loop can use.

A capture of a walk rarely is one steady walk: it starts from standing, speeds up, curves, stops,
turns on the spot. :func:`capture_segments` labels the whole clip as consecutive time ranges
(:class:`Segment`): ``standing``, ``turning on the spot``, ``turning``, ``speeding up``, ``slowing
down`` and the steady ``walk`` or ``run`` ranges, each with its mean speed, heading change, cadence
and steps. :func:`steady_segments` keeps the steady ones (of one gait, if asked);
``loop.capture_loop`` makes a treadmill loop from the longest of them.

The signals are the pelvis's horizontal velocity and the hips' facing direction, each averaged
over ``SMOOTH_S`` (in seconds, so any frame rate reads alike). Every threshold is in m/s or deg/s:

* ``MIN_SPEED_MPS = 0.2``: the slowest gait the protocol accepts (``SPEED_RANGE_MPS``); a captured
  actor standing and shifting weight moves the pelvis 0.02–0.15 m/s (measured on CMU 131_02 and
  06_10), a slow stylised walk 0.2–0.35 m/s (131_02).
* ``TURN_DEG_S = 20``: straight walks and runs of the captures in ``shared/data/mocap`` read at most
  15 deg/s after the 1-s average (the pelvis yaws ±5–10° every step); turning on the spot reads
  50–90 deg/s and a corridor corner (90° in two steps) about 45 deg/s. A slower curve is accepted
  and straightened by the loop (it drifts less than 20° per second).
* ``SPEED_TOL = 0.10``: a steady range keeps its smoothed speed within ±10 % of its mean. Steady
  overground walking varies 2–4 % stride to stride (coefficient of variation), so ±10 % is about
  three of those; a start, a stop or a deliberate change of pace leaves the band.
* ``MIN_RANGE_S = 0.4``: a label held for less than that (under one walking step) is merged into its
  neighbours, so a single yaw of the pelvis does not split a walk.

The gait comes from flight phases (:func:`flight_fraction`): a walk always has a foot planted, a
run has phases with neither foot on the ground (Alexander 1989, *Physiol. Rev.* 69:1199). Zeni et
al.'s (2008) toe offs were tried for the duty factor and rejected: on the stylised slow walk
(131_02) they read 0.26, on the CMU run 0.52 — the wrong side of 0.5 both times. Steps and whole
cycles count Zeni heel strikes inside the range.

Examples
--------
>>> import numpy as np
>>> from stimuli.motion.motion import Motion
>>> still = Motion(fps=30.0, joint_names=["pelvis", "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle"],
...                parents=[-1, 0, 1, 2, 0, 4, 5], offsets=[[0, 0, 0], [0.1, 0, 0], [0, -0.45, 0], [0, -0.42, 0],
...                [-0.1, 0, 0], [0, -0.45, 0], [0, -0.42, 0]], rotations=np.tile([1.0, 0, 0, 0], (60, 7, 1)),
...                root_translation=np.tile([0, 0.95, 0], (60, 1)))
>>> [s.describe() for s in capture_segments(still)]
['standing 0.0–2.0 s']
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import uniform_filter1d

from stimuli.errors import StimuliError
from stimuli.motion.events import facing, gait_events
from stimuli.motion.skeleton import role_indices

SMOOTH_S = 1.0            # about one walking stride (two steps at 120 steps/min): the within-stride sway averages out
MIN_SPEED_MPS = 0.2       # the protocol's slowest gait; a standing actor's pelvis moves 0.02-0.15 m/s
TURN_DEG_S = 20.0         # straight gaits read <= 15 deg/s, turning on the spot 50-90 deg/s
SPEED_TOL = 0.10          # about 3x the 2-4 % stride-to-stride speed variation of steady walking
MIN_RANGE_S = 0.4         # shorter than one walking step: merged into its neighbours
STILL_FRACTION = 0.2      # a planted foot moves < 20 % of the body's speed (a swinging foot 100-300 %)
STILL_MPS = 0.3           # ... and < 0.3 m/s at the slowest walks (the contact speed of events.contacts)
RUN_FLIGHT = 0.15         # walks here read 0-0.12 'no foot still', jogs and runs 0.24-0.65
RUNNING_GAITS = ("jog", "run")
GAITS = ("walk",) + RUNNING_GAITS


@dataclass
class Segment:
    """One labelled time range of a capture (seconds from the capture's first frame).

    ``kind`` is ``walk`` or ``run`` for a steady straight range (``steady`` true), else ``standing``,
    ``turning on the spot``, ``turning``, ``speeding up`` or ``slowing down``. ``steps`` counts heel
    strikes of either foot inside the range, ``cadence_spm`` steps per minute between the first and
    last heel strike; ``cycles`` the whole strides that fit in the range once one stride (heel strike to heel strike
    of one foot) has been seen in it; ``flight`` is :func:`flight_fraction` (walk ≤ ``RUN_FLIGHT`` <
    run). ``start``/``stop`` are frames ([start, stop), ``end_s`` the last frame's time); ``hs`` the heel strikes per foot.
    """

    start_s: float
    end_s: float
    kind: str
    speed_mps: float
    heading_change_deg: float
    start: int = 0
    stop: int = 0
    steps: int = 0
    cycles: int = 0
    cadence_spm: float = float("nan")
    speed_from_mps: float = float("nan")
    speed_to_mps: float = float("nan")
    flight: float = float("nan")
    hs: dict = field(default_factory=dict, repr=False)

    @property
    def steady(self) -> bool:
        return self.kind in ("walk", "run")

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s

    def matches(self, gait: str | None) -> bool:
        """A steady range of the requested gait: walk, or a running gait for jog/run (None: any)."""
        if not self.steady:
            return False
        return gait is None or (self.kind == "walk") == (gait == "walk")

    def describe(self) -> str:
        """The range in words, e.g. ``walk 0.8–3.1 s at 1.2 m/s, 2 steps (0 whole cycles)``."""
        span = f"{self.start_s:.1f}–{self.end_s:.1f} s"
        if self.kind == "standing":
            return f"standing {span}"
        if self.kind == "turning on the spot":
            return f"turning on the spot {span} ({abs(self.heading_change_deg):.0f}°)"
        if self.kind == "turning":
            return f"turning {span} at {self.speed_mps:.1f} m/s ({abs(self.heading_change_deg):.0f}°)"
        if self.kind in ("speeding up", "slowing down"):
            return f"{self.kind} {span} ({self.speed_from_mps:.1f}→{self.speed_to_mps:.1f} m/s)"
        return (f"{self.kind} {span} at {self.speed_mps:.2f} m/s, {self.steps} step{'s' * (self.steps != 1)} "
                f"({self.cycles} whole cycle{'s' * (self.cycles != 1)})")


def check_gait(gait: str | None) -> None:
    """StimuliError unless ``gait`` is None, walk, jog or run."""
    if gait is not None and gait not in GAITS:
        raise StimuliError(f"gait {gait!r}: expected one of {', '.join(GAITS)}")


def _window(fps: float, seconds: float) -> int:
    return max(int(round(seconds * fps)), 1)


def path_signals(motion, positions: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Per frame: smoothed horizontal pelvis speed (m/s), facing yaw (rad, unwrapped, smoothed) and
    yaw rate (deg/s), all averaged over ``SMOOTH_S``."""
    pos = motion.positions() if positions is None else positions
    roles = role_indices(motion)
    w = _window(motion.fps, SMOOTH_S)
    pelvis = pos[:, roles["pelvis"]][:, [0, 2]]
    vel = np.gradient(pelvis, 1.0 / motion.fps, axis=0) if motion.n_frames > 1 else np.zeros_like(pelvis)
    vel = uniform_filter1d(vel, w, axis=0, mode="nearest")
    fwd = facing(pos, roles)
    yaw = uniform_filter1d(np.unwrap(np.arctan2(fwd[:, 0], fwd[:, 2])), w, mode="nearest")
    rate = np.degrees(np.gradient(yaw, 1.0 / motion.fps)) if motion.n_frames > 1 else np.zeros(1)
    return {"speed": np.linalg.norm(vel, axis=1), "yaw": yaw, "yaw_rate": rate}


def _runs(labels: np.ndarray) -> list[list[int]]:
    """Consecutive equal labels as [label, start, stop) triples."""
    edges = np.flatnonzero(np.diff(labels)) + 1
    starts = np.r_[0, edges]
    stops = np.r_[edges, len(labels)]
    return [[int(labels[a]), int(a), int(b)] for a, b in zip(starts, stops)]


def _merge_short(runs: list[list[int]], min_frames: int) -> list[list[int]]:
    """Give each run shorter than ``min_frames`` to its longer neighbour, shortest first."""
    runs = [r[:] for r in runs]
    while len(runs) > 1:
        lengths = [b - a for _, a, b in runs]
        i = int(np.argmin(lengths))
        if lengths[i] >= min_frames:
            break
        left = lengths[i - 1] if i > 0 else -1
        right = lengths[i + 1] if i + 1 < len(runs) else -1
        j = i - 1 if left >= right else i + 1
        runs[j][1], runs[j][2] = min(runs[j][1], runs[i][1]), max(runs[j][2], runs[i][2])
        del runs[i]
        # neighbours that now share a label become one run
        merged: list[list[int]] = []
        for r in runs:
            if merged and merged[-1][0] == r[0]:
                merged[-1][2] = r[2]
            else:
                merged.append(r)
        runs = merged
    return runs


def longest_steady_window(speed: np.ndarray, tol: float = SPEED_TOL) -> tuple[int, int]:
    """Longest [a, b) whose values stay within ±``tol`` of a common centre (max/min ≤ (1+tol)/(1−tol)).

    >>> longest_steady_window(np.array([0.3, 1.0, 1.1, 1.05, 0.9, 2.0]))
    (1, 5)
    """
    ratio = (1 + tol) / (1 - tol)
    best, a = (0, 0), 0
    hi: list[int] = []   # indices of a decreasing run of maxima (monotonic deques)
    lo: list[int] = []
    for b, v in enumerate(speed):
        while hi and speed[hi[-1]] <= v:
            hi.pop()
        hi.append(b)
        while lo and speed[lo[-1]] >= v:
            lo.pop()
        lo.append(b)
        while speed[hi[0]] > ratio * speed[lo[0]]:
            a += 1
            if hi[0] < a:
                hi.pop(0)
            if lo[0] < a:
                lo.pop(0)
        if b + 1 - a > best[1] - best[0]:
            best = (a, b + 1)
    return best


def _split_by_speed(speed: np.ndarray, a: int, b: int, min_frames: int) -> list[tuple[str, int, int]]:
    """A moving straight range as steady and speed-changing parts (steady ones at least ``min_frames``)."""
    if b - a <= 0:
        return []
    s, e = longest_steady_window(speed[a:b])
    # a leftover too short to be a range of its own belongs to the steady part
    s = 0 if s < min_frames else s
    e = b - a if b - a - e < min_frames else e
    if e - s < min_frames:
        trend = "speeding up" if speed[b - 1] >= speed[a] else "slowing down"
        return [(trend, a, b)]
    return (_split_by_speed(speed, a, a + s, min_frames) + [("steady", a + s, a + e)]
            + _split_by_speed(speed, a + e, b, min_frames))


def flight_fraction(motion, positions: np.ndarray, speed_mps: float) -> float:
    """Fraction of frames in which no foot is still: both feet's slowest point (ankle or toe) move
    horizontally faster than ``STILL_FRACTION`` of the body's speed (and than ``STILL_MPS``).

    A walk always has a foot planted (single or double support): only the heel-to-toe roll at the
    changeover reads as 'no foot still' (0–12 % of frames on the walks in ``shared/data/mocap``). A
    run's flight phases leave neither foot still (24–65 % on its jogs and runs).
    """
    from stimuli.motion.events import foot_points
    from stimuli.motion.metrics import lowpass

    # Low-passed at 6 Hz first (as gait labs filter marker data): differentiated raw, a 120-fps
    # capture's 2 mm marker jitter alone reads 0.2–0.6 m/s on a planted foot, and an unseen
    # 1.6 m/s walk (Poser names, 120 fps) read 54 % 'flight' and was taken for a run.
    feet = [lowpass(f, motion.fps) for f in foot_points(motion, positions).values()]
    vel = np.stack([np.gradient(f[..., [0, 2]], 1.0 / motion.fps, axis=0) for f in feet])
    slowest = np.linalg.norm(vel, axis=-1).min(axis=-1)          # per foot and frame
    return float(np.mean(slowest.min(axis=0) > max(STILL_FRACTION * speed_mps, STILL_MPS)))


def _gait_counts(motion, positions: np.ndarray, a: int, b: int) -> dict:
    """Heel strikes (frames of the capture, per foot), steps, whole cycles and cadence of frames [a, b)."""
    out = {"steps": 0, "cycles": 0, "cadence_spm": float("nan"), "hs": {"l": np.array([], int), "r": np.array([], int)}}
    if b - a < 4:
        return out
    ev = gait_events(motion, positions[a:b])
    strikes = np.sort(np.r_[ev["l_hs"], ev["r_hs"]])
    out["steps"] = int(len(strikes))
    out["hs"] = {s: np.sort(ev[f"{s}_hs"]) + a for s in ("l", "r")}
    gaps = np.concatenate([np.diff(v) for v in out["hs"].values()])
    # Whole cycles: how many strides fit in the range, once a stride (heel strike to heel strike of
    # one foot) has been seen in it; Zeni misses the strikes in the range's first and last frames.
    out["cycles"] = int((b - a - 1) // np.median(gaps)) if len(gaps) else 0
    if len(strikes) >= 2:
        out["cadence_spm"] = float(60.0 * (len(strikes) - 1) / ((strikes[-1] - strikes[0]) / motion.fps))
    return out


def capture_segments(motion, positions: np.ndarray | None = None) -> list[Segment]:
    """The whole capture as consecutive labelled time ranges (see the module docstring)."""
    pos = motion.positions() if positions is None else positions
    sig = path_signals(motion, pos)
    fps = motion.fps
    moving = sig["speed"] >= MIN_SPEED_MPS
    turning = np.abs(sig["yaw_rate"]) > TURN_DEG_S
    # 0 standing, 1 turning on the spot, 2 turning while moving, 3 moving straight
    labels = np.where(moving, np.where(turning, 2, 3), np.where(turning, 1, 0))
    runs = _merge_short(_runs(labels), _window(fps, MIN_RANGE_S))
    names = {0: "standing", 1: "turning on the spot", 2: "turning"}
    parts: list[tuple[str, int, int]] = []
    for label, a, b in runs:
        if label == 3:
            parts += _split_by_speed(sig["speed"], a, b, _window(fps, MIN_RANGE_S))
        else:
            parts.append((names[label], a, b))
    segments = []
    for kind, a, b in parts:
        last = b - 1
        seg = Segment(start_s=a / fps, end_s=last / fps, kind=kind, start=a, stop=b,
                      speed_mps=float(sig["speed"][a:b].mean()),
                      heading_change_deg=float(np.degrees(sig["yaw"][last] - sig["yaw"][a])),
                      speed_from_mps=float(sig["speed"][a]), speed_to_mps=float(sig["speed"][last]))
        if kind == "steady":
            counts = _gait_counts(motion, pos, a, b)
            seg.steps, seg.cycles, seg.cadence_spm, seg.hs = (counts[k] for k in ("steps", "cycles", "cadence_spm", "hs"))
            seg.flight = flight_fraction(motion, pos[a:b], seg.speed_mps)
            seg.kind = "run" if seg.flight > RUN_FLIGHT else "walk"
        segments.append(seg)
    return segments


def steady_segments(motion, gait: str | None = None, positions: np.ndarray | None = None) -> list[Segment]:
    """The steady, straight ranges of a capture (of ``gait``: walk, or jog/run for a running gait).

    >>> from pathlib import Path
    >>> from stimuli.motion.bvh import read_bvh
    >>> walk = read_bvh(Path(__file__).resolve().parents[1] / "data" / "cmu_35_01_walk.bvh")
    >>> [s.describe() for s in steady_segments(walk, "walk")]
    ['walk 0.0–3.0 s at 1.29 m/s, 4 steps (2 whole cycles)']
    """
    check_gait(gait)
    return [s for s in capture_segments(motion, positions) if s.matches(gait)]
