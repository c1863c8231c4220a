"""Average motion of several actors: DTW alignment of gait cycles and quaternion averaging.

Each input is reduced to one gait cycle (its first whole cycle), described per frame by its joint
positions relative to the pelvis, divided by the skeleton's height (so tall and short actors
compare). The medoid cycle (smallest summed DTW distance to the others, ``dtaidistance``) is the
time reference; every cycle is aligned to it along its DTW warping path, and per reference frame
the matched local rotations are averaged with the sign-invariant quaternion mean (never Euler
angles), the root heights and offsets arithmetically. The averaged cycle is looped (it is
periodic by construction up to the seam correction) and repeated to the requested cycles. This is
the NoCOM condition of Exp 2. When every input carries its foot contacts (metadata ``contacts``,
as generated gaits and cleaned captures do; an input at another frame rate votes from its nearest
frames), the average carries the majority of the matched frames' contacts, so the
display plants its feet when its actors' feet were down rather than guessing from foot heights
(which planted one of the averaged jogs' two flight frames per step).
"""

from __future__ import annotations

import numpy as np

from stimuli.errors import StimuliError
from stimuli.motion import quat
from stimuli.motion.loop import close_loop, repeat
from stimuli.motion.motion import Motion
from stimuli.motion.skeleton import role_indices


def cycle_of(motion: Motion, fps: float | None = None) -> Motion:
    """One gait cycle at ``fps`` (default the motion's), end frame included for looping.

    A looped clip gives the mean of its cycles, each sampled over exactly one cycle's time at the same
    phases (its own frames when a cycle is a whole number of them at its own rate). Its end frame then
    repeats its first: the clip's cycle starts shift onto each other. Before, the first cycle was cut
    at a whole frame: frame 32 of a 129-frame, 4-cycle generated walk (32.25 frames a cycle) stood
    13–27 mm of pelvis away from frame 0; a capture's two looped cycles differ; and a 120-fps loop
    resampled to 30 fps (CMU 35_17: 22.25 frames a cycle) got 23 frames, the last a quarter of a frame
    before the first. The averages of such cycles jumped at every seam.
    Any other clip gives its first whole cycle (heel strike to heel strike).

    >>> from stimuli.motion.generate import GaitParams, generate
    >>> walk = generate(GaitParams(), 1.75, fps=30, cycles=4)
    >>> cycle = cycle_of(walk)
    >>> walk.n_frames, cycle.n_frames, bool(abs(cycle.root_translation[-1] - cycle.root_translation[0]).max() < 1e-9)
    (129, 33, True)
    >>> cycle_of(generate(GaitParams(), 1.75, fps=120, cycles=2), 30.0).n_frames   # 1.07 s: 32 frames at 30 fps, and the end
    33
    """
    from stimuli.motion.events import cycle_starts
    fps = float(fps or motion.fps)
    if not motion.metadata.get("looped"):
        clip = motion if motion.fps == fps else motion.resample(fps)
        hs = cycle_starts(clip)
        return clip.slice(int(hs[0]), int(hs[1]) + 1)
    cycles = max(int(motion.metadata.get("cycles", 1)), 1)
    period = motion.n_frames / cycles                 # in the motion's own frames
    n = max(int(round(period * fps / motion.fps)), 2)
    phase = np.arange(n + 1) * (period / n)
    samples = [_looped_frames(motion, k * period + phase) for k in range(cycles)]
    rots = np.stack([r for r, _ in samples])
    roots = np.stack([x for _, x in samples])
    # Cycles that repeat frame for frame (a generated loop of whole-frame cycles) are kept as they are.
    rot = rots[0] if np.array_equal(rots, np.broadcast_to(rots[:1], rots.shape)) else quat.mean(rots, axis=0)
    root = roots[0] if np.array_equal(roots, np.broadcast_to(roots[:1], roots.shape)) else roots.mean(axis=0)
    return motion.replace(fps=fps, rotations=rot, root_translation=root)


def _looped_frames(motion: Motion, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotations and root of a looped clip at (fractional) frame numbers; past its end it starts
    again (an overground loop's root goes on from where it ended)."""
    from stimuli.motion.loop import sample_periodic

    whole = np.floor(frames).astype(int)
    if not np.array_equal(whole, frames):
        return sample_periodic(motion, frames / motion.fps)
    rot = motion.rotations[whole % motion.n_frames]
    root = motion.root_translation[whole % motion.n_frames].copy()
    if not motion.metadata.get("treadmill"):
        lap = motion.root_translation[-1] - motion.root_translation[0] + (motion.root_translation[-1] - motion.root_translation[-2])
        root += (whole // motion.n_frames)[:, None] * lap
    return rot, root


def features(motion: Motion) -> np.ndarray:
    """Per-frame features for DTW: joint positions relative to the pelvis over stature (T×3K)."""
    roles = role_indices(motion)
    keys = [r for r in sorted(roles) if r != "pelvis"]
    pos = motion.positions()
    rel = pos[:, [roles[k] for k in keys]] - pos[:, [roles["pelvis"]]]
    stature = float(np.ptp(motion.rest_positions()[:, 1])) or 1.0
    return (rel / stature).reshape(len(pos), -1)


def dtw_distance(a: Motion, b: Motion) -> float:
    """DTW distance between the pelvis-relative, height-normalised poses of two motions."""
    return _feature_distance(features(a), features(b))


def _feature_distance(a: np.ndarray, b: np.ndarray) -> float:
    from dtaidistance import dtw_ndim
    return float(dtw_ndim.distance(a.astype(np.double), b.astype(np.double)))


def _path(ref: np.ndarray, other: np.ndarray) -> list[tuple[int, int]]:
    from dtaidistance import dtw_ndim
    return dtw_ndim.warping_path(ref.astype(np.double), other.astype(np.double))


# What an average's own body may record: a human height and BMI (as a protocol's actors have).
BODY_FIELDS = {"height_m": (1.2, 2.3, "m"), "bmi": (12.0, 70.0, "kg/m²")}


def _mean_body(motions: list[Motion]) -> dict:
    """Mean ``height_m`` and ``bmi`` (and the shared ``sex``) of the motions that all record them.

    The average's own body: COM retargeting measures the balance factor b against it. A value that is
    no number or no human figure (a height of 160: centimetres) is an error naming the motion;
    :func:`mean_body_notes` says what the average cannot record.
    """
    out = {}
    for key, (low, high, unit) in BODY_FIELDS.items():
        values = [m.metadata.get(key) for m in motions]
        for i, v in enumerate(values, 1):
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not low <= v <= high):
                raise StimuliError(f"average: motion {i}: metadata {key} is {v!r}; expected a number within "
                                   f"{low:g}–{high:g} {unit}")
        if all(v is not None for v in values):
            out[key] = float(np.mean(values))
    sexes = {m.metadata.get("sex") for m in motions}
    if len(sexes) == 1 and None not in sexes:
        out["sex"] = sexes.pop()
    return out


def mean_body_notes(motions: list[Motion]) -> list[str]:
    """Why an average records no body figure: the motions' sexes differ, or some lack a height or BMI."""
    notes = []
    sexes = [m.metadata.get("sex") for m in motions]
    if len(set(sexes)) > 1:
        notes.append(f"the motions' sexes differ ({', '.join(str(x) for x in sexes)}): the average records no sex; "
                     "give --reference-sex to physics retarget")
    for key in BODY_FIELDS:
        lacking = [i for i, m in enumerate(motions, 1) if m.metadata.get(key) is None]
        if lacking and len(lacking) < len(motions):
            notes.append(f"motion(s) {', '.join(map(str, lacking))} record no {key}: the average records none")
    return notes


def average_motion(motions: list[Motion], cycles: int = 2, fps: float | None = None) -> Motion:
    """DTW-aligned average of several motions on the same skeleton (joint names)."""
    if len(motions) < 2:
        raise StimuliError(f"average: needs at least 2 motions, got {len(motions)}")
    names = motions[0].joint_names
    for i, m in enumerate(motions[1:], 1):
        if m.joint_names != names:
            raise StimuliError(f"average: motion {i + 1} has another skeleton than motion 1 "
                               "(retarget them to one rig first)")
    fps = fps or motions[0].fps
    cyc = [cycle_of(m, fps) for m in motions]
    contacts = [_cycle_contacts(m, c.n_frames, fps) for m, c in zip(motions, cyc)]
    periodic = all(m.metadata.get("looped") for m in motions)
    feats = [features(c) for c in cyc]
    if periodic:
        # A loop may begin anywhere in the gait cycle (a capture's at its first heel strike or where its
        # seam matched best); DTW pins the cycles' ends together, so each loop first starts at the
        # phase of the first one (its pelvis-relative features roll with it).
        shifts = [0] + [_phase_shift(feats[0], f) for f in feats[1:]]
        rolls = [_rolled_frames(c.n_frames, k) for c, k in zip(cyc, shifts)]
        cyc = [_rolled(c, k) for c, k in zip(cyc, shifts)]
        feats = [f[r] for f, r in zip(feats, rolls)]
        contacts = [None if c is None else c[r] for c, r in zip(contacts, rolls)]
    dist = np.array([[_feature_distance(a, b) if i < j else 0.0 for j, b in enumerate(feats)] for i, a in enumerate(feats)])
    dist = dist + dist.T
    ref = int(np.argmin(dist.sum(axis=1)))
    n = cyc[ref].n_frames
    rots = [[] for _ in range(n)]
    roots = [[] for _ in range(n)]
    votes = np.zeros((n, 2))
    for c, f, contact in zip(cyc, feats, contacts):
        per_frame = _periodic_matches(feats[ref], f) if periodic else _matches(feats[ref], f)
        for i in range(n):
            js = per_frame.get(i, [i])
            rots[i].append(quat.mean(c.rotations[js]))
            roots[i].append(c.root_translation[js].mean(axis=0))
            if contact is not None:
                votes[i] += contact[js].mean(axis=0)
    rot = np.stack([quat.mean(np.stack(r)) for r in rots])
    root = np.stack([np.mean(r, axis=0) for r in roots])
    offsets = np.mean([c.offsets for c in cyc], axis=0)
    meta = {"source": "average", "n_motions": len(motions), "reference": ref,
            "dtw_distances": dist.round(6).tolist(), "treadmill": True,
            "belt_speed_mps": float(np.mean([m.metadata.get("belt_speed_mps", 0.0) for m in motions])),
            "speed_mps": float(np.mean([m.metadata.get("speed_mps", m.metadata.get("belt_speed_mps", 0.0)) for m in motions])),
            "gait": motions[0].metadata.get("gait"), "roles": motions[0].metadata.get("roles"),
            "naming": motions[0].metadata.get("naming"), **_mean_body(motions)}
    avg = Motion(fps, names, motions[0].parents, offsets, quat.unroll(rot), root, meta)
    # Averages of looped clips are periodic (their cycles are closed and matched around the loop): drop
    # the end frame; otherwise close the loop.
    looped = avg.slice(0, avg.n_frames - 1) if periodic else close_loop(avg)
    looped.metadata["looped"] = True
    looped.metadata.update(cycles=1, cadence_spm=120.0 * fps / (n - 1))
    out = repeat(looped, cycles)
    if periodic and all(c is not None for c in contacts):
        down = np.tile(votes[: n - 1] / len(motions) >= 0.5, (max(cycles, 1), 1))
        out.metadata["contacts"] = {s: down[:, k].astype(int).tolist() for k, s in enumerate("lr")}
    return out


def _matches(ref: np.ndarray, other: np.ndarray) -> dict[int, list[int]]:
    """Per frame of ``ref``, the frames of ``other`` on their DTW warping path (ends pinned together)."""
    per_frame: dict[int, list[int]] = {}
    for i, j in _path(ref, other):
        per_frame.setdefault(i, []).append(j)
    return per_frame


def _periodic_matches(ref: np.ndarray, other: np.ndarray) -> dict[int, list[int]]:
    """:func:`_matches` for closed cycles (end frame repeating the first), matched around the loop.

    DTW pins the first frames together and the last; at a loop's seam that forces the path onto
    the two cycles' start frames even where the gait phase says otherwise, and the average's frames
    next to its seam mixed poses a frame or two apart (the men's capture-average walk: an ankle
    turning 12° more in one frame than anywhere inside the cycle). Here both cycles are extended by
    a quarter cycle around their seam, the extended copies are aligned, and the middle of the path
    is kept; the end frame matches as the first does.

    >>> t = np.linspace(0, 2 * np.pi, 25)[:, None]
    >>> m = _periodic_matches(np.sin(t), np.sin(t))
    >>> all(m[i] == [i] for i in range(24)), m[24]
    (True, [0])
    """
    n, m = len(ref) - 1, len(other) - 1
    pad_r, pad_o = max(n // 4, 1), max(m // 4, 1)
    ext_r = ref[np.arange(-pad_r, n + pad_r) % n]
    ext_o = other[np.arange(-pad_o, m + pad_o) % m]
    per_frame: dict[int, list[int]] = {}
    for i, j in _path(ext_r, ext_o):
        if pad_r <= i < n + pad_r:
            per_frame.setdefault(i - pad_r, []).append((j - pad_o) % m)
    per_frame[n] = list(per_frame[0])
    return per_frame


def _phase_shift(ref: np.ndarray, other: np.ndarray) -> int:
    """The frames by which to roll a closed cycle (its per-frame features ``other``, end frame
    included) so that its gait phase lines up with ``ref``'s: least squares over the circular
    shifts, ``other`` resampled to ``ref``'s number of frames.

    >>> t = np.linspace(0, 2 * np.pi, 21)[:, None]
    >>> _phase_shift(np.sin(t), np.sin(t + 2 * np.pi * 5 / 20))   # starts 5 frames later in phase
    15
    """
    r, o = ref[:-1], other[:-1]
    n, m = len(r), len(o)
    x = np.arange(n) * m / n
    i0 = np.floor(x).astype(int)
    a = (x - i0)[:, None]
    on_ref = o[i0 % m] * (1 - a) + o[(i0 + 1) % m] * a
    costs = [float(np.sum((r - np.roll(on_ref, -k, axis=0)) ** 2)) for k in range(n)]
    return int(round(int(np.argmin(costs)) * m / n)) % m


def _rolled_frames(frames: int, shift: int) -> np.ndarray:
    """Indices of a closed cycle of ``frames`` (end frame repeating the first) started ``shift`` later."""
    unique = frames - 1
    return (np.arange(frames) + shift) % unique


def _rolled(cycle: Motion, shift: int) -> Motion:
    """A closed cycle started ``shift`` frames later (still closed; an overground cycle's root goes on
    by one cycle's travel past its end)."""
    if shift == 0:
        return cycle
    idx = _rolled_frames(cycle.n_frames, shift)
    root = cycle.root_translation[idx]
    if not cycle.metadata.get("treadmill"):
        laps = (np.arange(cycle.n_frames) + shift) // (cycle.n_frames - 1)
        root = root + laps[:, None] * (cycle.root_translation[-1] - cycle.root_translation[0])
    return cycle.replace(rotations=cycle.rotations[idx], root_translation=root)


def _cycle_contacts(motion: Motion, n: int, fps: float | None = None) -> np.ndarray | None:
    """The foot contacts (n × 2: left, right) of the first ``n`` frames at ``fps`` (default the
    motion's own rate; each frame takes its nearest frame of the motion) of a looped motion that
    carries them for all its frames (metadata ``contacts``), else None.

    Why resampled: an average of captures at 30 and 120 fps (Bandai's and CMU's runs) lost every vote
    and cleaned its feet by guessing from foot heights; the women's Exp-2 jog average then stood 3
    frames a cycle on its left foot and held it 14-26 mm over the floor for 8 more.

    >>> from stimuli.motion.generate import GaitParams, generate
    >>> walk = generate(GaitParams(), 1.75, fps=60, cycles=1)
    >>> bool((_cycle_contacts(walk, 10, 30.0) == _cycle_contacts(walk, 20)[::2]).all())
    True
    """
    known = motion.metadata.get("contacts") or {}
    if not motion.metadata.get("looped") or any(len(known.get(s, [])) != motion.n_frames for s in "lr"):
        return None
    both = np.stack([np.asarray(known[s], bool) for s in "lr"], axis=1)
    step = motion.fps / (fps or motion.fps)
    return both[np.round(np.arange(n) * step).astype(int) % motion.n_frames]


def protocol_average(protocol, sex: str, gait: str, fps: float | None = None, cycles: int | None = None) -> Motion:
    """The NoCOM motion of Exp 2: the DTW average of the test actors' own gaits of one sex (their
    captures where they name them, ``actors[].motions``; else generated).

    The metadata records the average body (mean height and BMI of those actors), which the physics
    step uses as the reference body. An average of captures gets the foot clean-up on that body
    (``retarget.cleanup_feet``), as each capture got it.
    """
    from stimuli.motion.captures import average_inputs

    actors = [a for a in protocol.actors if a.sex == sex and not a.practice_only]
    if len(actors) < 2:
        raise StimuliError(f"protocol {protocol.name}: an average motion of sex {sex} needs at least 2 test actors, "
                           f"found {len(actors)}")
    if gait not in protocol.gaits:
        raise StimuliError(f"protocol {protocol.name}: gaits.{gait} is not declared (cadence and speed are needed)")
    fps = float(fps or protocol.clip.fps)
    cycles = int(cycles or protocol.clip.cycles)
    # Actors' own captures where the protocol names them (stimuli.motion.captures), else generated gaits.
    motions = average_inputs(protocol, actors, gait, fps, cycles)
    average = average_motion(motions, cycles=cycles, fps=fps)
    if any(gait in a.motions for a in actors):
        # Each capture's feet were laid on the average's body, but not the average's: joint rotations of
        # runs at 1.5-3.7 m/s averaged into stance feet that slid and sank (Exp 2's men's jog average:
        # 29 % skate, 48 mm deep; each run 0 %), so the NoCOM clip is cleaned on that body as well.
        from stimuli.motion.captures import average_body
        from stimuli.motion.retarget import cleanup_feet

        average = cleanup_feet(average, average_body(actors))
    average.metadata.update(actors=[a.id for a in actors], sex=sex,
                            height_m=float(np.mean([a.height_m for a in actors])),
                            bmi=float(np.mean([a.bmi for a in actors])))
    return average
