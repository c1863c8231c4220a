"""Motion benchmark: import times per capture; generation, retargeting and metric times per 4 s clip, and
the quality figures.

Prints the BVH import time of every capture in ``../shared/data/mocap`` (both folders; the issue's
bound is 2 s per capture with loop extraction and clean-up) with what the import detected and
dropped; then, for the 8 actors of Exp 1 and both gaits: generation time, retargeting time onto the
actor's fitted Anny body, mesh-metric time, and Penetrate / Float / Skate / unstable %; the same for
the CMU captures retargeted onto every actor; loop seam error; the thesis worked-example error.
``--import-only`` stops after the import times; ``--loop-only`` prints, per capture, import + loop
extraction (``capture_loop``: steady-range search, best-closing cycles, heading drift, belt) and what
the loop took, then stops. ``--cleanup`` prints, per capture, the default clean-up's figures on a
1.80 m BMI-27 man (``capture_loop`` → ``retarget`` → ``motion_quality`` on the mesh): Skate (HUMOS %),
slip (PhysDiff/PHC mm), Penetrate mean/max and Float (mm), the largest knee flexion and the largest
knee change between two 30-fps frames of the result and of the loop before retargeting, the largest /
RMS joint change from the retargeted source, the CPU seconds of retarget + clean-up, and the share of
the loop's frames with neither foot down by the shared contact model (``contact.foot_contacts`` on
the capture's own skeleton: what the physics step's gain choice reads), and the largest turn of a
foot between two 30-fps frames, cleaned and retargeted without the clean-up (``dfoot``, ``src``:
a foot snapping at lift-off or landing), and how far a knee bends backwards past straight, cleaned
and in the loop (``hyper``, ``src``: the unsigned knee figures read a hyperextended knee as flexed);
then stops. ``--table2``
prints issue 20's acceptance table: every capture that loops (its gait as above), on each of
Table 2's eight bodies (the Exp-1 test actors), against the bounds — Skate ≤ 5 % (HUMOS),
Penetrate and Float ≤ 10 mm, walk knee-flexion peaks (each leg's largest) inside the CGM2.3
normative walk's peak mean ± 3 SD, no T-pose frame (arm abduction under the import's 30°), loop
seam no larger than the clip's own frame-to-frame change (``seam_error``: the seam's acceleration
and its step, each over the clip's own 99th percentile, ≤ 1), knees bent backwards past straight
no further than the loop's own (or straight) + 2° (``hyper``) — with the
joint change from the retargeted source and the CPU seconds of import + loop + retarget per
capture (bound: 2 s); then the worst per file and the refusal of a capture that gives no loop.
Numbers only, no assertions.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MOCAP = ROOT.parent / "shared" / "data" / "mocap"


def capture_files(paths: list[str] | None = None) -> list[Path]:
    """The captures to measure: ``paths`` (e.g. a lab's own files, or a hold-out kept unseen), else
    every BVH in ``../shared/data/mocap`` and its ``more/`` folder."""
    if paths:
        return [Path(p) for p in paths]
    return sorted(MOCAP.glob("*.bvh")) + sorted((MOCAP / "more").glob("*.bvh"))


def capture_gait(path: Path) -> str:
    """The gait a capture is measured as, from its file name: jog for a run, jog or dash, else walk."""
    return "jog" if any(w in path.name for w in ("run", "jog", "dash")) else "walk"


def _name(path: Path) -> str:
    """A capture's label: its path under ``../shared/data/mocap``, else as given."""
    try:
        return str(path.resolve().relative_to(MOCAP.resolve()))
    except ValueError:
        return str(path)


def import_times(files: list[Path], repeats: int = 3) -> None:
    """Best-of-``repeats`` wall time of ``read_bvh`` per capture, with the file's size and what was found."""
    from stimuli.motion.bvh import read_bvh

    if not files:
        print(f"import: no captures in {MOCAP} (shared/ sits beside the clone)")
        return
    print(f"{'capture':58} {'MB':>5} {'import s':>8} {'fps':>4} {'frames':>6} {'dropped':>7} {'unit':>5} naming")
    for path in files:
        best = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            m = read_bvh(path)
            best = min(best, time.perf_counter() - t0)
        print(f"{_name(path):58} {path.stat().st_size / 1e6:5.2f} {best:8.3f} {m.fps:4.0f} "
              f"{m.n_frames:6d} {m.metadata['dropped_lead_frames']:7d} {m.metadata['unit']:>5} {m.metadata['naming']}")


def loop_times(files: list[Path], repeats: int = 3) -> None:
    """Best-of-``repeats`` wall time of import + ``capture_loop`` per capture (walk, or jog for the
    runs and jogs), with the loop's range, cycles, belt speed and seam, or the refusal."""
    from stimuli.errors import StimuliError
    from stimuli.motion.bvh import read_bvh
    from stimuli.motion.loop import capture_loop, seam_error

    print(f"{'capture':58} {'import s':>8} {'loop s':>6} {'total s':>7}  loop")
    for path in files:
        gait = capture_gait(path)
        best_import = best_loop = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            m = read_bvh(path)
            t1 = time.perf_counter()
            try:
                loop = capture_loop(m, gait)
                what = (f"{gait} {loop.metadata['capture_range_s'][0]:.2f}-{loop.metadata['capture_range_s'][1]:.2f} s, "
                        f"{loop.metadata['cycles']} cycle(s), belt {loop.metadata['belt_speed_mps']:.2f} m/s, "
                        f"seam ratio {seam_error(loop)['ratio']:.2f}")
            except StimuliError as exc:
                what = "refused: " + str(exc).split(": no loop: ")[-1][:90] + "…"
            t2 = time.perf_counter()
            best_import, best_loop = min(best_import, t1 - t0), min(best_loop, t2 - t1)
        print(f"{_name(path):58} {best_import:8.3f} {best_loop:6.3f} {best_import + best_loop:7.3f}  {what}")


def _knee_at_30fps(motion) -> tuple[float, float]:
    """(largest knee change between two 30-fps frames, largest knee flexion), degrees, either leg."""
    from stimuli.motion.metrics import knee_angles

    knees = knee_angles(motion.resample(30.0))
    return (max(float(np.abs(np.diff(k)).max()) for k in knees.values()),
            max(float(k.max()) for k in knees.values()))


def _foot_turn_at_30fps(motion) -> float:
    """Largest turn of either foot (the ankle bone's world rotation) between two 30-fps frames, degrees."""
    from stimuli.motion import quat
    from stimuli.motion.skeleton import role_indices

    m30 = motion.resample(30.0)
    grot, _ = m30.global_transforms()
    roles = role_indices(m30)
    return max(float(np.degrees(quat.angle(quat.mul(quat.inv(g[:-1]), g[1:]))).max())
               for g in (grot[:, roles[f"{s}_ankle"]] for s in "lr"))


def cleanup_table(files: list[Path]) -> None:
    """The default clean-up on every capture that loops (walk, or jog for the runs and jogs), onto a
    1.80 m BMI-27 man; a capture that gives no loop (06_10) is looped whole by ``make_loop`` and marked *."""
    from stimuli.motion.metrics import knee_hyperextension
    from stimuli.bodies import fit_body
    from stimuli.errors import StimuliError
    from stimuli.motion.bvh import read_bvh
    from stimuli.motion.contact import foot_contacts
    from stimuli.motion.loop import capture_loop, make_loop
    from stimuli.motion.quality import motion_quality
    from stimuli.motion.retarget import retarget

    body = fit_body("M", 1.80, 27.0)
    print(f"{'capture':58} {'skate%':>6} {'slip':>5} {'pen':>5} {'penmax':>6} {'float':>5} {'knee':>5} {'src':>5} "
          f"{'dknee':>5} {'src':>5} {'chg max/rms':>12} {'cpu s':>5} {'flight%':>7} {'dfoot':>5} {'src':>5} {'hyper':>5} {'src':>5}")
    for path in files:
        gait = capture_gait(path)
        name = _name(path)
        capture = read_bvh(path)
        try:
            loop = capture_loop(capture, gait)
        except StimuliError:
            loop = make_loop(capture, cycles=2).resample(30.0)
            loop.metadata["looped"] = True
            name += " *"
        t0 = time.process_time()
        out = retarget(loop, body)
        cpu = time.process_time() - t0
        q = motion_quality(out, body)
        (d_src, k_src), (d_out, k_out) = _knee_at_30fps(loop), _knee_at_30fps(out)
        down = foot_contacts(loop).down
        foot_out, foot_src = _foot_turn_at_30fps(out), _foot_turn_at_30fps(retarget(loop, body, cleanup=False))
        print(f"{name:58} {q['skate_humos_pct']:6.1f} {q['skate_phc_mm']:5.2f} {q['penetrate_mm']:5.1f} "
              f"{q['penetrate_max_mm']:6.1f} {q['float_mm']:5.1f} {k_out:5.1f} {k_src:5.1f} {d_out:5.1f} {d_src:5.1f} "
              f"{out.metadata['joint_change_max_deg']:6.1f}/{out.metadata['joint_change_rms_deg']:5.1f} {cpu:5.2f} "
              f"{100 * (~(down['l'] | down['r'])).mean():7.1f} {foot_out:5.1f} {foot_src:5.1f} "
              f"{knee_hyperextension(out):5.1f} {knee_hyperextension(loop):5.1f}")


def walk_knee_peak_band(k: float = 3.0) -> tuple[float, float]:
    """The CGM2.3 normative walk's knee-flexion peak, mean ± ``k`` SD (the SD at the mean's peak), degrees."""
    from stimuli.motion.normative import curve

    phi = np.linspace(0.0, 1.0, 1001)
    mean = curve("KneeAngles", "X")(phi)
    at = phi[int(np.argmax(mean))]
    sd = float(curve("KneeAngles", "X", "sd")(np.array([at]))[0])
    return float(mean.max()) - k * sd, float(mean.max()) + k * sd


def _table2_rows(loop, bodies, gait, band) -> list[dict]:
    """One row per body: the acceptance figures of ``loop`` retargeted onto it."""
    from stimuli.motion.bvh import EASE_IN_MIN_DEG, arm_abduction
    from stimuli.motion.loop import seam_error
    from stimuli.motion.metrics import knee_angles, knee_hyperextension
    from stimuli.motion.quality import motion_quality
    from stimuli.motion.retarget import retarget

    arms = float(arm_abduction(loop).max())
    hyper_bound = max(knee_hyperextension(loop), 0.0) + 2.0
    rows = []
    for body in bodies:
        t0 = time.process_time()
        out = retarget(loop, body)
        cpu = time.process_time() - t0
        q = motion_quality(out, body)
        peaks = [float(k.max()) for k in knee_angles(out.resample(30.0)).values()]
        seam = seam_error(out)
        jump = seam["seam_step_m"] / max(seam["interior_step_p99_m"], 1e-12)
        hyper = knee_hyperextension(out)
        fails = [name for name, bad in (
            ("skate", q["skate_humos_pct"] > 5.0), ("pen", q["penetrate_mm"] > 10.0), ("float", q["float_mm"] > 10.0),
            ("knee", gait == "walk" and not all(band[0] <= k <= band[1] for k in peaks)),
            ("tpose", arms >= EASE_IN_MIN_DEG), ("seam", max(seam["ratio"], jump) > 1.0),
            ("hyper", hyper > hyper_bound)) if bad]
        rows.append({"body": body.body_id, "skate": q["skate_humos_pct"], "pen": q["penetrate_mm"],
                     "penmax": q["penetrate_max_mm"], "float": q["float_mm"], "knee_lo": min(peaks),
                     "knee_hi": max(peaks), "hyper": hyper, "arms": arms, "seam": seam["ratio"], "jump": jump,
                     "chg_max": out.metadata["joint_change_max_deg"],
                     "chg_rms": out.metadata["joint_change_rms_deg"], "cpu": cpu, "fails": fails})
    return rows


def table2(files: list[Path]) -> None:
    """Issue 20's acceptance table: every capture × each of Table 2's bodies, then the worst per capture."""
    from stimuli.bodies import body_for_actor
    from stimuli.errors import StimuliError
    from stimuli.motion.bvh import read_bvh
    from stimuli.motion.loop import capture_loop
    from stimuli.protocol import load_protocol

    proto = load_protocol(ROOT / "protocols" / "exp1_shape_motion.yaml")
    bodies = [body_for_actor(a) for a in proto.actors if not getattr(a, "practice_only", False)]
    band = walk_knee_peak_band()
    print(f"Table 2's {len(bodies)} bodies; walk knee peak band (CGM2.3 mean ± 3 SD) {band[0]:.1f}–{band[1]:.1f}°; "
          "bounds: skate ≤ 5 %, pen/float ≤ 10 mm, arms < 30°, seam and jump ratios ≤ 1, knees bent backwards no more "
          "than the loop's own (or straight) + 2°, import+loop+retarget ≤ 2 CPU s")
    head = (f"{'capture':52} {'body':7} {'skate%':>6} {'pen':>4} {'max':>4} {'float':>5} {'knee pk':>11} {'hyper':>5} {'arms':>4} "
            f"{'seam':>4} {'jump':>4} {'chg max/rms':>11} {'cpu s':>5}  fails")
    print(head)
    worst = []
    for path in files:
        gait = capture_gait(path)
        name = _name(path)
        t0 = time.process_time()
        try:
            loop = capture_loop(read_bvh(path), gait)
        except StimuliError as exc:
            worst.append(f"{name:52} refused ({gait}): {exc}")
            continue
        base_cpu = time.process_time() - t0
        rows = _table2_rows(loop, bodies, gait, band)
        for r in rows:
            print(f"{name:52} {r['body']:7} {r['skate']:6.1f} {r['pen']:4.1f} {r['penmax']:4.1f} {r['float']:5.1f} "
                  f"{r['knee_lo']:5.1f}-{r['knee_hi']:5.1f} {r['hyper']:5.1f} {r['arms']:4.0f} {r['seam']:4.2f} {r['jump']:4.2f} "
                  f"{r['chg_max']:5.1f}/{r['chg_rms']:5.1f} {base_cpu + r['cpu']:5.2f}  {' '.join(r['fails']) or 'ok'}")
        fails = sorted({f for r in rows for f in r["fails"]})
        worst.append(
            f"{name:52} {gait:4} skate ≤{max(r['skate'] for r in rows):4.1f} % pen ≤{max(r['pen'] for r in rows):4.1f} "
            f"(deepest {max(r['penmax'] for r in rows):4.1f}) float ≤{max(r['float'] for r in rows):4.1f} mm "
            f"knee {min(r['knee_lo'] for r in rows):5.1f}-{max(r['knee_hi'] for r in rows):5.1f}° "
            f"hyper ≤{max(r['hyper'] for r in rows):5.1f}° "
            f"arms {rows[0]['arms']:3.0f}° seam ≤{max(r['seam'] for r in rows):4.2f} jump ≤{max(r['jump'] for r in rows):4.2f} "
            f"chg ≤{max(r['chg_max'] for r in rows):5.1f}/{max(r['chg_rms'] for r in rows):4.1f}° "
            f"cpu ≤{base_cpu + max(r['cpu'] for r in rows):4.2f} s  {'FAILS ' + ' '.join(fails) if fails else 'all met'}")
    print("\nworst per capture over the bodies:")
    print("\n".join(worst))


def main() -> None:
    from stimuli.bodies import body_for_actor
    from stimuli.motion.bvh import read_bvh
    from stimuli.motion.loop import make_loop, seam_error
    from stimuli.motion.modifier import thesis_parameters
    from stimuli.motion.quality import motion_quality
    from stimuli.motion.retarget import retarget
    from stimuli.motion.style import actor_gait
    from stimuli.protocol import load_protocol

    proto = load_protocol(ROOT / "protocols" / "exp1_shape_motion.yaml")
    actors = [a for a in proto.actors if not getattr(a, "practice_only", False)][:8]
    expected = {"t": 0.960870, "wthr": 0.945304, "chest_m": 1.133739, "speed_ratio": 1.077012,
                "abduction_offset_deg": 6.14649, "base_mm": 85.9973, "bob_ratio": 1.108682,
                "swing_ratio": 1.286497, "height_scale": 1.040956}
    got = thesis_parameters(1.83, 34.1)
    errors = {k: abs(got[k] - v) for k, v in expected.items()}
    print("thesis worked example |error|: max over the 8 values printed to 5–6 decimals "
          f"{max(e for k, e in errors.items() if k != 'base_mm'):.1e}; walking base (printed to 4) "
          f"{errors['base_mm']:.1e}")
    cmu = {}
    for name in ("cmu_35_01_walk", "cmu_35_17_run"):
        t0 = time.perf_counter()
        loop = make_loop(read_bvh(ROOT / "stimuli" / "data" / f"{name}.bvh"), cycles=2).resample(30.0)
        loop.metadata["looped"] = True
        cmu[name] = loop
        print(f"{name}: import+loop {time.perf_counter() - t0:.2f} s, seam ratio {seam_error(loop)['ratio']:.2f}")
    header = f"{'actor':7} {'source':15} {'gen s/4s':>8} {'rt s/4s':>8} {'metric s':>8} {'pen cm':>7} {'float cm':>8} {'skate %':>7} {'unstab %':>8} {'seam':>5}"
    print(header)
    for a in actors:
        body = body_for_actor(a)
        sources = {}
        for gait, spec in proto.gaits.items():
            t0 = time.perf_counter()
            m = actor_gait(a, gait, spec.cadence_spm, spec.speed_mps, proto.seed, fps=30.0, cycles=2)
            sources[gait] = (m, (time.perf_counter() - t0) * 4.0 / m.duration_s)
        sources.update({k: (v, float("nan")) for k, v in cmu.items()})
        for label, (src, gen_s) in sources.items():
            t0 = time.perf_counter()
            rt = retarget(src, body)
            rt_s = (time.perf_counter() - t0) * 4.0 / rt.duration_s
            t0 = time.perf_counter()
            q = motion_quality(rt, body)
            q_s = time.perf_counter() - t0
            print(f"{a.id:7} {label:15} {gen_s:8.3f} {rt_s:8.3f} {q_s:8.2f} {q['penetrate_cm']:7.2f} "
                  f"{q['float_cm']:8.2f} {q['skate_pct']:7.2f} {q['dynamically_unstable_pct']:8.1f} "
                  f"{seam_error(rt)['ratio']:5.2f}")


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--import-only", action="store_true", help="only the import time per capture")
    parser.add_argument("--loop-only", action="store_true", help="only import + loop extraction per capture")
    parser.add_argument("--cleanup", action="store_true", help="only the clean-up's figures per capture")
    parser.add_argument("--table2", action="store_true", help="issue 20's acceptance table on Table 2's bodies")
    parser.add_argument("--files", nargs="+", metavar="BVH",
                        help="measure these captures instead of ../shared/data/mocap (gait from the name: "
                             "run/jog/dash → jog, else walk)")
    args = parser.parse_args()
    files = capture_files(args.files)
    np.set_printoptions(precision=3)
    if args.loop_only:
        loop_times(files)
    elif args.cleanup:
        cleanup_table(files)
    elif args.table2:
        table2(files)
    else:
        import_times(files)
        if not args.import_only:
            main()
