"""``shapemotion physics retarget | protocol | tune``: the COM method (physics-based retargeting)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from shapemotion.execution import SCHEDULER_HELP, SCHEDULER_METAVAR
from stimuli.commands.checks import in_range
from stimuli.errors import StimuliError
from stimuli.fileio import output_path


def register(subparsers) -> None:
    p = subparsers.add_parser("physics", help="COM method: physics-based retargeting in MuJoCo",
                              description="Physics-based retargeting with Table-1 segment masses (the paper's "
                                          "balance-point controller).")
    sub = p.add_subparsers(dest="physics_command", metavar="STEP")
    r = sub.add_parser("retarget", help="one COM motion for a body of given sex, height and weight",
                       description="Track MOTION with a ragdoll of the fitted body and write the COM motion and a report.")
    r.add_argument("--motion", type=Path, required=True, help="reference (NoCOM) motion .npz")
    r.add_argument("--sex", choices=["F", "M"], required=True)
    r.add_argument("--height", type=float, required=True, help="target height (m)")
    r.add_argument("--weight", type=float, required=True, help="target weight (kg)")
    r.add_argument("--reference-height", type=float, default=None,
                   help="height of the motion's own body (m; default: the motion's metadata, else the target)")
    r.add_argument("--reference-weight", type=float, default=None,
                   help="weight of the motion's own body (kg; default: the motion's metadata, else the target)")
    r.add_argument("--reference-sex", choices=["F", "M"], default=None,
                   help="sex of the motion's own body (default: the motion's metadata, else --sex)")
    r.add_argument("--allow-nearest", action="store_true",
                   help="a height/BMI the body model cannot reach: simulate the requested weight on the nearest "
                        "body shape it can (default: exit 2)")
    r.add_argument("--gait", choices=("walk", "jog"), default=None,
                   help="which gain set drives the ragdoll (default: the motion's metadata 'gait', else walk)")
    r.add_argument("--controller", choices=CONTROLLERS, default="pd",
                   help="pd: the paper's PD with the gait's shipped gains (default); feedforward: PD plus the inverse "
                        "dynamics of MOTION on its own body, the gains chosen first on that body (as `physics protocol "
                        "--controller feedforward` does)")
    r.add_argument("--out", type=output_path, required=True, help="COM motion .npz to write")
    r.add_argument("--report", type=Path, default=None, help="report JSON to write")
    r.set_defaults(func=run_retarget)
    pr = sub.add_parser("protocol", help="all COM motions of a protocol (cached)",
                        description="Make the COM motion of every actor × gait of PROTOCOL, the reports, "
                                    "summary.csv and the Fig.-7 plots.")
    pr.add_argument("protocol", type=Path)
    pr.add_argument("--out", type=output_path, required=True)
    pr.add_argument("--motions", type=Path, default=None,
                    help="folder with the NoCOM average motions <sex>_<gait>.npz (default: generated walks/jogs)")
    pr.add_argument("--workers", type=int, default=None, help="parallel processes (default: 2)")
    pr.add_argument("--controller", choices=CONTROLLERS, default="pd",
                    help="pd: the paper's PD with the shipped gains of each gait (default); feedforward: PD plus the "
                         "inverse dynamics of each NoCOM motion on its reference body, gains chosen once per NoCOM "
                         "motion on that body and kept for its every actor (issue 21; cached apart from pd)")
    pr.add_argument("--scheduler", metavar=SCHEDULER_METAVAR, help=SCHEDULER_HELP)
    pr.set_defaults(func=run_protocol)
    t = sub.add_parser("tune", help="re-find the fixed controller gains on the base character",
                       description="Search the PD gains for the base character and write stimuli/physics/gains.json.")
    t.add_argument("--out", type=output_path, default=None, help="gains JSON (default: the package's gains.json)")
    t.add_argument("--gait", choices=("walk", "jog", "all"), default="all",
                   help="which gait's gains to re-find (base: CMU 35_01 walk / 35_17 run); default all")
    t.add_argument("--target-rms", type=float, default=None, metavar="DEG",
                   help="tracking RMS bound for the base character (default 2.5°, a margin under the 3° acceptance)")
    t.set_defaults(func=run_tune)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


# The protocol step's controllers (docs/readme_physics.md, Controller variants).
CONTROLLERS = ("pd", "feedforward")

def _check_retarget_options(args: argparse.Namespace) -> None:
    """Heights in range and both output files writable, before the (minutes-long) simulation (weights:
    ``check_weight``)."""
    from stimuli.fileio import check_output_file
    from stimuli.protocol import HEIGHT_RANGE_M

    in_range("--height", args.height, HEIGHT_RANGE_M, "m (metres, not centimetres)")
    in_range("--reference-height", args.reference_height, HEIGHT_RANGE_M, "m (metres, not centimetres)")
    if args.out.suffix.lower() != ".npz":
        raise StimuliError(f"--out {args.out}: the COM motion is written as .npz")
    check_output_file(args.out)
    check_output_file(args.report, "--report")


def _reference(args, motion) -> tuple[float, float, str, str]:
    """Height (m) and weight (kg) of the motion's own body, and where each came from (for messages):
    the options, else the motion's metadata, else the target's (then b = 0, and a warning says so: the
    COM change is measured against it)."""
    from stimuli.physics.own_body import own_body

    given = (("height_m",) if args.reference_height is not None else ()) + \
        (("weight_kg", "bmi") if args.reference_weight is not None else ())
    own = own_body(motion, args.motion, hint=", or give the reference body with --reference-height/--reference-weight",
                   skip=given)
    height, h_from = args.reference_height, "--reference-height"
    if height is None and own.height_m is not None:
        height, h_from = own.height_m, f"{args.motion}: metadata height_m"
    if height is None:
        height, h_from = args.height, "--height"
    if args.reference_weight is not None:
        return float(height), float(args.reference_weight), h_from, "--reference-weight"
    weight = own.weight_at(float(height))
    if weight is not None:
        if h_from == "--height":
            print(f"warning: {args.motion} records its body's {weight[1]} but no height_m, so the target's "
                  f"{args.height:g} m is taken as the reference height; give --reference-height for the "
                  "motion's own body", file=sys.stderr)
        return float(height), weight[0], h_from, f"{args.motion}: metadata {weight[1]}"
    print(f"warning: {args.motion} records no weight or BMI of its own body, so the target's "
          f"{args.weight:g} kg is taken as the reference weight"
          + (" (and its height): b = 0" if height == args.height else "")
          + "; give --reference-weight (and --reference-height) for the motion's own body", file=sys.stderr)
    return float(height), float(args.weight), h_from, "--weight"


def run_retarget(args: argparse.Namespace) -> int:
    from stimuli.motion import Motion
    from stimuli.physics.checks import result_warnings
    from stimuli.physics.controller import Gains, motion_gait
    from stimuli.physics.inertia import check_weight
    from stimuli.physics.own_body import check_reference
    from stimuli.physics.retarget import RagdollFellError, retarget
    from stimuli.physics.tune import tune_for_motion

    _check_retarget_options(args)
    check_weight(args.weight, args.height, where="--weight")
    motion = Motion.load(args.motion)
    ref_h, ref_w, h_from, w_from = _reference(args, motion)
    check_reference(ref_h, ref_w, h_from, w_from)
    for line in _motion_notes(args, motion):
        print(f"warning: {line}", file=sys.stderr)
    body = _body(args.sex, args.height, args.weight, args.allow_nearest, "--height/--weight")
    ref_body = _body(_reference_sex(args, motion), ref_h, ref_w, args.allow_nearest,
                     f"the motion's own body ({h_from}, {w_from})")
    try:
        gait = args.gait or motion_gait(motion)
    except StimuliError as exc:
        raise StimuliError(f"{args.motion}: metadata gait: {exc}; or choose the gain set with --gait") from None
    feedforward = args.controller == "feedforward"
    try:
        gains = Gains.load(gait=gait)
        if feedforward:   # chosen once on the motion's own body, then kept (tune.tune_for_motion)
            gains = tune_for_motion(motion, ref_body, base=gains,
                                    progress=lambda line: print(f"gain choice: {line}", file=sys.stderr))
        result = retarget(motion, body, args.weight, reference_body=ref_body, gains=gains, raise_on_fall=True,
                          feedforward=feedforward)
    except RagdollFellError as exc:
        if args.report:
            _write_report(args.report, exc.result.report)
        raise StimuliError(f"{args.motion}: {exc}" + (f" (report: {args.report})" if args.report else "")) from None
    rep = result.report
    if feedforward:
        rep["gain_choice"] = {k: gains.tuning[k] for k in ("scale", "met", "history")}
    result.motion.save(args.out)
    if args.report:
        _write_report(args.report, rep)
    scale = f" × {gains.tuning['scale']:g}, feed-forward" if feedforward else ""
    print(f"{args.out}: COM motion ({gains.gait} gains{scale}), b = {rep['b_m'] * 1000:.2f} mm, tracking RMS "
          f"{rep['tracking_rms_deg_overall']:.2f}°, vs NoCOM {rep['nocom_rms_deg_mean']:.2f}°, no foot down "
          f"{100 * rep['flight_fraction']:.1f} % (reference {100 * rep['reference_flight_fraction']:.1f} %), "
          f"wall/simulated {rep['wall_per_simulated']:.2f}")
    for line in result_warnings(rep, gains.gait):
        print(f"warning: {line}", file=sys.stderr)
    return 0


def _reference_sex(args, motion) -> str:
    """--reference-sex, else the motion's own (an average of women's walks is a woman's motion), else --sex
    (with a warning when the metadata names a sex that is not F or M)."""
    meta = motion.metadata.get("sex")
    if args.reference_sex or meta in ("F", "M"):
        return args.reference_sex or meta
    if meta is not None:
        print(f"warning: {args.motion}: metadata sex is {meta!r}, not F or M; the reference body takes --sex "
              f"{args.sex} (give --reference-sex)", file=sys.stderr)
    return args.sex


def _body(sex: str, height: float, weight: float, allow_nearest: bool, what: str):
    """The fitted body; out of the model's reach, the nearest one with ``allow_nearest`` (the masses still
    follow the requested weight), else an error that says how to go on."""
    from stimuli.bodies import fit_body
    from stimuli.bodies.api import BodyFitError

    try:
        return fit_body(sex, height, weight / height**2, on_unreachable="nearest" if allow_nearest else "raise")
    except BodyFitError as exc:
        raise StimuliError(f"{what}: {exc}; --allow-nearest simulates {weight:g} kg (Table-1 masses) on that "
                           "nearest body shape") from None


def _motion_notes(args, motion) -> list[str]:
    """What the user should know about the motion before a simulation that takes a while."""
    notes = []
    if not motion.metadata.get("looped") and not motion.metadata.get("treadmill"):
        notes.append(f"{args.motion} is an overground capture: it is looped first (its steadiest straight range, "
                     "as `shapemotion motion import FILE --loop` does)")
    elif not motion.metadata.get("looped"):
        notes.append(f"{args.motion} is not a loop (imported without --loop?): the simulation repeats it with a "
                     "jump where its end meets its start; `shapemotion motion import FILE --loop` makes a loop")
    if args.gait is None and not motion.metadata.get("gait"):
        notes.append(f"{args.motion} records no gait: it is driven with the walking gains; give --gait jog for a "
                     "run or jog")
    return notes


def _write_report(path: Path, report: dict) -> None:
    from stimuli.fileio import atomic_write_text

    atomic_write_text(path, json.dumps(report, indent=1, sort_keys=True) + "\n")


def run_protocol(args: argparse.Namespace) -> int:
    from shapemotion.execution import errors_as, scheduler_option, unused_workers_warning
    from stimuli.physics.protocol_step import run_protocol as run

    scheduler = scheduler_option(args.scheduler, StimuliError)
    unused = unused_workers_warning(scheduler, args.workers)
    if unused:
        print(f"warning: {unused}", file=sys.stderr)
    workers = 2 if args.workers is None else args.workers
    with errors_as(StimuliError):
        result = run(args.protocol, args.out, args.motions, workers=workers, progress=print, scheduler=scheduler,
                     feedforward=args.controller == "feedforward")
    for line in result["warnings"]:
        print(f"warning: {line}", file=sys.stderr)
    print(f"{args.out}: {len(result['reports'])} COM motion(s) ({args.controller} controller), figures: "
          + ", ".join(str(p) for p in result["figures"]))
    return 0


def run_tune(args: argparse.Namespace) -> int:
    from stimuli.physics.controller import GAINS_FILE, GAITS
    from stimuli.physics.tune import TARGET_RMS_DEG, tune_gaits

    if args.target_rms is not None and not 0.0 < args.target_rms < 90.0:
        raise StimuliError(f"--target-rms: expected degrees between 0 and 90, got {args.target_rms}")
    out = args.out or GAINS_FILE
    gaits = GAITS if args.gait == "all" else (args.gait,)
    for gait, gains in tune_gaits(gaits, args.target_rms or TARGET_RMS_DEG, out).items():
        print(f"{out} [{gait}]: k_p {gains.k_p:g}, k_d {gains.k_d:.1f}, k_pf {gains.k_pf:.0f}, "
              f"k_df {gains.k_df:.0f} (tracking RMS {gains.tuning['best_rms_deg']:.2f}°)")
    return 0
