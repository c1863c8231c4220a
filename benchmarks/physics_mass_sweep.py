"""Does segment mass change knee flexion under the fixed-gain PD controller? (Fig. 7's claim)

The paper reports lower knee flexion for higher-BMI characters. This script isolates mass from
body geometry: one fitted body (Exp 2's female or male reference body) tracks the protocol's NoCOM
walk (the DTW average of the sex's actors) at 0.7×, 1× and 1.5× its own weight, with the shipped
gains scaled by 1, 1/4 and 1/10 (``k_d`` by the square root, so the damping ratio stays). It prints
the joint-centre knee flexion peaks (swing = the cycle's maximum, stance = first 40 %) against the
reference's, the tracking RMS and whether the ragdoll fell. Prints numbers; asserts nothing.

``--strength`` asks the other way a fixed controller could make mass show: at the shipped gains,
every actuator's torque is limited, per direction, to what the body needs at its own weight (its
peak over the recorded pass, times ``--margin``): the same muscles carrying more mass. ``--gait
jog`` sweeps the jog (its own gains) instead of the walk.

``--gain-scales 0.03,0.01`` sweeps other gain scales (the shipped set is 1, 0.25, 0.1).

``--balance-offset`` asks whether the paper's balance point (§4.2, Fig. 6) could lower the heavier
actors' knees: each of the protocol's test actors of the sex walks at the shipped gains, once as
shipped and once with its root target moved by ``--offset-scale`` × the vertical part of its own
``C − C′`` (``inertia.paper_com_shift``: where Table 1 puts the CoM against the uniform-density
body; lean bodies' Table-1 CoM sits 1–2 cm above, the heaviest men's below), so that a root force
placing the balance point would lower or raise the pelvis by that much.

    python benchmarks/physics_mass_sweep.py [--sex F|M] [--gait walk|jog] [--gain-scales S,...]
                                            [--strength [--margin 1.0]]
                                            [--balance-offset [--offset-scale 1.0]]
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

PROTOCOL = Path(__file__).resolve().parents[1] / "protocols" / "exp2_com_vs_average.yaml"
WEIGHT_FACTORS = (0.7, 1.0, 1.5)
GAIN_SCALES = (1.0, 0.25, 0.1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sex", choices=("F", "M"), default="M")
    parser.add_argument("--gait", choices=("walk", "jog"), default="walk")
    parser.add_argument("--strength", action="store_true", help="limit torques to the own-weight peaks")
    parser.add_argument("--margin", type=float, default=1.0, help="limits = own-weight peaks × margin")
    parser.add_argument("--gain-scales", type=_scales, default=GAIN_SCALES, help="comma-separated k_p factors")
    parser.add_argument("--balance-offset", action="store_true",
                        help="each test actor with its root target moved by its own C − C′ (vertical)")
    parser.add_argument("--offset-scale", type=float, default=1.0, help="multiplies the balance offset")
    args = parser.parse_args()
    sex, gait = args.sex, args.gait
    if args.balance_offset:
        balance_offsets(sex, gait, args.offset_scale)
        return

    from stimuli.bodies import fit_body
    from stimuli.motion.average import protocol_average
    from stimuli.motion.loop import cycles_for_clip
    from stimuli.physics import Gains
    from stimuli.physics.analysis_fig7 import reference_heel_strike_s
    from stimuli.protocol import load_protocol

    protocol = load_protocol(PROTOCOL)
    cycles = cycles_for_clip(protocol.clip.duration_s, protocol.gaits[gait].cadence_spm)
    motion = protocol_average(protocol, sex, gait, cycles=cycles)  # as the physics step makes it
    body = fit_body(sex, motion.metadata["height_m"], motion.metadata["bmi"])
    own = float(body.anthropometry.mass_kg)
    start = reference_heel_strike_s(motion)
    n_cycles = int(motion.metadata.get("cycles", 2))  # gait cycles in the clip
    shipped = Gains.load(gait=gait)
    print(f"{sex} reference body {body.body_id} ({own:.1f} kg), NoCOM {gait} of {', '.join(motion.metadata['actors'])}")
    print(f"{'gain×':>6}{'kg':>7}{'swing°':>8}{'ref':>7}{'Δ':>7}{'stance°':>9}{'ref':>7}{'Δ':>7}{'rms°':>7}  fell")
    if args.strength:
        limits = torque_peaks(run(motion, body, own, shipped), args.margin)
        for factor in WEIGHT_FACTORS:
            print_row(f"{args.margin:>5.2f}s", own * factor, run(motion, body, own * factor, shipped, limits), start, n_cycles)
        return
    for scale in args.gain_scales:
        gains = dataclasses.replace(shipped, k_p=shipped.k_p * scale, k_d=shipped.k_d * np.sqrt(scale))
        for factor in WEIGHT_FACTORS:
            print_row(f"{scale:>6.2f}", own * factor, run(motion, body, own * factor, gains), start, n_cycles)


def balance_offsets(sex: str, gait: str, scale: float) -> None:
    """Knee peaks of every test actor of ``sex``, as shipped and with the balance offset."""
    from unittest import mock

    import stimuli.physics.simulate as simulate_module
    from stimuli.bodies import fit_body
    from stimuli.physics import Gains, inertia
    from stimuli.physics.analysis_fig7 import reference_heel_strike_s
    from stimuli.physics.protocol_step import nocom_motion
    from stimuli.protocol import load_protocol

    protocol = load_protocol(PROTOCOL)
    motion = nocom_motion(protocol, sex, gait, None)   # as the physics step makes it
    start, n_cycles = reference_heel_strike_s(motion), int(motion.metadata.get("cycles", 2))
    gains = Gains.load(gait=gait)
    lift = simulate_module.ground_offset
    print(f"{sex} test actors, NoCOM {gait}, shipped gains; offset = {scale:g} × (C − C′) vertical")
    print(f"{'actor':>6}{'BMI':>7}{'mm':>7}{'swing°':>8}{'ref':>7}{'Δ':>7}{'stance°':>9}{'ref':>7}{'Δ':>7}{'rms°':>7}  fell")
    for actor in (a for a in protocol.actors if a.sex == sex and not a.practice_only):
        body = fit_body(sex, actor.height_m, actor.bmi)
        weight = float(body.anthropometry.mass_kg)
        offset = scale * float(inertia.paper_com_shift(body.segments, weight)[1])
        print_row(actor.id, actor.bmi, run(motion, body, weight, gains), start, n_cycles, extra=f"{0:>7.1f}")
        # ground_offset lifts the root targets until the feet reach the floor, which would undo a
        # shift of the targets themselves: the offset is added to the lift instead
        with mock.patch.object(simulate_module, "ground_offset", lambda model, ref: lift(model, ref) + offset):
            print_row("", actor.bmi, run(motion, body, weight, gains), start, n_cycles, extra=f"{offset * 1000:>+7.1f}")


def _scales(text: str) -> tuple[float, ...]:
    """``"1,0.1"`` → ``(1.0, 0.1)``; positive factors only."""
    try:
        scales = tuple(float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None
    if not scales or min(scales) <= 0:
        raise argparse.ArgumentTypeError(f"gain scales must be > 0, got {text!r}")
    return scales


def run(motion, body, weight_kg: float, gains, limits: dict | None = None):
    """Simulate ``motion`` on ``body`` at ``weight_kg``, actuators limited to ``limits`` (N·m) if given."""
    from stimuli.physics.retarget import prepare, tracking_rms
    from stimuli.physics.simulate import simulate

    ref, ragdoll, model, gains = prepare(motion, body, weight_kg, gains)
    for name, (low, high) in (limits or {}).items():
        a = model.actuator(name).id
        model.actuator_forcelimited[a] = 1
        model.actuator_forcerange[a] = (low, high)
    warmup = max(1, int(np.ceil(4.0 / ref.period - 1.0 - 1e-9)))  # as retarget: ≥ 4 s simulated
    sim = simulate(model, ref, gains, warmup_loops=warmup)
    track = list(tracking_rms(sim, ragdoll).values())
    return sim, ragdoll, float(np.sqrt(np.mean(np.square(track))))


def torque_peaks(result, margin: float) -> dict[str, tuple[float, float]]:
    """Per actuator, the lowest and highest torque of the recorded pass, times ``margin``."""
    sim = result[0]
    return {name: (margin * float(low), margin * float(high))
            for name, low, high in zip(sim.dof_names, sim.actuator_force.min(axis=0), sim.actuator_force.max(axis=0))}


def print_row(label: str, value: float, result, start: float, n_cycles: int, extra: str = "") -> None:
    """One table row: ``label``, ``value`` (kg or BMI), ``extra`` (pre-formatted), then the peaks."""
    from stimuli.physics.analysis_fig7 import gait_curves

    sim, ragdoll, rms = result
    if sim.fell:
        print(f"{label:>6}{value:>7.1f}{extra}  fell at {sim.fall_time_s:.2f} s: {sim.fall_reason}")
        return
    c = gait_curves(sim, ragdoll, n_cycles, start)
    ref = np.array(c["reference_knee_flexion_deg"])
    ref_stance = float(ref[:41].max())
    print(f"{label:>6}{value:>7.1f}{extra}{c['knee_flexion_peak_deg']:>8.2f}{ref.max():>7.2f}"
          f"{c['knee_flexion_peak_change_deg']:>+7.2f}{c['knee_flexion_stance_peak_deg']:>9.2f}{ref_stance:>7.2f}"
          f"{c['knee_flexion_stance_peak_deg'] - ref_stance:>+7.2f}{rms:>7.2f}  no")


if __name__ == "__main__":
    main()
