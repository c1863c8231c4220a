"""How a gait's cadence is fitted to a clip, and what that does to the protocol's cadence and speed.

A looping clip shows a whole number of gait cycles (two steps each): the motion is made with the
whole number of cycles closest to ``duration_s × cadence_spm / 120`` and ``sources.fit_loop``
stretches it over the clip's frames. The clip therefore shows ``cycles × 120 / clip seconds``
steps per minute. The belt keeps the protocol's speed on every body (the gait is generated at
the speed that gives it after retargeting and the loop's fit: :func:`belt_matched_speed`), so the
steps get shorter or longer by that ratio instead. When the cadence differs from the protocol's by
more than :data:`TOLERANCE`, ``validate`` and ``render`` say so (:func:`cadence_warnings`), naming
clip durations that would keep it. A clip with ``clip.loop: false`` keeps the protocol's cadence
and speed and ends mid-cycle (a replay restarts it).

Only the gaits the protocol declares under ``gaits`` are fitted here: motions read from captures
(the thesis protocols) keep their own cadence and are retimed to whole loops by ``fit_loop``.

>>> fit = gait_fit("jog", 150, 2.4, duration_s=2, fps=15)
>>> fit.cycles, round(fit.effective_cadence_spm, 1), fit.effective_speed_mps, round(fit.step_length_m, 2)
(2, 120.0, 2.4, 1.2)
"""

from __future__ import annotations

from dataclasses import dataclass

TOLERANCE = 0.02  # a cadence change below 2 % is within a real walker's stride-to-stride variation
STEPS_PER_CYCLE = 2


def whole_cycles(duration_s: float, cadence_spm: float) -> int:
    """The number of gait cycles a clip shows: ``stimuli.motion.loop.cycles_for_clip``'s rule.

    Restated here (``tests/test_clip_timing.py`` checks the two agree) because importing the motion
    package loads scipy, which would add a second to every ``validate``.

    >>> whole_cycles(4.0, 112), whole_cycles(4.0, 138)
    (4, 5)
    """
    return max(1, int(round(duration_s * cadence_spm / (60.0 * STEPS_PER_CYCLE))))


def clip_seconds(duration_s: float, fps: int) -> float:
    """The length of a clip as rendered: a whole number of frames (``Look.n_frames``)."""
    return round(duration_s * fps) / fps


@dataclass(frozen=True)
class GaitFit:
    """One gait as a clip shows it: the protocol's cadence and speed, and what the clip plays."""

    gait: str
    cadence_spm: float
    speed_mps: float
    clip_s: float
    cycles: int
    loop: bool = True

    fps: float = 30.0

    @property
    def effective_cadence_spm(self) -> float:
        """Steps per minute the clip shows: whole cycles over the clip, or (not looped) the generator's
        cadence — the protocol's with its loop rounded to whole frames (``generate``: 150 steps/min at
        24 fps plays 151.6)."""
        if self.loop:
            return self.cycles * 60.0 * STEPS_PER_CYCLE / self.clip_s
        frames = max(1, round(self.cycles * 60.0 * STEPS_PER_CYCLE / self.cadence_spm * self.fps))
        return self.cycles * 60.0 * STEPS_PER_CYCLE * self.fps / frames

    @property
    def shown_cycles(self) -> float:
        """Gait cycles the clip shows (a whole number when it loops)."""
        return self.clip_s * self.effective_cadence_spm / (60.0 * STEPS_PER_CYCLE)

    @property
    def ratio(self) -> float:
        """Effective / protocol cadence: how much faster ``fit_loop`` plays the generated loop."""
        return self.effective_cadence_spm / self.cadence_spm

    @property
    def effective_speed_mps(self) -> float:
        """Belt speed: the protocol's, on every body and whatever the cadence (:func:`belt_matched_speed`)."""
        return self.speed_mps

    @property
    def step_length_m(self) -> float:
        """The step length the clip shows: belt speed over the shown cadence (steps per second)."""
        return self.effective_speed_mps * 60.0 / self.effective_cadence_spm

    @property
    def protocol_step_length_m(self) -> float:
        """The step length the protocol's cadence and speed make."""
        return self.speed_mps * 60.0 / self.cadence_spm

    @property
    def within_tolerance(self) -> bool:
        return abs(self.ratio - 1.0) <= TOLERANCE


def gait_fit(gait: str, cadence_spm: float, speed_mps: float, duration_s: float, fps: int,
             loop: bool = True) -> GaitFit:
    """How a clip of ``duration_s`` at ``fps`` shows a gait of the given cadence and speed (``loop``:
    the protocol's ``clip.loop``; a clip that does not loop keeps the cadence and is cut at its end)."""
    return GaitFit(gait, float(cadence_spm), float(speed_mps), clip_seconds(duration_s, fps),
                   whole_cycles(duration_s, cadence_spm), bool(loop), float(fps))


def belt_matched_speed(speed_mps: float, cadence_spm: float, cycles: int, fps: float, height_m: float, body,
                       clip_s: float, loop: bool = True) -> float:
    """The speed to generate a gait at so that, on ``body`` and in the clip, the belt runs at ``speed_mps``.

    The gait is the generator's loop of ``cycles`` cycles at ``cadence_spm`` and ``fps`` for an actor
    of stature ``height_m``. Two things change the belt speed after generation: retargeting scales
    the stride by the legs' ratio ``k`` (``stimuli.motion.retarget``), and ``fit_loop`` plays the
    loop ``s`` times faster to fill the clip with whole cycles (112 steps/min shown at 120 in a
    4-s clip). Generating at ``speed_mps / (k·s)`` makes the shown belt speed the protocol's for
    every body (within 0.07 %: ``generated_leg_length``); the cadence stays the clip's, so the step
    length is ``speed / cadence`` (0.60 m for a 1.2 m/s walk at 120 steps/min) for everyone. Both
    factors come from the skeleton and the frame count alone, so the gait is generated once.
    """
    from stimuli.motion.generate import generated_leg_length, loop_frames
    from stimuli.motion.retarget import rig_leg_length

    legs = rig_leg_length(body.rig) / generated_leg_length(height_m)
    loop_s = loop_frames(cycles, cadence_spm, fps) / fps
    loops = max(1, int(round(clip_s / loop_s)))
    faster = loops * loop_s / clip_s if loop else 1.0
    return float(speed_mps) / (legs * faster)


# The motion generator needs this many frames for the gait cycles of a clip (stimuli.motion.generate).
GENERATOR_MIN_FRAMES = 8


def generator_frames_problem(protocol, fps: int) -> str | None:
    """Why the generator cannot make the protocol's gaits at ``fps`` (too few frames for the gait
    cycles a clip holds), or None. Only for protocols whose clips show generated walks (no
    alternatives factor: ``stimuli.render.sources.actor_motion``)."""
    if protocol.factors_with_role("alternatives"):
        return None
    for name, spec in protocol.gaits.items():
        cycles = whole_cycles(protocol.clip.duration_s, spec.cadence_spm)
        frames = int(round(cycles * 120.0 / spec.cadence_spm * fps))
        if frames < GENERATOR_MIN_FRAMES:
            return (f"{cycles} cycle(s) of {name} at {spec.cadence_spm:g} steps/min last only {frames} frames at "
                    f"{fps} fps, and a generated gait needs at least {GENERATOR_MIN_FRAMES}")
    return None


def protocol_fits(protocol, fps: int | None = None) -> list[GaitFit]:
    """The fit of every gait the protocol declares, at the protocol's clip duration (and frame rate,
    unless ``fps`` overrides it as ``render --fps``/``--quick`` do)."""
    clip = protocol.clip
    return [gait_fit(name, spec.cadence_spm, spec.speed_mps, clip.duration_s, fps or clip.fps, clip.loop)
            for name, spec in protocol.gaits.items()]


def keeping_durations(cadences: list[float], duration_s: float, fps: int) -> tuple[float | None, float | None]:
    """The clip durations nearest to ``duration_s`` (one shorter or equal, one longer) at which every
    cadence is shown within :data:`TOLERANCE`; None where there is none up to 120 s (the longest clip).

    Candidates are the whole-cycle durations of each gait, rounded to whole frames.

    >>> keeping_durations([150], 2.0, 15)
    (1.6, 2.4)
    """
    candidates = set()
    for cadence in cadences:
        cycle_s = 60.0 * STEPS_PER_CYCLE / cadence
        for k in range(1, int(120.0 / cycle_s) + 1):
            d = clip_seconds(k * cycle_s, fps)
            if d > 0 and all(gait_fit("", c, 1.0, d, fps).within_tolerance for c in cadences):
                candidates.add(round(d, 6))
    shorter = max((d for d in candidates if d <= duration_s), default=None)
    longer = min((d for d in candidates if d > duration_s), default=None)
    return shorter, longer


def seconds_text(seconds: float, fps: int) -> str:
    """A duration with the fewest decimals (2 to 4) that still gives the same whole number of frames.

    >>> seconds_text(17 / 15, 15), seconds_text(2.4, 15)
    ('1.13', '2.4')
    """
    frames = round(seconds * fps)
    for decimals in (2, 3, 4):
        text = f"{seconds:.{decimals}f}".rstrip("0").rstrip(".")
        if round(float(text) * fps) == frames:
            return text
    return f"{seconds:g}"


def _seconds(values, fps: int) -> str:
    return " or ".join(f"{seconds_text(v, fps)} s" for v in values if v is not None)


def cadence_warnings(protocol, fps: int | None = None) -> list[str]:
    """One warning per declared gait whose clip cadence is off by more than :data:`TOLERANCE`, plus,
    with several gaits, the nearest durations that keep all of them."""
    fits = protocol_fits(protocol, fps)
    rate = fps or protocol.clip.fps
    duration = protocol.clip.duration_s
    warnings = []
    for fit in fits:
        if fit.within_tolerance or not fit.loop:   # not looped: only the generator's whole-frame rounding
            continue
        keep = _seconds(keeping_durations([fit.cadence_spm], duration, rate), rate)
        warnings.append(
            f"gaits.{fit.gait}: {fit.cadence_spm:g} steps/min does not fill the {fit.clip_s:g} s clip with whole "
            f"gait cycles, so the clip shows {fit.cycles} cycle(s) at {fit.effective_cadence_spm:.1f} steps/min "
            f"({(fit.ratio - 1) * 100:+.1f} %); the belt keeps {fit.effective_speed_mps:g} m/s, so steps are "
            f"{fit.step_length_m:.2f} m instead of {fit.protocol_step_length_m:.2f}" + (f"; clip.duration_s {keep} keeps {fit.cadence_spm:g} steps/min "
                                    f"(within {TOLERANCE:.0%})" if keep else ""))
    if warnings and len(fits) > 1:
        both = _seconds(keeping_durations([f.cadence_spm for f in fits], duration, rate), rate)
        warnings.append(f"clip.duration_s: {both} keeps every gait within {TOLERANCE:.0%}" if both else
                        f"clip.duration_s: no clip up to 120 s keeps every gait within {TOLERANCE:.0%}")
    return warnings


def fits_summary(protocol) -> str:
    """One line for ``validate``: the cycles and cadence each declared gait is shown with."""
    parts = [f"{f.gait} {f.shown_cycles:.{0 if f.loop else 2}f} cycle(s) at {f.effective_cadence_spm:.1f} steps/min "
             f"(protocol {f.cadence_spm:g})" for f in protocol_fits(protocol)]
    looping = "looped" if protocol.clip.loop else "not looped: the protocol's cadence to whole frames, cut at the end"
    return f"clip {protocol.clip.duration_s:g} s ({looping}): " + ", ".join(parts)


def clip_cadence(protocol, stimulus, duration_s: float, fps: int) -> str:
    """The manifest's ``cadence_spm``: the steps per minute a clip shows, for clips whose gait the
    protocol declares ('' for motions read from captures, which keep their own cadence)."""
    from stimuli.render.sources import gait_of

    spec = protocol.gaits.get(gait_of(protocol, stimulus))
    if spec is None:
        return ""
    fit = gait_fit("", spec.cadence_spm, spec.speed_mps, duration_s, fps, protocol.clip.loop)
    return f"{fit.effective_cadence_spm:.2f}"
