"""COM method speed: wall-clock time per simulated second (≤ 1 means faster than real time).

Runs the ragdoll of a fitted body tracking a generated 4-s walk and jog (2 cycles each, looped,
one warm-up pass + one recorded pass) and prints, per gait, simulated time, wall time of the
MuJoCo loop, their ratio, the simulation rate and the end-to-end time (reference + model build +
simulation + COM motion). Prints numbers; asserts nothing.

    python benchmarks/physics_bench.py
"""

from __future__ import annotations

import time


def main() -> None:
    from stimuli.bodies import fit_body
    from stimuli.motion.generate import DEFAULT_PACE, GaitParams, generate
    from stimuli.physics import retarget

    body = fit_body("M", 1.83, 35.8)
    reference = fit_body("M", 1.81, 28.1)
    print(f"{'gait':<6}{'simulated_s':>12}{'wall_s':>9}{'wall/sim':>10}{'rate_hz':>9}{'end_to_end_s':>14}")
    for gait, (cadence, speed) in DEFAULT_PACE.items():
        motion = generate(GaitParams(gait=gait, cadence_spm=cadence, speed_mps=speed), height_m=1.81, fps=30, cycles=2)
        start = time.perf_counter()
        rep = retarget(motion, body, 119.9, reference_body=reference).report
        total = time.perf_counter() - start
        print(f"{gait:<6}{rep['simulated_s']:>12.2f}{rep['wall_s']:>9.2f}{rep['wall_per_simulated']:>10.3f}"
              f"{rep['rate_hz']:>9.0f}{total:>14.2f}")


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()   # --help, and no stray arguments
    main()
