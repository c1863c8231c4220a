"""An actor's own captures in a protocol (``actors[].motions``): read, looped, checked, recorded.

A protocol actor may name a capture per gait::

    motions: {walk: captures/F_Hi1_walk.bvh, jog: {file: captures/F_Hi1_jog.npz, start_s: 2.0, end_s: 9.5}}

(paths relative to the protocol file; BVH or AMASS ``.npz``). Its gait is then that capture: read
(:func:`read_capture`), its steady straight range of the gait made a treadmill loop
(:func:`stimuli.motion.loop.capture_loop`, ``start_s``/``end_s`` choosing the range by hand), and
retargeted onto whichever body shows it. A gait without a capture is generated from the actor's
height and BMI, as before (:func:`actor_motion`). ``validate`` runs :func:`check_captures` before
anything is rendered; the manifest records :func:`motion_record` for each clip.
"""

from __future__ import annotations

import functools
from pathlib import Path

from stimuli.errors import StimuliError
from stimuli.motion.motion import Motion


def read_capture(path: str | Path) -> Motion:
    """A BVH or AMASS ``.npz`` capture as a Motion (StimuliError naming the file when it is missing or
    does not parse).

    >>> m = read_capture(Path(__file__).resolve().parents[1] / "data" / "cmu_35_01_walk.bvh")
    >>> m.fps, m.metadata["naming"]
    (120.0, 'cmu')
    """
    path = Path(path)
    if not path.is_file():
        raise StimuliError(f"{path}: capture not found")
    if path.suffix.lower() == ".bvh":
        from stimuli.motion.bvh import read_bvh

        return read_bvh(path)
    if path.suffix.lower() == ".npz":
        from stimuli.motion.amass import read_amass

        return read_amass(path)
    raise StimuliError(f"{path}: unknown motion format (expected .bvh or an AMASS .npz)")


@functools.lru_cache(maxsize=32)
def _looped(path: str, mtime_ns: int, size: int, gait: str, start_s: float | None, end_s: float | None) -> Motion:
    """The treadmill loop of one capture (cached per process; time and size key a rewritten file)."""
    from stimuli.motion.loop import capture_loop

    return capture_loop(read_capture(path), gait, start_s=start_s, end_s=end_s)


def capture_of(protocol, actor_id: str, gait: str):
    """The actor's :class:`stimuli.protocol.Capture` for ``gait``, or None (the gait is generated)."""
    actor = next((a for a in protocol.actors if a.id == actor_id), None)
    return None if actor is None else actor.motions.get(gait)


def looped_capture(protocol, actor_id: str, gait: str) -> Motion:
    """The actor's capture of ``gait`` as a seamless treadmill loop at the capture's own frame rate.

    >>> from stimuli.protocol import load_protocol
    >>> p = load_protocol("protocols/exp1_own_captures.yaml")
    >>> loop = looped_capture(p, "M_Lo", "walk")
    >>> loop.metadata["looped"], loop.metadata["cycles"]
    (True, 2)
    """
    from stimuli.protocol import actor_capture_file

    capture = capture_of(protocol, actor_id, gait)
    if capture is None:
        raise StimuliError(f"{protocol.name}: actor {actor_id} has no capture for {gait}")
    path = actor_capture_file(protocol, capture)
    if not path.is_file():
        raise StimuliError(f"{protocol.name}: actors.{actor_id}.motions.{gait}: {path} not found")
    stat = path.stat()
    return _looped(str(path.resolve()), stat.st_mtime_ns, stat.st_size, gait, capture.start_s, capture.end_s)


def actor_motion(protocol, actor, gait: str, fps: float, cycles: int) -> Motion:
    """The actor's looped gait: its capture where it names one, else the generator's gait at the
    protocol's cadence and speed (``cycles`` cycles at ``fps``; a capture keeps its own rate and
    the whole cycles its loop took)."""
    if gait in actor.motions:
        return looped_capture(protocol, actor.id, gait)
    from stimuli.motion.style import actor_gait

    spec = protocol.gaits[gait]
    return actor_gait(actor, gait, spec.cadence_spm, spec.speed_mps, protocol.seed, fps, cycles)


MOTION_COLUMNS = ("motion_source", "motion_file", "motion_sha256", "motion_range_s", "motion_params")


def motion_record(protocol, actor_id: str | None, gait: str) -> dict[str, str]:
    """What a clip's motion came from, as the manifest's :data:`MOTION_COLUMNS`: ``capture`` with the
    file (as the protocol names it), its SHA-256 and the range of the capture the loop took (seconds),
    or ``generator`` with its parameters (the actor's height, BMI and sex, the gait's cadence and
    speed, the protocol's seed). Empty for clips whose motion no actor gives (Exp 2, thesis sets).

    >>> from stimuli.protocol import load_protocol
    >>> p = load_protocol("protocols/exp1_own_captures.yaml")
    >>> motion_record(p, "F_Hi", "jog")["motion_source"], motion_record(p, "M_Lo", "walk")["motion_file"]
    ('generator', 'captures/cmu_35_01_walk.bvh')
    """
    record = dict.fromkeys(MOTION_COLUMNS, "")
    actor = next((a for a in protocol.actors if a.id == actor_id), None)
    if actor is None:
        return record
    capture = actor.motions.get(gait)
    if capture is None:
        spec = protocol.gaits.get(gait)
        params = {"actor": actor.id, "sex": actor.sex, "height_m": actor.height_m, "bmi": actor.bmi, "gait": gait,
                  "cadence_spm": spec.cadence_spm if spec else "", "speed_mps": spec.speed_mps if spec else "",
                  "seed": protocol.seed}
        return record | {"motion_source": "generator",
                         "motion_params": ";".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                                                   for k, v in params.items())}
    from stimuli.protocol import actor_capture_file
    from stimuli.render.video import sha256_file   # the clips' own hash, one implementation

    first, last = looped_capture(protocol, actor.id, gait).metadata["capture_range_s"]
    return record | {"motion_source": "capture", "motion_file": capture.file,
                     "motion_sha256": sha256_file(actor_capture_file(protocol, capture)),
                     "motion_range_s": f"{first:.3f}-{last:.3f}"}


def shown_cadence(loop: Motion, duration_s: float, looping: bool = True) -> float:
    """Steps per minute a captured loop shows in a clip of ``duration_s``: its own cadence, times the
    time scale with which whole loops fill the clip (``stimuli.render.sources.fit_loop``).

    >>> from stimuli.protocol import load_protocol
    >>> loop = looped_capture(load_protocol("protocols/exp1_own_captures.yaml"), "M_Lo", "walk")
    >>> round(loop.metadata["cadence_spm"], 1), round(shown_cadence(loop, 4.4), 1)
    (107.1, 109.1)
    """
    loop_s = loop.n_frames / loop.fps
    loops = max(1, int(round(duration_s / loop_s)))
    return float(loop.metadata["cadence_spm"]) * (loops * loop_s / duration_s if looping else 1.0)


def capture_files(protocol, actor_id: str | None, gait: str) -> list[Path]:
    """The capture file a clip of ``actor_id``'s ``gait`` reads ([] when it is generated): part of
    the clip's inputs hash, so that a changed capture renders again."""
    from stimuli.protocol import actor_capture_file

    capture = capture_of(protocol, actor_id, gait) if actor_id else None
    return [] if capture is None else [actor_capture_file(protocol, capture)]


def check_captures(protocol, protocol_path: str | Path) -> list[str]:
    """Every actor's capture exists, parses and holds a usable steady cycle of its gait (import and
    loop dry run). Returns what was checked, one line per capture; StimuliError listing every
    problem (actor, gait, file with its YAML line, and what was found) otherwise.
    """
    from stimuli.protocol import actor_capture_file, capture_line

    checked, problems = [], []
    for actor in protocol.actors:
        for gait, capture in actor.motions.items():
            path = actor_capture_file(protocol, capture)
            line = capture_line(protocol_path, actor.id, gait)
            where = f"actors.{actor.id}.motions.{gait}{f' (line {line})' if line else ''}: {capture.file}"
            if not path.is_file():
                problems.append(f"{where}: file not found ({path}; relative paths start from the protocol's folder)")
                continue
            try:
                loop = looped_capture(protocol, actor.id, gait)
            except StimuliError as exc:
                problems.append(f"{where}: {exc}")
                continue
            first, last = loop.metadata["capture_range_s"]
            checked.append(f"{actor.id} {gait}: {capture.file}: {loop.metadata['cycles']} cycle(s) from "
                           f"{first:.2f}-{last:.2f} s, belt {loop.metadata['belt_speed_mps']:.2f} m/s")
    if problems:
        raise StimuliError(f"{protocol_path}: {len(problems)} actor capture(s) cannot be used: " + " | ".join(problems))
    return checked


def average_inputs(protocol, actors: list, gait: str, fps: float, cycles: int) -> list[Motion]:
    """The motions Exp 2's DTW average is made of: each actor's capture of ``gait`` where it names
    one, else its generated gait. Generated gaits share one skeleton; captures (each on its own
    rig) and generated gaits are first retargeted onto the body of the actors' mean height and BMI
    (the average's own body), so that the average compares like with like.
    """
    motions = [actor_motion(protocol, a, gait, fps, cycles) for a in actors]
    if not any(gait in a.motions for a in actors):
        return motions
    from stimuli.motion.retarget import retarget

    body = average_body(actors)
    return [retarget(m, body) for m in motions]


def average_body(actors: list):
    """The body of the actors' mean height and BMI (of the first sex among them): the body an
    average of their captures is made on (:func:`average_inputs`)."""
    import numpy as np

    from stimuli.bodies import body_for_actor
    from stimuli.protocol import Actor

    sexes = sorted({a.sex for a in actors})
    mean = Actor(id=f"average_{'_'.join(sexes)}", label="average", sex=sexes[0],
                 height_m=round(float(np.mean([a.height_m for a in actors])), 3),
                 bmi=round(float(np.mean([a.bmi for a in actors])), 2))
    return body_for_actor(mean)
