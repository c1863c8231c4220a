"""Does segment mass change knee flexion under the fixed-gain PD controller? (Fig. 7's claim)

The paper reports lower knee flexion for higher-BMI characters. This script isolates mass from
body geometry: one fitted body (Exp 2's female or male reference body) tracks the protocol's NoCOM
walk (the DTW average of the sex's actors) at 0.7×, 1× and 1.5× its own weight, with the shipped
gains scaled by 1, 1/4 and 1/10 (``k_d`` by the square root, so the damping ratio stays). It prints
the joint-centre knee flexion peaks (swing = the cycle's maximum, stance = first 40 %) against the
reference's, the tracking RMS and whether the ragdoll fell. Prints numbers; asserts nothing.

    python benchmarks/physics_mass_sweep.py [--sex F|M]
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
    sex = parser.parse_args().sex

    from stimuli.bodies import fit_body
    from stimuli.motion.average import protocol_average
    from stimuli.motion.loop import cycles_for_clip
    from stimuli.physics import Gains, retarget
    from stimuli.physics.analysis_fig7 import gait_curves, reference_heel_strike_s
    from stimuli.protocol import load_protocol

    protocol = load_protocol(PROTOCOL)
    cycles = cycles_for_clip(protocol.clip.duration_s, protocol.gaits["walk"].cadence_spm)
    motion = protocol_average(protocol, sex, "walk", cycles=cycles)  # as the physics step makes it
    body = fit_body(sex, motion.metadata["height_m"], motion.metadata["bmi"])
    own = float(body.anthropometry.mass_kg)
    start = reference_heel_strike_s(motion)
    shipped = Gains.load()
    print(f"{sex} reference body {body.body_id} ({own:.1f} kg), NoCOM walk of {', '.join(motion.metadata['actors'])}")
    print(f"{'gain×':>6}{'kg':>7}{'swing°':>8}{'ref':>7}{'Δ':>7}{'stance°':>9}{'ref':>7}{'Δ':>7}{'rms°':>7}  fell")
    for scale in GAIN_SCALES:
        gains = dataclasses.replace(shipped, k_p=shipped.k_p * scale, k_d=shipped.k_d * np.sqrt(scale))
        for factor in WEIGHT_FACTORS:
            result = retarget(motion, body, own * factor, reference_body=body, gains=gains)
            rep = result.report
            if result.sim.fell:
                print(f"{scale:>6.2f}{own * factor:>7.1f}  fell at {rep['fall_time_s']:.2f} s: {rep['fall_reason']}")
                continue
            c = gait_curves(result.sim, result.ragdoll, int(motion.metadata.get("cycles", 2)), start)
            ref = np.array(c["reference_knee_flexion_deg"])
            ref_stance = float(ref[:41].max())
            print(f"{scale:>6.2f}{own * factor:>7.1f}{c['knee_flexion_peak_deg']:>8.2f}{ref.max():>7.2f}"
                  f"{c['knee_flexion_peak_change_deg']:>+7.2f}{c['knee_flexion_stance_peak_deg']:>9.2f}{ref_stance:>7.2f}"
                  f"{c['knee_flexion_stance_peak_deg'] - ref_stance:>+7.2f}{rep['tracking_rms_deg_overall']:>7.2f}  no")


if __name__ == "__main__":
    main()
