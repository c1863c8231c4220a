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

``--captures OUT`` runs the same protocol step with NoCOM averages of real captures: Exp 2 with
each test actor naming a capture of ``../shared/data/mocap`` per gait (:data:`CAPTURES`, fixed
before any run: 7 distinct walks, the 3 runs, split between the sexes), looped from their steady
straight ranges, retargeted onto the sex's mean body and DTW-averaged; then PD and PD +
feed-forward (gains chosen per average) on the 12 bodies (``OUT/pd``, ``OUT/pd_ff``), with the
acceptance figures (fall, flight against the average's own, tracking, b against the weight gap).

``--single-support CAPTURE ...`` (paths under ``../shared/data/mocap``) looks at each looped walk's
single-support frames on the base character (PD + feed-forward) and splits the pelvis's distance
below its target into its parts: the posed reference's stance foot above the floor (the target
itself), the simulated foot's depth in the floor, and what the stance leg's joint errors and the
pelvis's orientation error account for; beside them the stance knee's PD and feed-forward torques
and the root spring's forward tow (issue 21's "single-support sag").

``--ballistic MOTION ...`` (NoCOM averages as .npz, or runs under ``../shared/data/mocap``) prints
each run's flight share by the contact model beside the share a body under gravity alone would
have, leaving and landing as the run does, and the share of a body that follows the run's centre
of mass wherever a floor that only pushes allows it, with the pull the run asks of the floor
(issue 21's men's capture-average jog).

    python benchmarks/physics_bench.py [--controllers OUT | --captures OUT | --single-support CAPTURE ... |
                                        --ballistic MOTION ...]
"""

from __future__ import annotations

import os
import time
from pathlib import Path


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


MOCAP = Path(__file__).resolve().parents[2] / "shared" / "data" / "mocap"
# Exp-2 test actor -> capture per gait (../shared/data/mocap). Seven distinct walks import to a
# loop (06_10 does not); the eighth actor takes the metres copy of 131_02 (the same take). Only
# three runs exist, so each sex's jog average holds all three and repeats one.
CAPTURES = {
    "F_Hi1": ("more/bandai1_walk_normal_001_30fps.bvh", "more/bandai1_run_tired_001_jog_30fps.bvh"),
    "F_Hi2": ("more/cmu_07_01_walk_cc4rig_60fps.bvh", "more/bandai1_dash_active_001_run_30fps.bvh"),
    "F_Lo1": ("more/cmu_07_12_brisk_walk_cc4rig_60fps_tpose_frame0.bvh", "cmu_35_17_run.bvh"),
    "F_Lo2": ("more/cmu_131_02_start_walk_stop_maxnames_120fps.bvh", "more/bandai1_run_tired_001_jog_30fps.bvh"),
    "M_Hi1": ("cmu_35_01_walk.bvh", "cmu_35_17_run.bvh"),
    "M_Hi2": ("more/cmu_02_01_walk_mb2names_120fps.bvh", "more/bandai1_run_tired_001_jog_30fps.bvh"),
    "M_Lo1": ("more/cmu_07_02_walk_cc4rig_60fps_NOTOES_derived.bvh", "more/bandai1_dash_active_001_run_30fps.bvh"),
    "M_Lo2": ("more/cmu_131_02_start_walk_stop_maxnames_120fps_meters.bvh", "cmu_35_17_run.bvh"),
}


def captures_protocol(out: Path, protocol: str = "protocols/exp2_com_vs_average.yaml") -> Path:
    """Exp 2 with every test actor naming its captures (:data:`CAPTURES`), written to ``out``."""
    import yaml

    data = yaml.safe_load(Path(protocol).read_text())
    for actor in data["actors"]:
        if actor["id"] in CAPTURES:
            actor["motions"] = dict(zip(("walk", "jog"), (str(MOCAP / f) for f in CAPTURES[actor["id"]])))
    data["name"] = "exp2_captures"
    out.mkdir(parents=True, exist_ok=True)
    path = out / "exp2_captures.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def compare_controllers(out: str, protocol: str = "protocols/exp2_com_vs_average.yaml") -> None:
    """The Exp-2 table of both controller readings (see the module docstring)."""
    import resource

    from stimuli.physics.protocol_step import run_protocol

    print("controller actor gait ref_flight ref_flight_under_gravity sim_flight sim_flight_contact_model tracking_deg b_mm weight_gap_kg gain_scale knee_swing_peak "
          "knee_stance_peak over_limit(dof:peak/limit) fell wall_s cpu_s")
    for name, ff in (("pd", False), ("pd_ff", True)):
        start, cpu = time.perf_counter(), _cpu_s(resource)
        try:
            reports = run_protocol(protocol, Path(out) / name, feedforward=ff)["reports"]
        except Exception as exc:   # a fall: the reports are still on disk
            print(f"{name}: {exc}")
            import json
            reports = [json.loads(p.read_text()) for p in sorted((Path(out) / name / "reports").glob("*.json"))]
        wall, cpu = time.perf_counter() - start, _cpu_s(resource) - cpu
        for r in sorted(reports, key=lambda r: (r["gait"], r["actor"])):
            over = [f"{d}:{v['peak']:.0f}/{v['limit']:.0f}" for d, v in r.get("torque_peaks_nm", {}).items()
                    if v["peak"] > v["limit"]]
            gap = r["body"]["weight_kg"] - r["reference_body"]["weight_kg"]
            print(f"{name} {r['actor']} {r['gait']} {r.get('reference_flight_fraction')} "
                  f"{r.get('reference_under_gravity', {}).get('flight_fraction')} {r['flight_fraction']} "
                  f"{r.get('flight_fraction_contact_model')} "
                  f"{r['tracking_rms_deg_overall']} {1000 * r['b_m']:.2f} {gap:+.1f} {r.get('gain_choice', {}).get('scale', 1)} "
                  f"{r.get('knee_flexion_peak_deg')} {r.get('knee_flexion_stance_peak_deg')} {','.join(over) or '-'} "
                  f"{r['fell']} {wall:.0f} {cpu:.0f}")
        print(f"{name}: wall {wall:.1f} s, CPU {cpu:.1f} s (this process and its workers), "
              f"load average (1 min) {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")


def single_support_budget(motion, body) -> dict[str, dict[str, float]]:
    """Means over the single-support frames (``all``) and over those with the pelvis more than 2 cm
    below its target (``sag``) of the simulated walk's pelvis height budget (m), torques (N·m) and
    root tow (N); see the module docstring."""
    import mujoco
    import numpy as np

    from stimuli.physics.feedforward import reference_feedforward
    from stimuli.physics.retarget import prepare, retarget

    sim = retarget(motion, body, feedforward=True).sim
    _, _, model, gains = prepare(motion, body)   # the same model and shipped gains retarget used
    ff = reference_feedforward(motion, body)
    data = mujoco.MjData(model)
    qadr = np.array([model.jnt_qposadr[model.actuator_trnid[a, 0]] for a in range(model.nu)])
    k = len(sim.actuator_force) // len(sim.q)
    fps = 1.0 / (sim.times[1] - sim.times[0])

    def stance_leg(qpos, side):   # pelvis height over the foot's lowest corner, that corner's height
        data.qpos[:] = qpos
        mujoco.mj_kinematics(model, data)
        g = model.geom(f"foot.{side}").id
        corners = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)], float) * model.geom_size[g]
        low = float((data.geom_xpos[g][:, None] + data.geom_xmat[g].reshape(3, 3) @ corners.T)[1].min())
        return float(data.xpos[model.body("pelvis").id][1]) - low, low

    rows = []
    for i in range(1, len(sim.q) - 1):
        down = sim.foot_contact[i * k:(i + 1) * k].mean(0) > 0.5
        if down.sum() != 1:
            continue
        s = "LR"[int(np.argmax(down))]
        qs = sim.qpos[i]
        qr = qs.copy()
        qr[:3], qr[3:7], qr[qadr] = sim.root_target[i], sim.root_target_quat[i], sim.qref[i]
        h_sim, low_sim = stance_leg(qs, s)
        h_ref, low_ref = stance_leg(qr, s)
        parts = {}
        for joint in ("hip", "knee", "ankle", "root"):
            qx = qs.copy()
            if joint == "root":
                qx[3:7] = qr[3:7]
            else:
                idx = [j for j, d in enumerate(sim.dof_names) if d.startswith(f"{joint}.{s}")]
                qx[qadr[idx]] = qr[qadr[idx]]
            parts[joint] = stance_leg(qx, s)[0] - h_sim
        knee = sim.dof_names.index(f"knee.{s}")
        v_sim = (sim.qpos[i + 1, :3] - sim.qpos[i - 1, :3]) * fps / 2
        v_ref = (sim.root_target[i + 1] - sim.root_target[i - 1]) * fps / 2
        tow = gains.k_pf * (sim.root_target[i] - qs[:3]) + gains.k_df * (v_ref - v_sim)
        knee_error = sim.qref[i][knee] - sim.q[i][knee]
        rows.append({"pelvis_below_target_m": sim.root_target[i][1] - qs[1], "reference_foot_above_floor_m": low_ref,
                     "foot_depth_m": -low_sim, "leg_joints_m": parts["hip"] + parts["knee"] + parts["ankle"],
                     "pelvis_orientation_m": parts["root"], "knee_error_deg": np.degrees(knee_error),
                     "knee_pd_nm": model.actuator_gainprm[knee, 0] * knee_error,
                     "knee_feedforward_nm": ff.torque[i % len(ff.torque), knee],
                     "knee_total_nm": sim.actuator_force[i * k:(i + 1) * k, knee].mean(),
                     "root_tow_forward_n": tow[2], "pelvis_trail_m": sim.root_target[i][2] - qs[2]})
    sag = [r for r in rows if r["pelvis_below_target_m"] > 0.02]
    return {name: {key: float(np.mean([r[key] for r in group])) if group else float("nan") for key in rows[0]}
            | {"frames": len(group)} for name, group in (("all", rows), ("sag", sag))}


def single_support_table(captures: list[str]) -> None:
    """Print :func:`single_support_budget` per capture (base character M 1.75 m BMI 23, 30 fps loops)."""
    from stimuli.bodies import fit_body
    from stimuli.motion.bvh import read_bvh
    from stimuli.motion.loop import capture_loop

    body = fit_body("M", 1.75, 23.0)
    for name in captures:
        motion = capture_loop(read_bvh(MOCAP / name), "walk")
        motion = motion.resample(30.0) if motion.fps > 30 else motion
        for group, means in single_support_budget(motion, body).items():
            print(name, group, " ".join(f"{key} {value:.4g}" for key, value in means.items()), flush=True)


def ballistic_flight(motion, body) -> dict[str, float]:
    """The motion's flight share by the contact model (``contact_model``) beside two shares under
    physics, its reference posed on the ragdoll of ``body`` (its segment masses) at 8 × its frame
    rate: ``ballistic``, each flight phase lasting as long as a body leaving the floor with the
    reference's centre of mass height and vertical speed at take-off takes to fall back to its
    centre of mass height at landing; and ``pushing_floor`` with the pull it needs
    (:func:`stimuli.physics.attainable.pushing_floor_flight`: the body follows the centre of mass
    wherever a floor that only pushes allows it). A real capture's three agree within a few points;
    a motion whose flight is not ballistic (an average of runs with different flights) cannot have
    its own flight share under physics."""
    import numpy as np

    from stimuli.motion.contact import foot_contacts
    from stimuli.motion.footfix import contact_runs
    from stimuli.physics.attainable import com_heights, pushing_floor_flight
    from stimuli.physics.controller import motion_gait
    from stimuli.physics.ragdoll import TOES_BY_GAIT, build_ragdoll, compile_model
    from stimuli.physics.reference import build_reference
    from stimuli.physics.retarget import finely_sampled

    toes = TOES_BY_GAIT[motion_gait(motion)]
    ref, ragdoll = build_reference(motion, body, lambda axes: build_ragdoll(body, None, axes, toes=toes))
    ones = {d: 1.0 for d in ragdoll.dof_names}
    com, rate = com_heights(ref, compile_model(ragdoll, 1e-3, ones, ones))
    speed = (np.roll(com, -1) - np.roll(com, 1)) * rate / 2          # the clip is a loop
    down = foot_contacts(finely_sampled(motion, rate)).down
    down = down["l"] | down["r"]
    if len(down) != len(com):
        raise ValueError(f"contacts have {len(down)} samples, the pose {len(com)}")
    pushing = pushing_floor_flight(com, rate, down)
    flight = ~down
    n, extra = len(flight), 0.0
    shift, phases = contact_runs(flight, cyclic=True)    # rolled to start on the floor
    com, speed = np.roll(com, -shift), np.roll(speed, -shift)
    for start, stop in phases:
        y0, v0, y1 = com[start - 1], speed[start - 1], com[stop % n]
        # Falling and already below its landing height at take-off, a ballistic body lands at once.
        fall = max(0.0, (v0 + np.sqrt(max(v0 ** 2 + 2 * 9.81 * (y0 - y1), 0.0))) / 9.81)
        extra += fall - (stop - start + 1) / rate
    return {"contact_model": float(flight.mean()), "ballistic": float(flight.mean() + extra * rate / n),
            "pushing_floor": pushing["flight_fraction"], "pull": pushing["pull_mps_per_s"],
            "pull_foot_down": pushing["pull_with_foot_down_mps_per_s"], "highest_over_m": pushing["highest_over_m"]}


def ballistic_table(paths: list[str]) -> None:
    """Print :func:`ballistic_flight` per motion: a NoCOM average (.npz, on its sex's body of its
    metadata's height and BMI) or a capture under ``../shared/data/mocap`` (looped, ~30 fps, on
    the base character)."""
    from stimuli.bodies import fit_body
    from stimuli.motion import Motion
    from stimuli.motion.bvh import read_bvh
    from stimuli.motion.loop import capture_loop

    for name in paths:
        if name.endswith(".npz"):
            motion = Motion.load(name)
            meta = motion.metadata
            body = fit_body(meta["sex"], meta["height_m"], meta["bmi"])
        else:
            motion = capture_loop(read_bvh(MOCAP / name), "jog")
            motion = motion.resample(30.0) if motion.fps > 30 else motion
            body = fit_body("M", 1.75, 23.0)
        shares = ballistic_flight(motion, body)
        print(f"{name} flight {shares['contact_model']:.3f} (contact model), {shares['ballistic']:.3f} under gravity "
              f"alone, {shares['pushing_floor']:.3f} on a floor that only pushes ({100 * shares['highest_over_m']:.1f} cm "
              f"over its centre of mass; pull {shares['pull']:.2f} m/s per s, {shares['pull_foot_down']:.2f} with a foot "
              "down)", flush=True)


def _cpu_s(resource) -> float:
    """CPU seconds of this process and its finished child processes (the protocol step's workers)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--controllers", metavar="OUT", help="Exp-2 table of pure PD vs PD + feed-forward")
    parser.add_argument("--captures", metavar="OUT", help="the same on NoCOM averages of the real captures")
    parser.add_argument("--single-support", nargs="+", metavar="CAPTURE",
                        help="single-support pelvis height budget of these looped walks (../shared/data/mocap)")
    parser.add_argument("--ballistic", nargs="+", metavar="MOTION",
                        help="flight share of these runs (NoCOM .npz or ../shared/data/mocap captures) beside "
                             "the share under gravity alone")
    args = parser.parse_args()
    if args.ballistic:
        ballistic_table(args.ballistic)
    elif args.single_support:
        single_support_table(args.single_support)
    elif args.captures:
        compare_controllers(args.captures, str(captures_protocol(Path(args.captures))))
    else:
        compare_controllers(args.controllers) if args.controllers else main()
