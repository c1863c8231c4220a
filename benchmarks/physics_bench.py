"""COM method speed: wall-clock time per simulated second (≤ 1 means faster than real time).

Runs the ragdoll of a fitted body tracking a generated 4-s walk and jog (2 cycles each, looped,
one warm-up pass + one recorded pass), with the pure PD and with the feed-forward, and prints the
machine's load and, per gait and controller, simulated time, wall time of the
MuJoCo loop, their ratio, the simulation rate and the end-to-end time (reference + model build +
simulation + COM motion). Prints numbers; asserts nothing.

``--controllers OUT`` runs the Exp-2 protocol step twice, with the paper's pure PD and with the
PD plus the reference body's inverse-dynamics feed-forward (``OUT/pd``, ``OUT/pd_ff``: motions,
reports, Fig. 7), and prints per actor × gait the flight share against the reference's own,
tracking RMS, b, the knee flexion peaks and the torques over the human limits (issue 21's table).

    python benchmarks/physics_bench.py [--controllers OUT]
"""

from __future__ import annotations

import os
import time


def main() -> None:
    from stimuli.bodies import fit_body
    from stimuli.motion.generate import DEFAULT_PACE, GaitParams, generate
    from stimuli.physics import retarget

    body = fit_body("M", 1.83, 35.8)
    reference = fit_body("M", 1.81, 28.1)
    print(f"load average (1 min) {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    print(f"{'gait':<6}{'controller':<8}{'simulated_s':>12}{'wall_s':>9}{'wall/sim':>10}{'rate_hz':>9}{'end_to_end_s':>14}")
    for gait, (cadence, speed) in DEFAULT_PACE.items():
        motion = generate(GaitParams(gait=gait, cadence_spm=cadence, speed_mps=speed), height_m=1.81, fps=30, cycles=2)
        for name, ff in (("pd", False), ("pd+ff", True)):
            start = time.perf_counter()
            rep = retarget(motion, body, 119.9, reference_body=reference, feedforward=ff).report
            total = time.perf_counter() - start
            print(f"{gait:<6}{name:<8}{rep['simulated_s']:>12.2f}{rep['wall_s']:>9.2f}{rep['wall_per_simulated']:>10.3f}"
                  f"{rep['rate_hz']:>9.0f}{total:>14.2f}")


def compare_controllers(out: str, protocol: str = "protocols/exp2_com_vs_average.yaml") -> None:
    """The Exp-2 table of both controller readings (see the module docstring)."""
    from pathlib import Path

    from stimuli.physics.protocol_step import run_protocol

    print("controller actor gait ref_flight sim_flight tracking_deg b_mm knee_swing_peak knee_stance_peak "
          "over_limit(dof:peak/limit) fell wall_s")
    for name, ff in (("pd", False), ("pd_ff", True)):
        start = time.perf_counter()
        try:
            reports = run_protocol(protocol, Path(out) / name, feedforward=ff)["reports"]
        except Exception as exc:   # a fall: the reports are still on disk
            print(f"{name}: {exc}")
            import json
            reports = [json.loads(p.read_text()) for p in sorted((Path(out) / name / "reports").glob("*.json"))]
        wall = time.perf_counter() - start
        for r in sorted(reports, key=lambda r: (r["gait"], r["actor"])):
            over = [f"{d}:{v['peak']:.0f}/{v['limit']:.0f}" for d, v in r.get("torque_peaks_nm", {}).items()
                    if v["peak"] > v["limit"]]
            print(f"{name} {r['actor']} {r['gait']} {r.get('reference_flight_fraction')} {r['flight_fraction']} "
                  f"{r['tracking_rms_deg_overall']} {1000 * r['b_m']:.2f} {r.get('knee_flexion_peak_deg')} "
                  f"{r.get('knee_flexion_stance_peak_deg')} {','.join(over) or '-'} {r['fell']} {wall:.0f}")


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--controllers", metavar="OUT", help="Exp-2 table of pure PD vs PD + feed-forward")
    args = parser.parse_args()
    compare_controllers(args.controllers) if args.controllers else main()
