"""Whole gait cycles, seamless loops and treadmill display.

* :func:`face_forward` turns a motion about the vertical so that it progresses along +z.
* :func:`to_treadmill` removes the root's forward progression (a straight-line fit) and records
  it as the belt speed, so a planted foot moves backwards at belt speed.
* :func:`trim_cycles` keeps whole gait cycles (left heel strike to left heel strike, inclusive).
* :func:`make_loop` closes a trimmed clip: a cubic Hermite correction spread over the clip makes
  the last frame continue into the first in both pose and velocity; the duplicate end frame is
  dropped so that playing the clip on repeat has no seam.
* :func:`seam_error` measures how smooth the wrap-around is compared with the clip's interior.
* :func:`cycles_for_clip` is the whole number of gait cycles that best fills a clip.
* :func:`capture_loop` makes a treadmill loop from an overground capture: the longest steady,
  straight range of the requested gait (``steady.capture_segments``), the whole cycles in it whose
  ends match best, heading drift removed (:func:`turn_path`), put on the belt at its own speed; a
  capture without such a range is refused, naming the ranges it holds.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from stimuli.errors import StimuliError
from stimuli.motion import quat
from stimuli.motion.events import cycle_starts, gait_events
from stimuli.motion.motion import Motion
from stimuli.motion.skeleton import role_indices
from stimuli.motion.steady import capture_segments, check_gait

UP = np.array([0.0, 1.0, 0.0])


def rotate_world(motion: Motion, q: np.ndarray) -> Motion:
    """Rotate the whole motion about the world origin by ``q`` (root rotation and translation)."""
    rot = motion.rotations.copy()
    rot[:, 0] = quat.mul(q, rot[:, 0])
    return motion.replace(rotations=rot, root_translation=quat.rotate(q, motion.root_translation))


def face_forward(motion: Motion) -> Motion:
    """Turn the motion about y so that the walker faces (and progresses along) +z."""
    fwd = gait_events(motion)["forward"]
    yaw = np.arctan2(fwd[0], fwd[2])
    q = quat.from_axis_angle(UP * -yaw)
    return rotate_world(motion, q)


def to_treadmill(motion: Motion) -> Motion:
    """Remove forward and sideways progression of the root; record the belt speed (m/s).

    The motion is first turned to face +z. The root's horizontal path is fitted by a straight line
    in time; its slope along +z is the belt speed, and the fitted line is subtracted so the body
    stays in place (its mean horizontal position at the origin).
    """
    motion = face_forward(motion)
    t = np.arange(motion.n_frames) / motion.fps
    root = motion.root_translation.copy()
    belt = 0.0
    for axis in (0, 2):
        slope, intercept = np.polyfit(t, root[:, axis], 1) if motion.n_frames > 1 else (0.0, root[0, axis])
        root[:, axis] -= slope * t + intercept
        if axis == 2:
            belt = float(slope)
    out = motion.replace(root_translation=root)
    out.metadata.update(treadmill=True, belt_speed_mps=belt,
                        speed_mps=belt if "speed_mps" not in motion.metadata else motion.metadata["speed_mps"])
    out.metadata["belt_speed_mps"] = belt
    return out


def trim_cycles(motion: Motion, cycles: int | None = None) -> Motion:
    """Frames from one left heel strike to the heel strike ``cycles`` later, both included.

    ``cycles=None`` keeps as many whole cycles as the clip holds. StimuliError when the clip is
    shorter than the cycles asked for.
    """
    hs = cycle_starts(motion)
    available = len(hs) - 1
    n = available if cycles is None else int(cycles)
    if n < 1 or n > available:
        raise StimuliError(f"{motion.metadata.get('source', 'motion')}: asked for {n} whole gait cycle(s), "
                           f"the clip holds {available}")
    out = motion.slice(int(hs[0]), int(hs[n]) + 1)
    out.metadata["cycles"] = n
    return out


def _hermite(n: int, window: int) -> tuple[np.ndarray, np.ndarray]:
    """Hermite basis over ``n`` frames: h01 (position, spread over the clip) and h11 (end tangent,
    in frames, confined to the last ``window`` frames so a velocity mismatch is fixed locally)."""
    s = np.linspace(0.0, 1.0, n)
    h01 = -2 * s**3 + 3 * s**2
    u = np.clip((np.arange(n) - (n - 1 - window)) / window, 0.0, 1.0)
    h11 = (u**3 - u**2) * window
    return h01, h11


def close_loop(motion: Motion) -> Motion:
    """Make frame T−1 equal frame 0 in pose and velocity, then drop it (see module docstring)."""
    t = motion.n_frames
    if t < 4:
        raise StimuliError("motion: a loop needs at least 4 frames")
    window = int(np.clip(round(0.2 * motion.fps), 3, max((t - 1) // 2, 3)))
    h01, h11 = _hermite(t, window)
    span = 1
    # Velocities at the seam from each side, by second-order one-sided differences: for a smooth
    # periodic motion both estimate the same velocity (first differences would differ by one
    # frame of acceleration, which the correction would then amplify over the whole clip).
    x = motion.root_translation
    dx = x[0] - x[-1]
    v0 = (-3 * x[0] + 4 * x[1] - x[2]) / 2
    vt = (3 * x[-1] - 4 * x[-2] + x[-3]) / 2
    root = x + h01[:, None] * dx + h11[:, None] * span * (v0 - vt)
    # Rotations: the same correction in the tangent space (rotation vectors) of each joint.
    q = quat.unroll(motion.rotations)

    def log(a, b):
        return quat.to_axis_angle(quat.mul(quat.inv(a), b))

    d = log(q[-1], q[0])
    w0 = (4 * log(q[0], q[1]) - log(q[0], q[2])) / 2
    wt = (-4 * log(q[-1], q[-2]) + log(q[-1], q[-3])) / 2
    corr = h01[:, None, None] * d + h11[:, None, None] * span * (w0 - wt)
    rot = quat.mul(q, quat.from_axis_angle(corr))
    closed = motion.replace(rotations=rot[:-1], root_translation=root[:-1])
    closed.metadata["looped"] = True
    return closed


def repeat(motion: Motion, times: int) -> Motion:
    """A looped clip played ``times`` times in a row (root translation continued)."""
    if times <= 1:
        return motion
    rot = np.concatenate([motion.rotations] * times)
    root = np.concatenate([motion.root_translation] * times)
    if not motion.metadata.get("treadmill"):
        step = motion.root_translation[-1] - motion.root_translation[0]
        step = step + (motion.root_translation[-1] - motion.root_translation[-2])
        step[1] = 0.0
        root = root + np.repeat(np.arange(times), motion.n_frames)[:, None] * step
    out = motion.replace(rotations=rot, root_translation=root)
    out.metadata["cycles"] = int(motion.metadata.get("cycles", 1)) * times
    return out


def cycles_for_clip(duration_s: float, cadence_spm: float) -> int:
    """Whole gait cycles (two steps each) closest to filling ``duration_s`` at ``cadence_spm``.

    A looping clip holds whole cycles, so the renderer retimes the motion by the rounding (walk
    112 steps/min in 4 s: 4 cycles, played 7 % fast; jog 138: 5 cycles, 9 % fast). A motion made
    with another number of cycles is retimed further: a 2-cycle jog loop played twice in 4 s
    runs 13 % slow, at the walk's 120 steps/min.

    >>> cycles_for_clip(4.0, 112), cycles_for_clip(4.0, 138)
    (4, 5)
    """
    return max(1, int(round(duration_s * cadence_spm / 120.0)))


def make_loop(motion: Motion, cycles: int | None = None, treadmill: bool = True) -> Motion:
    """Trim to whole cycles, optionally put on a treadmill, close the loop.

    If the clip holds fewer cycles than asked for, the cycles it holds are looped and repeated
    (``cycles`` must then be a multiple of them).
    """
    hs = cycle_starts(motion)
    available = len(hs) - 1
    want = available if cycles is None else int(cycles)
    use = want if want <= available else max(k for k in range(1, available + 1) if want % k == 0)
    clip = trim_cycles(motion, use)
    fps = clip.fps
    # Cadence of the trimmed clip: two steps per cycle over its span.
    cadence = 120.0 * use / ((clip.n_frames - 1) / fps)
    if treadmill:
        clip = to_treadmill(clip)
    looped = close_loop(clip)
    looped.metadata.update(cycles=use, cadence_spm=float(cadence))
    return repeat(looped, want // use)


def retime(motion: Motion, factor: float) -> Motion:
    """Play ``factor`` times faster (cadence × factor) at the same frame rate; speed × factor."""
    if factor <= 0:
        raise StimuliError(f"retime: factor must be > 0, got {factor}")
    span = motion.n_frames / motion.fps / factor
    n = max(int(round(span * motion.fps)), 2)
    # Sample the periodic clip: times wrap so the loop stays closed.
    src_t = (np.arange(n) / motion.fps * factor)
    rot, root = sample_periodic(motion, src_t) if motion.metadata.get("looped") else motion.sample(src_t)
    out = motion.replace(rotations=rot, root_translation=root)
    for key in ("cadence_spm", "speed_mps", "belt_speed_mps"):
        if key in motion.metadata:
            out.metadata[key] = float(motion.metadata[key]) * factor
    return out


def sample_periodic(motion: Motion, times: np.ndarray):
    """Sample a looped clip at times in [0, duration): the last frame blends into the first."""
    f = np.asarray(times) * motion.fps % motion.n_frames
    i0 = np.floor(f).astype(int) % motion.n_frames
    i1 = (i0 + 1) % motion.n_frames
    a = f - np.floor(f)
    rot = quat.slerp(motion.rotations[i0], motion.rotations[i1], np.repeat(a[:, None], motion.n_joints, 1))
    r0, r1 = motion.root_translation[i0], motion.root_translation[i1]
    if not motion.metadata.get("treadmill"):
        # Crossing the seam of an overground loop: continue from the end rather than jump back.
        jump = (motion.root_translation[-1] - motion.root_translation[0])
        r1 = np.where((i1 == 0)[:, None], r1 + jump + (motion.root_translation[-1] - motion.root_translation[-2]), r1)
    root = r0 * (1 - a[:, None]) + r1 * a[:, None]
    return rot, root


def seam_error(motion: Motion) -> dict:
    """How smooth the wrap-around of a looped clip is.

    Treats the clip as periodic and compares the joints' second differences (acceleration × dt²)
    at the seam with the 99th percentile inside the clip. Overground clips are measured relative to
    the root's horizontal position. Returns metres and the ratio (≈ 1 or less: seamless).
    """
    p = motion.positions()
    if not motion.metadata.get("treadmill"):
        p = p - motion.root_translation[:, None, :] * np.array([1.0, 0.0, 1.0])
    acc = np.linalg.norm(np.roll(p, -1, 0) - 2 * p + np.roll(p, 1, 0), axis=-1).max(axis=1)
    seam = float(max(acc[0], acc[-1]))
    interior = float(np.percentile(acc[1:-1], 99)) if len(acc) > 3 else seam
    jump = float(np.linalg.norm(p[0] - p[-1], axis=-1).max())
    step = float(np.percentile(np.linalg.norm(np.diff(p, axis=0), axis=-1).max(axis=1), 99))
    return {"seam_accel_m": seam, "interior_accel_p99_m": interior, "ratio": seam / max(interior, 1e-12),
            "seam_step_m": jump, "interior_step_p99_m": step}


def cycle_seams(motion: Motion, cycles: int | None = None) -> dict:
    """How smooth the joins between the repeated cycles of a looped clip are.

    :func:`seam_error` compares the wrap-around with the clip's 99th percentile, which in a clip of
    4 or 5 repeated cycles holds the other joins too. This takes one cycle (``cycles``, default the
    metadata's) as periodic and divides the root's second difference at the join (the two frames
    either side) by its largest inside the cycle, and the largest change of a joint's angular step
    there by the largest inside: ratios ≈ 1 or less are seamless.

    >>> from stimuli.motion.generate import GaitParams, generate
    >>> seams = cycle_seams(generate(GaitParams(), 1.75, fps=30, cycles=2))
    >>> seams["root_ratio"] < 1.5 and seams["joint_ratio"] < 1.5
    True
    """
    cycles = int(cycles or motion.metadata.get("cycles", 1) or 1)
    n = motion.n_frames // cycles
    root = motion.root_translation[:n]
    rot = quat.unroll(motion.rotations[:n])
    root_acc = np.linalg.norm(np.roll(root, -1, 0) - 2 * root + np.roll(root, 1, 0), axis=1)
    step = quat.angle(quat.mul(quat.inv(rot), np.roll(rot, -1, 0)))
    joint_acc = np.abs(step - np.roll(step, 1, 0)).max(axis=1)
    # A jump between two frames shows in the second differences at both: frames next to the join count
    # as the join (a jump one frame before it is still the join's).
    join = [-2, -1, 0, 1]
    return {"root_ratio": float(root_acc[join].max() / max(root_acc[2:-2].max(), 1e-12)),
            "joint_ratio": float(joint_acc[join].max() / max(joint_acc[2:-2].max(), 1e-12)),
            "root_accel_m": float(root_acc[join].max())}


# Seam matching: a velocity mismatch of v (m/s) costs like a position mismatch of v × SEAM_TAU_S,
# about the half-width of close_loop's 0.2-s velocity correction over which it is spread.
SEAM_TAU_S = 0.1
# Heel strikes (Zeni) are found within a frame or two; the loop's end may move this far from the
# heel strike for a closer pose match (a whole cycle stays whole within 0.05 s).
SEAM_SLACK_S = 0.05


def turn_path(motion: Motion, yaw: np.ndarray) -> Motion:
    """Turn each frame by ``yaw[t]`` radians about the vertical through the root and re-trace the
    root's horizontal path from the turned frame-to-frame steps (a curve becomes straight when
    ``yaw`` undoes its heading change; a straight walk curves when it adds one).

    >>> import numpy as np
    >>> line = Motion(fps=10.0, joint_names=["root"], parents=[-1], offsets=[[0, 0, 0]],
    ...               rotations=np.tile([1.0, 0, 0, 0], (3, 1, 1)), root_translation=[[0, 1, 0], [0, 1, 1], [0, 1, 2]])
    >>> turn_path(line, np.full(3, np.pi / 2)).root_translation.round(6).tolist()
    [[0.0, 1.0, 0.0], [1.0, 1.0, 0.0], [2.0, 1.0, 0.0]]
    """
    yaw = np.asarray(yaw, float)
    turns = quat.from_axis_angle(UP[None] * yaw[:, None])
    rot = motion.rotations.copy()
    rot[:, 0] = quat.mul(turns, rot[:, 0])
    root = motion.root_translation
    mid = quat.from_axis_angle(UP[None] * ((yaw[1:] + yaw[:-1]) / 2)[:, None])
    steps = quat.rotate(mid, np.diff(root, axis=0))
    path = np.concatenate([root[:1], root[:1] + np.cumsum(steps, axis=0)])
    return motion.replace(rotations=rot, root_translation=path)


def facing_yaw(motion: Motion, positions: np.ndarray | None = None) -> np.ndarray:
    """Per-frame facing direction of the hips about the vertical (radians, unwrapped; 0 = +z)."""
    from stimuli.motion.events import facing

    pos = motion.positions() if positions is None else positions
    fwd = facing(pos, role_indices(motion))
    return np.unwrap(np.arctan2(fwd[:, 0], fwd[:, 2]))


def remove_heading_drift(motion: Motion, cycles: int) -> tuple[Motion, float]:
    """Turn a clip of ``cycles`` whole cycles so that it travels along one constant direction;
    returns it and the mean drift removed (deg/s).

    The root's path is averaged over one stride (a moving window of one cycle), which removes each
    step's sideways sway; a quadratic in time fitted to what is left is the slow curve, and each
    frame is turned back by its direction's departure from the mean direction, so the path becomes
    straight. One cycle holds no curve to tell from the sway: it is only faced forward (the belt's
    straight-line fit removes a constant sideways drift).
    """
    if cycles < 2:
        return motion, 0.0
    t = np.arange(motion.n_frames) / motion.fps
    w = max(int(round((motion.n_frames - 1) / cycles)), 1)
    kernel = np.ones(w) / w
    tc = np.convolve(t, kernel, mode="valid")
    root = motion.root_translation
    dx, dz = (np.polyval(np.polyder(np.polyfit(tc, np.convolve(root[:, k], kernel, mode="valid"), 2)), t)
              for k in (0, 2))
    heading = np.unwrap(np.arctan2(dx, dz))
    turned = turn_path(motion, -(heading - heading.mean()))
    return turned, float(np.degrees(heading[-1] - heading[0]) / max(t[-1], 1e-9))


def _seam_features(motion: Motion, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Role joints in the facing frame: positions relative to the pelvis's ground point, and
    velocities (m/s), so that poses compare wherever and whichever way the walker goes."""
    roles = role_indices(motion)
    joints = sorted(set(roles.values()))
    p = positions[:, joints]
    yaw = facing_yaw(motion, positions)
    undo = quat.from_axis_angle(UP[None] * -yaw[:, None])[:, None]
    ground = positions[:, roles["pelvis"]] * np.array([1.0, 0.0, 1.0])
    local = quat.rotate(undo, p - ground[:, None])
    vel = quat.rotate(undo, np.gradient(p, 1.0 / motion.fps, axis=0))
    return local, vel


def stride_frames(strikes: dict) -> float:
    """Median frames from one heel strike to the next of the same foot."""
    gaps = np.concatenate([np.diff(np.sort(v)) for v in strikes.values()] + [np.zeros(0)])
    if not len(gaps):
        raise StimuliError("motion: no whole gait cycle (fewer than two heel strikes of one foot)")
    return float(np.median(gaps))


def best_cycles(motion: Motion, positions: np.ndarray, strikes: dict, cycles: int, lo: int, hi: int) -> tuple[int, int, float]:
    """First and last frame (inclusive) of ``cycles`` whole cycles within frames [lo, hi) whose ends
    match best (pose + SEAM_TAU_S × velocity, RMS over the role joints), and that mismatch (m).

    A loop may start at any phase of the stride (a seam at heel strike meets the foot's sharpest
    deceleration); it lasts ``cycles`` median strides (heel strike to heel strike of one foot),
    give or take SEAM_SLACK_S where the pose matches better.
    """
    local, vel = _seam_features(motion, positions)
    span = stride_frames(strikes) * cycles
    slack = int(round(SEAM_SLACK_S * motion.fps))
    best = (-1, -1, np.inf)
    for a in range(lo, hi):
        end = int(round(a + span))
        if end - slack > hi - 1:
            break
        ends = np.arange(end - slack, min(end + slack, hi - 1) + 1)
        pose = np.sqrt(np.mean(np.sum((local[ends] - local[a]) ** 2, axis=-1), axis=-1))
        speed = np.sqrt(np.mean(np.sum((vel[ends] - vel[a]) ** 2, axis=-1), axis=-1))
        score = pose + SEAM_TAU_S * speed
        k = int(np.argmin(score))
        if score[k] < best[2]:
            best = (a, int(ends[k]), float(score[k]))
    if best[0] < 0:
        raise StimuliError(f"{motion.metadata.get('source', 'motion')}: frames {lo}–{hi - 1} hold fewer than "
                           f"{cycles} whole gait cycle(s)")
    return best


def _shifted(segment, frames: int, fps: float):
    """A segment of a clip cut ``frames`` into the capture, in the capture's time."""
    return dataclasses.replace(segment, start=segment.start + frames, stop=segment.stop + frames,
                   start_s=segment.start_s + frames / fps, end_s=segment.end_s + frames / fps,
                   hs={k: v + frames for k, v in segment.hs.items()})


def _range_frames(motion: Motion, start_s: float | None, end_s: float | None) -> tuple[int, int]:
    """Frames [a, b) of a hand-chosen time range; StimuliError naming the range when it is not inside."""
    where = motion.metadata.get("source", "motion")
    length = (motion.n_frames - 1) / motion.fps
    lo = 0.0 if start_s is None else float(start_s)
    hi = length if end_s is None else float(end_s)
    if not (0.0 <= lo < hi <= length + 0.5 / motion.fps):
        raise StimuliError(f"{where}: start/end {lo:g}–{hi:g} s: expected 0 ≤ start < end ≤ {length:.2f} s "
                           "(the capture's length)")
    a, b = int(round(lo * motion.fps)), min(int(round(hi * motion.fps)) + 1, motion.n_frames)
    if b - a < 4:
        raise StimuliError(f"{where}: start/end {lo:g}–{hi:g} s holds {b - a} frame(s); a loop needs at least 4")
    return a, b


def capture_loop(motion: Motion, gait: str | None = "walk", start_s: float | None = None,
                 end_s: float | None = None, cycles: int | None = None) -> Motion:
    """A seamless treadmill loop from an overground capture (see the module docstring).

    The longest steady, straight range of ``gait`` (walk; jog or run: a running gait; None: either)
    inside ``start_s``–``end_s`` (default: the whole capture) gives the loop: ``cycles`` whole cycles
    (default: as many as leave half a stride of the range free for choosing the seam, at least one;
    more than the range holds repeats a divisor of them, as :func:`make_loop` does) starting at the heel strike whose cycles close best, heading drift
    removed, forward travel subtracted (the belt speed in metadata). StimuliError naming the
    capture and every range found when no steady range of that gait holds a whole cycle.

    >>> from pathlib import Path
    >>> from stimuli.motion.bvh import read_bvh
    >>> walk = read_bvh(Path(__file__).resolve().parents[1] / "data" / "cmu_35_01_walk.bvh")
    >>> loop = capture_loop(walk, "walk")
    >>> loop.metadata["cycles"], round(loop.metadata["belt_speed_mps"], 1), loop.metadata["capture_range_s"]
    (2, 1.3, [0.617, 2.858])
    """
    check_gait(gait)
    where = motion.metadata.get("source", "motion")
    a, b = _range_frames(motion, start_s, end_s)
    part = motion.slice(a, b) if (a, b) != (0, motion.n_frames) else motion
    pos = part.positions()
    segments = [_shifted(s, a, motion.fps) for s in capture_segments(part, pos)]
    usable = [s for s in segments if s.matches(gait) and s.cycles >= 1]
    if not usable:
        what = "a steady straight " + ("walk or run" if gait is None else "walk" if gait == "walk" else
                                       f"running gait ({gait})")
        chosen = "" if start_s is None and end_s is None else f" between {a / motion.fps:.1f} and {(b - 1) / motion.fps:.1f} s"
        raise StimuliError(f"{where}: no loop: the capture{chosen} holds fewer than one whole gait cycle of {what}. "
                           f"It holds: {'; '.join(s.describe() for s in segments)}. Choose another gait, or a "
                           "range with --start/--end (start_s/end_s in a protocol)")
    seg = max(usable, key=lambda s: (s.duration_s, s.cycles))
    strikes = {k: v - a for k, v in seg.hs.items()}
    # By default as many whole cycles as leave half a stride free to choose where the seam falls.
    free = int((seg.stop - seg.start - 1) / stride_frames(strikes) - 0.5)
    want = max(1, min(free, seg.cycles)) if cycles is None else int(cycles)
    if want < 1:
        raise StimuliError(f"{where}: cycles must be >= 1, got {want}")
    use = want if want <= seg.cycles else max(k for k in range(1, seg.cycles + 1) if want % k == 0)
    first, last, mismatch = best_cycles(part, pos, strikes, use, seg.start - a, seg.stop - a)
    clip, drift = remove_heading_drift(part.slice(first, last + 1), use)
    clip = to_treadmill(clip)
    looped = close_loop(clip)
    looped.metadata.update(
        cycles=use, cadence_spm=float(120.0 * use / ((clip.n_frames - 1) / clip.fps)), gait=seg.kind if gait is None else gait,
        speed_mps=float(clip.metadata["belt_speed_mps"]), heading_drift_deg_s=round(drift, 2),
        capture_range_s=[round((first + a) / motion.fps, 3), round((last + a) / motion.fps, 3)],
        capture_segment=seg.describe(), seam_mismatch_m=round(mismatch, 4))
    return repeat(looped, want // use)
