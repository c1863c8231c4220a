"""``shapemotion motion generate|import|average|modify|metrics|export-bvh|retarget|markers|strip``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from stimuli.commands.checks import at_least, human_body, in_range, parse_body, positive
from stimuli.errors import StimuliError
from stimuli.fileio import check_output_dir, check_output_file, output_path


STRIP_SUFFIXES = (".png", ".svg", ".pdf", ".jpg")
# Feet standing higher than this above y = 0 mark a clip that was not grounded on its flat feet.
RAW_STANCE_HEIGHT_CM = 0.5
# The generator's shortest loop (one cycle): fewer frames hold no step to measure.
MIN_METRIC_FRAMES = 8


def register(subparsers) -> None:
    motion = subparsers.add_parser("motion", help="generate, import, average, modify and measure motions",
                                   description="Motions as .npz files (DESIGN.md contract) and BVH.")
    sub = motion.add_subparsers(dest="motion_command", metavar="ACTION", required=True)

    p = sub.add_parser("generate", help="a looped treadmill walk or jog for a body or an actor")
    p.add_argument("--gait", choices=["walk", "jog"], default="walk")
    p.add_argument("--cadence", type=float, default=None, help="steps/min (default: protocol or 112/138)")
    p.add_argument("--speed", type=float, default=None, help="m/s (default: protocol or 1.2/2.2)")
    p.add_argument("--height", type=float, default=None, help="body height in m (default 1.75)")
    p.add_argument("--bmi", type=float, default=None, help="BMI: applies the anthropometric gait trends")
    p.add_argument("--sex", choices=["F", "M"], default=None, help="default M")
    p.add_argument("--protocol", type=Path, help="take the actor, cadence, speed and seed from a protocol")
    p.add_argument("--actor", help="actor id in the protocol (e.g. F_Hi1); needed with --protocol")
    p.add_argument("--seed", type=int, default=None, help="style seed (default: protocol seed or 0)")
    p.add_argument("--no-style", action="store_true", help="no individual style, trends only")
    p.add_argument("--fps", type=float, default=30.0)
    p.add_argument("--cycles", type=int, default=2)
    p.add_argument("--out", type=output_path, required=True, help="output .npz")
    p.add_argument("--bvh", type=Path, help="also write a BVH file")
    p.set_defaults(func=run_generate)

    p = sub.add_parser("import", help="import a BVH or AMASS .npz, optionally as a treadmill loop")
    p.add_argument("source", type=Path)
    p.add_argument("--mapping", type=Path, help="YAML/JSON {role: joint} for unknown skeleton namings")
    p.add_argument("--height", type=float, default=None, help="performer height in m (scales the skeleton)")
    p.add_argument("--loop", action="store_true",
                   help="a treadmill loop from the longest steady, straight range of --gait: whole cycles, "
                        "heading drift removed, on the belt at its own speed")
    p.add_argument("--cycles", type=int, default=None, help="whole cycles to keep when looping")
    p.add_argument("--gait", choices=("walk", "jog", "run"), default=None,
                   help="with --loop: the gait to find (jog and run: a running gait); default walk")
    p.add_argument("--start", type=float, default=None, help="with --loop: search from this time (s)")
    p.add_argument("--end", type=float, default=None, help="with --loop: search up to this time (s)")
    p.add_argument("--fps", type=float, default=None, help="resample to this frame rate")
    p.add_argument("--out", type=output_path, required=True)
    p.set_defaults(func=run_import)

    p = sub.add_parser("average", help="DTW-aligned average of several motions on one skeleton")
    p.add_argument("motions", type=Path, nargs="+")
    p.add_argument("--cycles", type=int, default=2)
    p.add_argument("--out", type=output_path, required=True)
    p.set_defaults(func=run_average)

    p = sub.add_parser("modify", help="the thesis's five-parameter body-shape walk modifier")
    p.add_argument("motion", type=Path)
    p.add_argument("--height", type=float, required=True, help="target height in m")
    p.add_argument("--body-fat", type=float, required=True, help="target body fat in %%")
    p.add_argument("--chest", type=float, default=None, help="chest in m (default: interpolated from body fat)")
    p.add_argument("--wthr", type=float, default=None, help="waist-to-hip ratio (default: interpolated)")
    p.add_argument("--base-scale", type=float, default=1.0, help="multiplies the walking-base offset (read in mm; 10 = the thesis script's literal cm)")
    p.add_argument("--out", type=output_path, required=True)
    p.set_defaults(func=run_modify)

    p = sub.add_parser("metrics", help="gait figures and HUMOS plausibility metrics of a motion")
    p.add_argument("motion", type=Path)
    p.add_argument("--body", help="sex=M,height=1.80,bmi=25: measure on the skinned mesh of this body (a motion not "
                                  "on its rig is retargeted onto it first)")
    p.add_argument("--json", type=Path, help="write the metrics as JSON")
    p.set_defaults(func=run_metrics)

    p = sub.add_parser("export-bvh", help="write a motion as BVH")
    p.add_argument("motion", type=Path)
    p.add_argument("--out", type=output_path, required=True)
    p.add_argument("--order", default="ZYX", help="rotation channel order")
    p.add_argument("--scale", type=float, default=1.0, help="length unit multiplier (100: centimetres)")
    p.set_defaults(func=run_export)

    p = sub.add_parser("retarget", help="retarget a motion onto the Anny rig of a fitted body")
    p.add_argument("motion", type=Path)
    p.add_argument("--body", required=True, help="sex=M,height=1.80,bmi=25")
    p.add_argument("--keep-speed", action="store_true", help="keep the belt speed (no stride scaling)")
    p.add_argument("--foot-lock", action="store_true",
                   help="after the clean-up, the whole-clip foot-locking solve (IK with mink; docs/readme_motion.md)")
    p.add_argument("--out", type=output_path, required=True)
    p.set_defaults(func=run_retarget)

    p = sub.add_parser("markers", help="the 15 point-light marker trajectories as CSV")
    p.add_argument("motion", type=Path)
    p.add_argument("--body", help="sex=M,height=1.80,bmi=25: the body whose rig the motion is on; the markers are "
                                  "then exactly the dots its point-light clips show")
    p.add_argument("--out", type=output_path, required=True)
    p.set_defaults(func=run_markers)

    p = sub.add_parser("strip", help="a frame strip (poses across one cycle, side view) as PNG")
    p.add_argument("motions", type=Path, nargs="*", help="motion files (or use --protocol)")
    p.add_argument("--protocol", type=Path, help="strips of every actor's generated walk and jog on its body")
    p.add_argument("--skeleton-only", action="store_true", help="with --protocol: do not retarget onto bodies")
    p.add_argument("--frames", type=int, default=8, help="poses per motion, evenly spaced over its first cycle (default 8)")
    p.add_argument("--out", type=output_path, required=True, help="PNG file (or folder with --protocol)")
    p.set_defaults(func=run_strip)


def _fit(spec: str):
    from stimuli.bodies import fit_body

    b = parse_body(spec)
    return fit_body(b["sex"], b["height_m"], b["bmi"])


def _on_body(motion, args: argparse.Namespace):
    """The body of ``--body``, whose rig ``motion`` must be on (metrics and markers use its mesh)."""
    from stimuli.motion.retarget import is_on_rig

    body = _fit(args.body)
    if not is_on_rig(motion, body):   # a motion of a 1.80 m man measured on a 1.50 m woman read Float 18 cm
        made_for = motion.metadata.get("body_id")
        raise StimuliError(f"{args.motion}: --body measures on the body's mesh, so the motion must be on its rig"
                           + (f" (it is on body {made_for})" if made_for else "")
                           + f"; retarget it first: shapemotion motion retarget {args.motion} --body {args.body} "
                           "--out R.npz")
    return body


def _onto_body(motion, body, args: argparse.Namespace):
    """``motion`` on ``body``'s rig for the mesh metrics: retargeted first (and said so) when it is not
    on it yet — a motion of a 1.80 m man skinned on a 1.50 m woman's rig read Float 18 cm."""
    from stimuli.motion.retarget import is_on_rig, retarget

    if is_on_rig(motion, body):
        return motion
    made_for = motion.metadata.get("body_id")
    print(f"note: {args.motion} is not on the rig of body {body.body_id}"
          + (f" (it is on body {made_for})" if made_for else "")
          + f"; measuring it retargeted onto that body (as 'shapemotion motion retarget {args.motion} "
          f"--body {args.body}' would)", file=sys.stderr)
    return retarget(motion, body)


def _load(path: Path):
    from stimuli.motion import Motion

    if path.is_dir():
        raise StimuliError(f"{path}: is a folder, not a motion file")
    if not path.is_file():
        raise StimuliError(f"{path}: motion file not found")
    if path.suffix.lower() == ".bvh":
        from stimuli.motion.bvh import read_bvh
        return read_bvh(path)
    return Motion.load(path)


def run_generate(args: argparse.Namespace) -> int:
    from types import SimpleNamespace

    from stimuli.motion.bvh import write_bvh
    from stimuli.motion.generate import DEFAULT_PACE
    from stimuli.motion.style import actor_gait

    _check_generate(args)
    cadence, speed = DEFAULT_PACE[args.gait]
    seed = args.seed or 0
    # Without --bmi the trends are an average build's; the motion records no BMI.
    actor = SimpleNamespace(id="cli", height_m=args.height or 1.75, bmi=22.0 if args.bmi is None else args.bmi,
                            sex=args.sex or "M")
    bmi = args.bmi
    if args.protocol:
        from stimuli.protocol import load_protocol
        proto = load_protocol(args.protocol)
        gait = proto.gaits.get(args.gait)
        if gait is None:
            raise StimuliError(f"{args.protocol}: no gait {args.gait!r} in gaits ({', '.join(proto.gaits)})")
        cadence, speed = gait.cadence_spm, gait.speed_mps
        seed = proto.seed if args.seed is None else args.seed
        actor = next((a for a in proto.actors if a.id == args.actor), None)
        if actor is None:
            raise StimuliError(f"{args.protocol}: no actor {args.actor!r}; actors are "
                               f"{', '.join(a.id for a in proto.actors)}")
        bmi = actor.bmi
    cadence = args.cadence if args.cadence is not None else cadence
    speed = args.speed if args.speed is not None else speed
    m = actor_gait(actor, args.gait, cadence, speed, seed, args.fps, args.cycles, style=not args.no_style)
    m.metadata.update(actor_id=actor.id, sex=actor.sex, bmi=bmi)
    print(m.save(args.out))
    if args.bvh:
        print(write_bvh(m, args.bvh))
    return 0


def _check_generate(args: argparse.Namespace) -> None:
    """Options of ``motion generate``: numbers in range, and the body from the options or from
    --protocol/--actor, never a mix of both (one of them would be silently ignored)."""
    from stimuli.protocol import CADENCE_RANGE_SPM, SPEED_RANGE_MPS

    _check_npz_out(args.out)
    check_output_file(args.bvh, "--bvh")
    in_range("--cadence", args.cadence, CADENCE_RANGE_SPM, "steps/min")
    in_range("--speed", args.speed, SPEED_RANGE_MPS, "m/s")
    positive("--fps", args.fps, "a frame rate > 0")
    at_least("--cycles", args.cycles, 1)
    at_least("--seed", args.seed, 0)
    if args.protocol is None:
        if args.actor:
            raise StimuliError(f"--actor {args.actor}: needs --protocol (the file that declares the actor)")
        human_body(args.height, args.bmi)
        return
    if not args.actor:
        raise StimuliError(f"--protocol {args.protocol}: also give --actor (an actor id of the protocol) to say "
                           "whose body and gait to make")
    given = [o for o, v in (("--height", args.height), ("--bmi", args.bmi), ("--sex", args.sex)) if v is not None]
    if given:
        raise StimuliError(f"{', '.join(given)}: the body comes from --actor {args.actor} of the protocol; give "
                           "either --protocol/--actor or --height/--bmi/--sex, not both")


def _check_npz_out(path: Path, option: str = "--out") -> None:
    """A motion is written as ``.npz`` (DESIGN.md contract); a file there must be writable."""
    if path.suffix.lower() != ".npz":
        raise StimuliError(f"{option} {path}: a motion is written as .npz (use 'motion export-bvh' for BVH)")
    check_output_file(path, option)


def run_import(args: argparse.Namespace) -> int:
    from stimuli.motion.loop import capture_loop

    src = args.source
    _check_npz_out(args.out)
    positive("--fps", args.fps, "a frame rate > 0")
    in_range("--height", args.height, _height_range(), "m")
    at_least("--cycles", args.cycles, 1)
    for option, value in (("--cycles", args.cycles), ("--gait", args.gait), ("--start", args.start), ("--end", args.end)):
        if value is not None and not args.loop:
            raise StimuliError(f"{option}: only used with --loop (it chooses what the loop is made of)")
    if src.suffix.lower() == ".bvh":
        from stimuli.motion.bvh import read_bvh
        m = read_bvh(src, mapping=args.mapping, height_m=args.height)
        # What the import changed or dropped (a T-pose ease-in, a root OFFSET, a re-rooted rig) is
        # said, not only recorded in the metadata.
        for note in m.metadata.get("import_notes", []):
            print(f"note: {src.name}: {note}", file=sys.stderr)
    elif src.suffix.lower() == ".npz":
        from stimuli.motion.amass import read_amass
        m = read_amass(src, height_m=args.height)
    else:
        raise StimuliError(f"{src}: unknown motion format (expected .bvh or an AMASS .npz)")
    if args.loop:
        m = capture_loop(m, args.gait or "walk", start_s=args.start, end_s=args.end, cycles=args.cycles)
        print(f"note: {src.name}: loop of {m.metadata['cycles']} whole cycle(s) from "
              f"{m.metadata['capture_range_s'][0]:.2f}–{m.metadata['capture_range_s'][1]:.2f} s "
              f"({m.metadata['capture_segment']}), belt {m.metadata['belt_speed_mps']:.2f} m/s, heading drift "
              f"{m.metadata['heading_drift_deg_s']:+.1f} deg/s removed", file=sys.stderr)
    if args.fps is not None:
        looped = m.metadata.get("looped")
        m = m.resample(args.fps)
        m.metadata["looped"] = bool(looped)
    print(m.save(args.out))
    return 0


def _height_range() -> tuple[float, float]:
    from stimuli.protocol import HEIGHT_RANGE_M

    return HEIGHT_RANGE_M


def run_average(args: argparse.Namespace) -> int:
    from stimuli.motion.average import average_motion, mean_body_notes

    _check_npz_out(args.out)
    at_least("--cycles", args.cycles, 1)
    motions = [_load(p) for p in args.motions]
    gaits = {str(p): m.metadata["gait"] for p, m in zip(args.motions, motions) if m.metadata.get("gait")}
    if len(set(gaits.values())) > 1:  # an average of a walk and a jog is neither
        raise StimuliError("average: the motions have different gaits ("
                           + ", ".join(f"{p}: {g}" for p, g in gaits.items()) + "); average one gait at a time")
    avg = average_motion(motions, cycles=args.cycles)
    print(avg.save(args.out))
    for note in mean_body_notes(motions):
        print(f"note: {note}", file=sys.stderr)
    return 0


def run_modify(args: argparse.Namespace) -> int:
    from stimuli.motion.modifier import modify
    from stimuli.protocol import BODY_FAT_RANGE_PCT

    _check_npz_out(args.out)
    in_range("--height", args.height, _height_range(), "m")
    in_range("--body-fat", args.body_fat, BODY_FAT_RANGE_PCT, "%")
    positive("--chest", args.chest, "a chest girth > 0 m")
    positive("--wthr", args.wthr, "a waist-to-hip ratio > 0")
    positive("--base-scale", args.base_scale, "a factor > 0")
    m = modify(_load(args.motion), args.height, args.body_fat, args.chest, args.wthr, base_scale=args.base_scale)
    print(json.dumps(m.metadata["modifier"], indent=2))
    print(m.save(args.out))
    return 0


def run_metrics(args: argparse.Namespace) -> int:
    from stimuli.motion.quality import motion_quality

    check_output_file(args.json, "--json")
    m = _load(args.motion)
    if m.n_frames < MIN_METRIC_FRAMES:
        raise StimuliError(f"{args.motion}: {m.n_frames} frame(s) hold no gait cycle; the metrics need a motion of "
                           f"at least one cycle (≥ {MIN_METRIC_FRAMES} frames)")
    body = _fit(args.body) if args.body else None
    if body is not None:
        m = _onto_body(m, body, args)
    q = motion_quality(m, body)
    # NaN (a figure with no value, e.g. no foot contact) is not JSON: write null.
    text = json.dumps(_finite_or_none(q), indent=2, sort_keys=True)
    if args.json:
        from stimuli.fileio import atomic_write_text

        atomic_write_text(args.json, text + "\n")
    print(text)
    if q.get("stance_height_cm", 0.0) > RAW_STANCE_HEIGHT_CM:
        advice = ("retarget onto a body and use --body for the mesh's figures" if body is None else
                  "the clip floats over the floor (Float)")
        print(f"note: the feet stand {q['stance_height_cm']:.1f} cm above y = 0 (a raw capture's floor is its toes' "
              f"push-off dip, or the clip floats): stance, double support and flight are judged from that level; "
              f"{advice}", file=sys.stderr)
    return 0


def _finite_or_none(value):
    """``value`` with every NaN or infinite float (in nested dicts and lists) replaced by None."""
    import math

    if isinstance(value, dict):
        return {k: _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_or_none(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def run_export(args: argparse.Namespace) -> int:
    from stimuli.motion.bvh import write_bvh

    check_output_file(args.out)
    positive("--scale", args.scale, "a length multiplier > 0")
    print(write_bvh(_load(args.motion), args.out, order=args.order, scale=args.scale))
    return 0


def run_retarget(args: argparse.Namespace) -> int:
    from stimuli.motion.retarget import retarget

    _check_npz_out(args.out)
    out = retarget(_load(args.motion), _fit(args.body), keep_speed=args.keep_speed, foot_lock=args.foot_lock)
    print(out.save(args.out))
    meta = out.metadata
    print(f"joint change from the retargeted source: largest {meta['joint_change_max_deg']:.1f}°, "
          f"RMS {meta['joint_change_rms_deg']:.1f}°", file=sys.stderr)
    return 0


def run_markers(args: argparse.Namespace) -> int:
    from stimuli.motion.markers import write_markers_csv

    check_output_file(args.out)
    if args.out.suffix.lower() != ".csv":
        raise StimuliError(f"--out {args.out}: the markers are written as a .csv file")
    m = _load(args.motion)
    body = _on_body(m, args) if args.body else None
    if body is None and m.metadata.get("naming") == "anny":
        print(f"note: {args.motion} is on an Anny body's rig; give that body as --body for the dots its clips show "
              "(without it the head and heels are placed from the skeleton alone)", file=sys.stderr)
    print(write_markers_csv(m, args.out, body))
    return 0


def run_strip(args: argparse.Namespace) -> int:
    from stimuli.motion.strip import frame_strip

    at_least("--frames", args.frames, 1)
    if args.protocol:
        from stimuli.motion.strip import protocol_strips
        if args.motions:
            raise StimuliError(f"motion strip: give motion files or --protocol, not both (got {args.motions[0]} "
                               f"and --protocol {args.protocol})")
        check_output_dir(args.out)
        written = protocol_strips(args.protocol, args.out, args.frames, on_bodies=not args.skeleton_only)
        if not written:
            raise StimuliError(f"{args.protocol}: declares no gaits, so there is no generated walk or jog to "
                               "draw; give motion files instead")
        for path in written:
            print(path)
        return 0
    if not args.motions:
        raise StimuliError("motion strip: give motion files or --protocol")
    if args.skeleton_only:
        raise StimuliError("--skeleton-only: only with --protocol (motion files are drawn as they are)")
    if args.out.suffix.lower() not in STRIP_SUFFIXES:
        raise StimuliError(f"--out {args.out}: a strip is an image; expected a file ending in "
                           f"{', '.join(STRIP_SUFFIXES)}")
    check_output_file(args.out)
    print(frame_strip({p.stem: _load(p) for p in args.motions}, args.out, n=args.frames))
    return 0
