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


def cycle_of(motion: Motion) -> Motion:
    """One gait cycle (frames of the first whole cycle, end frame included for looping)."""
    from stimuli.motion.events import cycle_starts
    if motion.metadata.get("looped"):
        cycles = int(motion.metadata.get("cycles", 1))
        n = motion.n_frames // max(cycles, 1)
        rot = np.concatenate([motion.rotations[:n], motion.rotations[n:n + 1] if motion.n_frames > n else motion.rotations[:1]])
        root = np.concatenate([motion.root_translation[:n], motion.root_translation[n:n + 1] if motion.n_frames > n else motion.root_translation[:1]])
        return motion.replace(rotations=rot, root_translation=root)
    hs = cycle_starts(motion)
    return motion.slice(int(hs[0]), int(hs[1]) + 1)


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
    from dtaidistance import dtw_ndim
    return float(dtw_ndim.distance(features(a).astype(np.double), features(b).astype(np.double)))


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
    cyc = [cycle_of(m if m.fps == fps else m.resample(fps)) for m in motions]
    feats = [features(c) for c in cyc]
    dist = np.array([[dtw_distance(a, b) if i < j else 0.0 for j, b in enumerate(cyc)] for i, a in enumerate(cyc)])
    dist = dist + dist.T
    ref = int(np.argmin(dist.sum(axis=1)))
    n = cyc[ref].n_frames
    rots = [[] for _ in range(n)]
    roots = [[] for _ in range(n)]
    contacts = [_cycle_contacts(m, c.n_frames, fps) for m, c in zip(motions, cyc)]
    votes = np.zeros((n, 2))
    for c, f, contact in zip(cyc, feats, contacts):
        per_frame: dict[int, list[int]] = {}
        for i, j in _path(feats[ref], f):
            per_frame.setdefault(i, []).append(j)
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
    # Averages of looped clips are periodic already: drop the end frame; otherwise close the loop.
    periodic = all(m.metadata.get("looped") for m in motions)
    looped = avg.slice(0, avg.n_frames - 1) if periodic else close_loop(avg)
    looped.metadata["looped"] = True
    looped.metadata.update(cycles=1, cadence_spm=120.0 * fps / (n - 1))
    out = repeat(looped, cycles)
    if periodic and all(c is not None for c in contacts):
        down = np.tile(votes[: n - 1] / len(motions) >= 0.5, (max(cycles, 1), 1))
        out.metadata["contacts"] = {s: down[:, k].astype(int).tolist() for k, s in enumerate("lr")}
    return out


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
