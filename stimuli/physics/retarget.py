"""The COM method end to end: motion + body (+ weight) → ragdoll simulation → COM Motion + report.

Examples
--------
>>> from stimuli.bodies import fit_body
>>> from stimuli.motion.generate import GaitParams, generate
>>> walk = generate(GaitParams(gait="walk", cadence_spm=112, speed_mps=1.2), height_m=1.60, fps=30, cycles=2)
>>> result = retarget(walk, fit_body("F", 1.60, 28.1))     # its own body: b = 0
>>> result.report["fell"], result.report["b_m"], result.report["gains"]["gait"]
(False, 0.0, 'walk')
>>> result.motion.n_frames == walk.n_frames
True
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial.transform import Rotation

from stimuli.errors import StimuliError
from stimuli.physics import inertia
from stimuli.physics.attainable import reference_under_gravity
from stimuli.physics.controller import (Gains, motion_gait, set_joint_gains, set_torque_limits, torque_limit,
                                        torque_limit_source, torque_limit_sourced)
from stimuli.physics.output import joint_rms_difference, to_motion
from stimuli.physics.ragdoll import TOES_BY_GAIT, build_ragdoll, compile_model
from stimuli.physics.reference import build_reference
from stimuli.physics.simulate import DEFAULT_RATE_HZ, simulate


class RagdollFellError(StimuliError):
    """The ragdoll fell while tracking the motion (the report says when and why)."""


@dataclasses.dataclass
class RetargetResult:
    motion: object
    report: dict
    sim: object
    reference: object
    ragdoll: object


def prepare(motion, body, weight_kg: float | None = None, gains: Gains | None = None,
            rate_hz: float = DEFAULT_RATE_HZ, toe_segment: bool | None = None):
    """Reference targets, ragdoll and compiled model with the fixed gains (no simulation yet).

    ``gains`` default: the shipped set of the motion's gait (:func:`motion_gait`); ``toe_segment``
    default: the gains' gait's (:data:`stimuli.physics.ragdoll.TOES_BY_GAIT`)."""
    gains = gains or Gains.load(gait=motion_gait(motion))
    toes = TOES_BY_GAIT[gains.gait] if toe_segment is None else bool(toe_segment)
    ref, ragdoll = build_reference(motion, body, lambda axes: build_ragdoll(body, weight_kg, axes, toes=toes))
    kp, kd = gains.joint_gains(ragdoll.dof_names)
    model = compile_model(ragdoll, 1.0 / rate_hz, kp, kd)
    set_joint_gains(model, kp, kd)
    return ref, ragdoll, model, gains


def tracking_rms(sim, ragdoll) -> dict[str, float]:
    """RMS (degrees) per joint of the angle between simulated and target joint rotations."""
    out, col = {}, 0
    for link in ragdoll.links:
        n = len(link.dofs)
        if not n:
            continue
        q, r = sim.q[:, col:col + n], sim.qref[:, col:col + n]
        if len(q) == 0:
            err = np.full(1, np.nan)
        elif n == 1:
            err = np.abs(q[:, 0] - r[:, 0])
        else:
            err = (Rotation.from_euler(link.euler, r).inv() * Rotation.from_euler(link.euler, q)).magnitude()
        out[link.joint_name] = float(np.degrees(np.sqrt(np.mean(err**2))))
        col += n
    return out


def root_drift(sim) -> dict[str, float]:
    """Distance (m) of the simulated pelvis from its target: horizontal mean/max, vertical max."""
    pelvis = sim.body_names.index("pelvis")
    if len(sim.xpos) == 0:
        return {"horizontal_mean_m": float("nan"), "horizontal_max_m": float("nan"), "vertical_max_m": float("nan")}
    d = sim.xpos[:, pelvis] - sim.root_target
    horiz = np.linalg.norm(d[:, [0, 2]], axis=1)
    return {"horizontal_mean_m": float(horiz.mean()), "horizontal_max_m": float(horiz.max()),
            "vertical_max_m": float(np.abs(d[:, 1]).max())}


def root_tilt(sim) -> dict[str, float]:
    """Angle (degrees) between the simulated pelvis orientation and its target: mean and max.

    The per-joint tracking RMS measures each joint against its parent, so it cannot see the whole
    body leaning: on CMU 35_01 (base body, PD + feed-forward) the pelvis ran 8.3° (up to 14.6°) off
    its target, mostly pitch, while the joints tracked at 1.1°, which put the stance feet 10–15 cm
    behind the reference's relative to the pelvis.
    """
    if len(sim.xquat) == 0:
        return {"mean": float("nan"), "max": float("nan")}
    import mujoco

    pelvis = sim.body_names.index("pelvis")
    angles = np.empty(len(sim.xquat))
    inv, err, vel = np.empty(4), np.empty(4), np.empty(3)
    for i, (q, target) in enumerate(zip(sim.xquat[:, pelvis], sim.root_target_quat)):
        mujoco.mju_negQuat(inv, target)
        mujoco.mju_mulQuat(err, q, inv)
        mujoco.mju_quat2Vel(vel, err, 1.0)
        angles[i] = np.linalg.norm(vel)
    return {"mean": float(np.degrees(angles.mean())), "max": float(np.degrees(angles.max()))}


def build_report(sim, ragdoll, body, reference_body, weight_kg: float, gains: Gains, nocom: dict | None) -> dict:
    """The JSON report of one retargeting (see docs/readme_physics.md for the fields)."""
    ref_w = float(reference_body.anthropometry.mass_kg)
    ref_masses = inertia.segment_masses(reference_body.segments, ref_w)
    masses = inertia.segment_masses(body.segments, weight_kg)
    track = tracking_rms(sim, ragdoll)
    report = {
        "body": _body_row(body, weight_kg), "reference_body": _body_row(reference_body, ref_w),
        "b_m": inertia.balance_factor(ref_masses, masses, reference_body.rig.rest_heads[0], body.rig.rest_heads[0]),
        "b_paper_m": inertia.paper_balance_factor(body.segments, weight_kg),
        "com_m": np.round(inertia.whole_body_com(masses), 5).tolist(),
        "reference_com_m": np.round(inertia.whole_body_com(ref_masses), 5).tolist(),
        "segments": [m.as_row() for m in masses],
        "tracking_rms_deg": {k: round(v, 3) for k, v in track.items()},
        "tracking_rms_deg_overall": round(float(np.sqrt(np.mean(np.square(list(track.values()))))), 3),
        "root_drift": {k: round(v, 4) for k, v in root_drift(sim).items()},
        "root_tilt_deg": {k: round(v, 3) for k, v in root_tilt(sim).items()},
        # Steps with neither foot on the floor: a walk has none (double support instead); the
        # tracked ragdoll still hops between steps (readme: known limits).
        "flight_fraction": round(float((~sim.foot_contact.any(axis=1)).mean()), 4) if len(sim.foot_contact) else None,
        "torque_peaks_nm": torque_peaks(sim),
        "fell": bool(sim.fell), "fall_time_s": sim.fall_time_s, "fall_reason": sim.fall_reason,
        "simulated_s": round(sim.simulated_s, 4), "wall_s": round(sim.wall_s, 4),
        "wall_per_simulated": round(sim.wall_s / sim.simulated_s, 4), "timestep_s": sim.timestep,
        "rate_hz": round(1.0 / sim.timestep, 2), "dof": len(ragdoll.dof_names),
        "gains": dict({k: getattr(gains, k) for k in ("k_p", "k_d", "k_pf", "k_df", "k_pr", "k_dr")}, gait=gains.gait),
    }
    if nocom is not None:
        report["nocom_rms_deg"] = {k: round(v, 3) for k, v in nocom.items()}
        report["nocom_rms_deg_mean"] = round(float(np.mean(list(nocom.values()))), 3)
    return report


def torque_peaks(sim) -> dict[str, dict[str, float | bool | str]]:
    """Per DoF: peak |actuator torque| (N·m) over the recorded pass, the human limit it is held to,
    whether that limit has a published figure behind it (``sourced``) and which (``source``).

    The limit (:data:`stimuli.physics.controller.TORQUE_LIMITS_NM`) is reported whether or not the
    simulation enforced it, so a pure-PD run shows where it asks for more than a strong adult has.
    """
    if not len(sim.actuator_force):
        return {}
    peaks = np.abs(sim.actuator_force).max(axis=0)
    return {d: {"peak": round(float(p), 1), "limit": torque_limit(d), "sourced": torque_limit_sourced(d),
                "source": torque_limit_source(d)}
            for d, p in zip(sim.dof_names, peaks)}


# The reference's flight share is read at this frame rate at least (the simulation's per physics step).
FLIGHT_FPS = 240.0


def reference_flight_fraction(motion) -> float:
    """Share of the motion's time with neither foot down (the shared contact model), read on the
    motion sampled at :data:`FLIGHT_FPS` at least (slerp between its frames; a looped clip across
    its seam too).

    Why not at the clip's own rate: at 30 fps one frame is 3.8 % of a 26-frame jog cycle, and the
    contact model places touchdown up to a frame late where the foot's speed is a difference across
    the landing. The Exp-2 DTW jog averages read 0.192 (men) and 0.231 (women) at 30 fps, 0.202 and
    0.207 sampled at 240; the simulation's flight share is counted per physics step, so the 5-point
    bound on jogs was judged against a figure with up to two frames' (7.7 points') rounding in it.
    Sampling finer cannot restore what 30-fps frames lost: the generated jog made at 30, 60, 120
    and 240 fps reads 0.283, 0.242, 0.219 and 0.214 here (0.311, 0.244, 0.228, 0.214 at its own
    rate), against 0.178-0.194 by the generator's own contacts.

    >>> from stimuli.motion.generate import GaitParams, generate
    >>> reference_flight_fraction(generate(GaitParams(gait="walk"), 1.75))
    0.0
    """
    from stimuli.motion.contact import foot_contacts

    down = foot_contacts(finely_sampled(motion, FLIGHT_FPS)).down
    return round(float((~(down["l"] | down["r"])).mean()), 4)


def finely_sampled(motion, fps: float):
    """``motion`` at a whole multiple of its frame rate of at least ``fps`` (itself when it has as
    many frames already). A looped treadmill clip is sampled around its seam as well (the last frame
    runs on into the first), so the result is again a loop of the same period.

    >>> from stimuli.motion.generate import GaitParams, generate
    >>> walk = generate(GaitParams(), 1.75, fps=30, cycles=1)
    >>> fine = finely_sampled(walk, 240)
    >>> fine.fps, fine.n_frames == 8 * walk.n_frames
    (240.0, True)
    """
    import math

    k = math.ceil(fps / motion.fps - 1e-9)
    if k <= 1:
        return motion
    meta = motion.metadata
    if not (meta.get("looped") and meta.get("treadmill")):
        return motion.resample(float(motion.fps * k))
    return on_period(motion, motion.n_frames * k)


# The highest frame rate the physics takes a reference at. The gains were chosen, and every flight and
# tracking figure measured, on 30-fps loops; at their own 60 and 120 fps the same captures flew more
# (CMU 07_12 24.0 % against 9.4 %, 02_01 13.1 % against 0, 07_01 4.6 % against 0) because the
# clean-up's frame-counted corrections and the capture's frame-to-frame detail reach the PD targets.
REFERENCE_FPS = 30.0


def at_reference_rate(motion):
    """``(motion, resampled)``: a motion above :data:`REFERENCE_FPS` sampled at about that rate;
    any other unchanged. A treadmill loop keeps its exact period (its frame count scales, its rate
    moves by a fraction of a frame per loop: 106 frames at 60 fps become 53 at 30).

    >>> from stimuli.motion.generate import GaitParams, generate
    >>> walk = generate(GaitParams(), 1.75, fps=60, cycles=1)
    >>> low, resampled = at_reference_rate(walk)
    >>> resampled, low.n_frames * 2 == walk.n_frames, round(low.n_frames / low.fps, 6) == round(walk.n_frames / 60, 6)
    (True, True, True)
    """
    n = max(2, int(round(motion.n_frames * REFERENCE_FPS / motion.fps)))
    if n >= motion.n_frames:
        return motion, False
    meta = motion.metadata
    if not (meta.get("looped") and meta.get("treadmill")):
        low = motion.resample(REFERENCE_FPS)
        low.metadata.pop("contacts", None)   # per frame of the motion given
        return low, True
    return on_period(motion, n), True


def on_period(motion, n_frames: int):
    """A treadmill loop sampled at ``n_frames`` frames over its own period (the rate follows); its
    per-frame foot contacts (metadata ``contacts``) are taken from the nearest frame in time.

    >>> from stimuli.motion.generate import GaitParams, generate
    >>> walk = generate(GaitParams(), 1.75, fps=30, cycles=1)
    >>> fine = on_period(walk, 2 * walk.n_frames)
    >>> fine.metadata["contacts"]["l"][::2] == walk.metadata["contacts"]["l"]
    True
    """
    from stimuli.motion.loop import sample_periodic

    fps = n_frames * motion.fps / motion.n_frames
    rot, root = sample_periodic(motion, np.arange(n_frames) / fps)
    out = motion.replace(fps=float(fps), rotations=rot, root_translation=root)
    contacts = out.metadata.pop("contacts", None)
    if contacts and all(len(contacts.get(s, [])) == motion.n_frames for s in ("l", "r")):
        nearest = np.rint(np.arange(n_frames) * motion.n_frames / n_frames).astype(int) % motion.n_frames
        out.metadata["contacts"] = {s: [int(contacts[s][i]) for i in nearest] for s in ("l", "r")}
    return out


def loop_input(motion):
    """``(motion, looped_here)``: an overground capture (neither looped nor on a treadmill) becomes a
    treadmill loop of its gait (:func:`stimuli.motion.loop.capture_loop`); loops and treadmill clips
    pass unchanged. A capture with no steady straight cycle is refused, naming the command that
    loops it by hand (the simulation repeats its clip: an unlooped capture would jump at the seam
    and walk off the treadmill).
    """
    meta = motion.metadata
    if meta.get("looped") or meta.get("treadmill"):
        return motion, False
    from stimuli.motion.loop import capture_loop

    gait = motion_gait(motion)
    try:
        looped = capture_loop(motion, gait)
    except StimuliError as exc:
        raise StimuliError(f"{exc}. The COM method simulates loops: choose a range with `shapemotion motion import "
                           f"FILE --loop --gait {gait} --start S --end S`") from None
    looped.metadata.setdefault("gait", gait)
    return looped, True


def _body_row(body, weight_kg: float) -> dict:
    h = float(body.anthropometry.height_m)
    return {"body_id": body.body_id, "sex": body.sex, "height_m": round(h, 4), "weight_kg": round(weight_kg, 3),
            "bmi": round(weight_kg / h**2, 3)}


def on_reference_rig(motion, reference_body):
    """``(motion, retargeted_here)``: a walk that was not made on ``reference_body`` itself is
    retargeted onto that body's rig with the foot clean-up (:func:`stimuli.motion.retarget.retarget`)
    before it becomes the ragdoll's reference: a capture on its own skeleton, and an Anny-rig motion
    made on another body or on none (an average of several actors' retargeted captures, metadata
    ``source: average``, has no ``body_id``). Two kinds pass unchanged: a motion retargeted onto this
    very body (metadata ``body_id``), and the generator's canonical rig (generated gaits and their
    averages, whose feet the generator lays out on the body it is given). Runs keep their own
    skeleton: the clean-up moved the contact model's flight share of the Bandai runs' references by
    18 and 15 points (the dash 0.71 → 0.54, the tired jog 0.15 → 0.00), and their simulations flew
    11–26 points more than those references (CMU 35_17: 0.59 against 0.44; on its own skeleton 0.45).

    Why: followed bone by bone, a capture's own rest frames posed the ragdoll's feet on their sides
    (the CC4 rig's feet rolled 69–71°, Bandai's pitched 43–53° toe down, CMU's rolled 20–21° at
    mid-stance), stood its flat stance feet 0.5–2.5 cm above the floor and ran its belt 1–16 % faster
    than its posed stance feet moved. The average of the men's real walks (Exp 2, on the mean man's
    Anny rig) stood its stance feet 18-20 mm above the floor at the median: the body ran 29-32 mm
    below its target and the swing placement bent the swing knees 8-10° past the reference to keep
    the feet off the floor (tracking 3.4-4.1°; retargeted: 2.2-2.8°). Jog averages stay as they are:
    the clean-up cut the women's jog average's flight share from 0.62 to 0.15. The retargeting lays
    the feet flat on the body's own soles and runs the belt at the speed the body's legs carry a
    planted foot.
    """
    made_on_this_body = (list(motion.joint_names) == list(reference_body.rig.names)
                         and motion.metadata.get("body_id") == reference_body.body_id)
    if made_on_this_body or motion.metadata.get("naming") == "canonical" or motion_gait(motion) != "walk":
        return motion, False
    from stimuli.motion.retarget import retarget as onto_rig

    return onto_rig(motion, reference_body), True


def retarget(motion, body, weight_kg: float | None = None, reference_body=None, gains: Gains | None = None,
             min_simulated_s: float = 4.0, rate_hz: float = DEFAULT_RATE_HZ, raise_on_fall: bool = False,
             feedforward: bool = False, torque_limits: bool = False, swing_placement: bool | None = None,
             toes: bool | None = None, toe_segment: bool | None = None) -> RetargetResult:
    """Physics-based retargeting of ``motion`` onto ``body`` with Table-1 masses for ``weight_kg``.

    ``reference_body`` is the body the motion belongs to (for the balance factor b; default the
    target body itself, b = 0). ``gains`` default: the shipped set for the motion's gait
    (metadata ``gait``; walk when it has none). With ``raise_on_fall`` a fall raises :class:`RagdollFellError`
    (its ``.result`` holds the report); otherwise ``result.motion`` is None after a fall.
    The clip is simulated in whole passes, at least ``min_simulated_s`` in all (the paper's 4-s
    clips); the last pass is the COM motion, the ones before it are warm-up.
    ``feedforward``: add the inverse-dynamics torques of the motion on the *reference* body
    (:mod:`stimuli.physics.feedforward`) to the PD; ``torque_limits``: clamp every actuator to the
    human limits of :data:`stimuli.physics.controller.TORQUE_LIMITS_NM` (the same for every body).
    Both default off: the shipped controller is the paper's pure PD (readme: Controller variants).
    ``swing_placement`` (default: with the feed-forward, on walks): each swinging foot is placed in
    the world as the reference places it (:mod:`stimuli.physics.swing`). ``toes`` (default: with
    the feed-forward, on runs): where the motion stands on its toes, the reference's toe-less foot
    box stands on its ball (:mod:`stimuli.physics.toes`), for the PD and the feed-forward alike.
    ``toe_segment`` (default: on walks, :data:`stimuli.physics.ragdoll.TOES_BY_GAIT`): the ragdoll's
    feet have toes hinged at the ball that follow the motion's toe bend.
    An overground capture is looped first (:func:`loop_input`), one above 30 fps is simulated from
    about 30 fps (:func:`at_reference_rate`; the COM motion comes back at its own rate and frame
    count), and a capture is retargeted onto the reference body's rig (:func:`on_reference_rig`);
    ``result.motion`` is then the COM motion of that.
    """
    weight = float(body.anthropometry.mass_kg if weight_kg is None else weight_kg)
    inertia.check_weight(weight, float(body.anthropometry.height_m))
    motion, looped_here = loop_input(motion)
    given_fps, given_frames = motion.fps, motion.n_frames
    motion, resampled = at_reference_rate(motion)
    motion, onto_rig_here = on_reference_rig(motion, reference_body or body)
    ref, ragdoll, model, gains = prepare(motion, body, weight, gains, rate_hz, toe_segment)
    # Read on the motion as given, before the toes' grounding moves its root.
    under_gravity = reference_under_gravity(motion, ref, model)
    if swing_placement is None:
        swing_placement = bool(feedforward) and motion_gait(motion) == "walk"
    toes = bool(feedforward) and motion_gait(motion) != "walk" if toes is None else bool(toes)
    stance, toe_changes = None, None
    if swing_placement or toes:
        from stimuli.physics.feedforward import reference_stance

        stance = reference_stance(motion, ref.n_frames)
    if toes:
        from stimuli.physics.toes import stand_on_toes

        ref, toe_changes = stand_on_toes(ref, model, stance)
    if torque_limits:
        set_torque_limits(model)
    ff = None
    if feedforward:
        from stimuli.physics.feedforward import reference_feedforward

        ff = reference_feedforward(motion, reference_body or body, toes=toes, toe_segment=ragdoll.has_toes)
    warmup_loops = max(1, int(np.ceil(min_simulated_s / ref.period - 1.0 - 1e-9)))
    sim = simulate(model, ref, gains, warmup_loops=warmup_loops, rate_hz=rate_hz, feedforward=ff,
                   swing_stance=stance if swing_placement else None)
    out, nocom = None, None
    if not sim.fell:
        out = to_motion(motion, body, sim, ref, ragdoll)
        nocom = joint_rms_difference(motion, out, ref, ragdoll)
    report = build_report(sim, ragdoll, body, reference_body or body, weight, gains, nocom)
    report["controller"] = {"feedforward": bool(feedforward), "torque_limits": bool(torque_limits),
                            "swing_placement": bool(swing_placement), "toes": toes,
                            "toe_segment": ragdoll.has_toes}
    if toe_changes is not None:
        report["reference_on_toes"] = toe_changes
    report["reference_flight_fraction"] = reference_flight_fraction(motion)
    # What a body the floor only pushes can make of the reference (an average of runs can ask the
    # floor to pull: its own flight share is then out of reach of a body that follows it).
    report["reference_under_gravity"] = under_gravity
    # The same detector on the simulated motion: box contacts and the contact model read a run's flight
    # differently (Bandai's tired jog: 0.41 by the boxes, 0.13 by the contact model, its reference 0.14).
    report["flight_fraction_contact_model"] = reference_flight_fraction(out) if out is not None else None
    report["looped_input"] = looped_here
    report["retargeted_onto_reference_rig"] = onto_rig_here
    report["reference_fps"] = round(float(motion.fps), 4)
    if resampled:
        # Simulated from the reference rate; the COM motion comes back at the motion's own rate and length.
        report["resampled_from_fps"] = float(given_fps)
        if out is not None:
            out = on_period(out, given_frames).replace(fps=float(given_fps))
    result = RetargetResult(out, report, sim, ref, ragdoll)
    if sim.fell and raise_on_fall:
        err = RagdollFellError(f"the ragdoll of body {body.body_id} ({weight:.1f} kg) fell at "
                               f"t = {sim.fall_time_s:.2f} s: {sim.fall_reason}")
        err.result = result
        raise err
    return result
