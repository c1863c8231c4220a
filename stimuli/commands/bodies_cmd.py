"""``shapemotion bodies``: fitted Anny bodies for a protocol's actors, or one body from sex/height/BMI."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from shapemotion.execution import SCHEDULER_HELP, SCHEDULER_METAVAR
from stimuli.errors import StimuliError
from stimuli.fileio import check_output_dir, check_output_file, output_path

MESH_SUFFIXES = (".ply", ".obj", ".glb", ".stl")
GIRTH_TOLERANCE_M = 0.02  # a girth target missed by more is reported, not passed off as reached


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "bodies", help="fit body meshes to sex, height and BMI (Anny)",
        description="Fit Anny bodies to every actor of a protocol (writes bodies.csv, meshes/<body_id>.ply, "
                    "anthropometry.csv, segments.csv, contact_sheet.png into --out), or one body from "
                    "--sex/--height/--bmi (writes the mesh to --out, a .ply/.obj/.glb file).")
    p.add_argument("protocol", type=Path, nargs="?", help="protocol YAML (omit for a single body)")
    p.add_argument("--out", type=output_path, required=True, help="output folder (protocol) or mesh file (single body)")
    p.add_argument("--sex", help="F or M (single body)")
    p.add_argument("--height", type=float, help="standing height in metres (single body)")
    p.add_argument("--bmi", type=float, help="body-mass index in kg/m² (single body)")
    p.add_argument("--waist", type=float, help="optional waist girth in metres")
    p.add_argument("--hip", type=float, help="optional hip girth in metres")
    p.add_argument("--chest", type=float, help="optional chest girth in metres")
    p.add_argument("--json", type=Path, help="single body: also write anthropometry, segments and fit as JSON")
    p.add_argument("--backend", default="anny", help="body model backend: anny (default) or smplx")
    p.add_argument("--smplx-dir", type=Path, help="smplx backend: folder with SMPLX_FEMALE.npz and SMPLX_MALE.npz")
    p.add_argument("--allow-nearest", action="store_true",
                   help="write the nearest reachable body where a target is out of reach (default: exit 2)")
    p.add_argument("--no-sheet", action="store_true", help="protocol: skip the contact-sheet PNG")
    p.add_argument("--scheduler", metavar=SCHEDULER_METAVAR, help="protocol: " + SCHEDULER_HELP)
    p.set_defaults(func=run_bodies)


def run_bodies(args: argparse.Namespace) -> int:
    from stimuli.bodies.api import BACKENDS

    if args.backend not in BACKENDS:
        raise StimuliError(f"--backend {args.backend!r} is not available; known backends: {', '.join(BACKENDS)}")
    if args.backend != "anny" and args.protocol is not None:
        raise StimuliError(f"--backend {args.backend}: protocol bodies use Anny; the smplx backend builds one body "
                           "at a time (--sex/--height/--bmi)")
    single = [args.sex, args.height, args.bmi]
    if args.protocol is not None:
        if any(v is not None for v in single):
            raise StimuliError("give either a PROTOCOL or --sex/--height/--bmi, not both")
        # The protocol gives each actor's girths, and writes the per-body facts as CSV files.
        unused = [name for name, v in (("--waist", args.waist), ("--hip", args.hip), ("--chest", args.chest),
                                       ("--json", args.json)) if v is not None]
        if unused:
            raise StimuliError(f"{', '.join(unused)}: only for a single body (--sex/--height/--bmi); a protocol "
                               "takes girths from its actors and writes bodies.csv, anthropometry.csv and "
                               "segments.csv")
        if args.out.suffix.lower() in MESH_SUFFIXES:
            raise StimuliError(f"--out {args.out}: a protocol's bodies go into a folder (bodies.csv, meshes/…); "
                               "give a folder name, not a mesh file")
        check_output_dir(args.out)
        return _run_protocol(args)
    if args.scheduler is not None:
        raise StimuliError("--scheduler: only for a PROTOCOL's bodies; a single body is one fit, made here")
    missing = [name for name, v in zip(("--sex", "--height", "--bmi"), single) if v is None]
    if missing:
        raise StimuliError(f"a single body needs {', '.join(missing)} (or give a PROTOCOL file)")
    return _run_single(args)


def _run_protocol(args) -> int:
    from stimuli.bodies import fit_protocol_bodies, write_bodies
    from stimuli.protocol import load_protocol

    from shapemotion.execution import errors_as, scheduler_option

    scheduler = scheduler_option(args.scheduler, StimuliError)
    protocol = load_protocol(args.protocol)
    if scheduler is None:
        bodies = fit_protocol_bodies(protocol, allow_nearest=args.allow_nearest, progress=True)
    else:
        with errors_as(StimuliError):
            bodies = _fit_on(scheduler, protocol, args.allow_nearest)
    write_bodies(bodies, args.out, sheet=not args.no_sheet, title=f"{protocol.name}: bodies sorted by BMI")
    for b in bodies:
        a = b.anthropometry
        flag = "" if b.fit.reachable else "  NEAREST (target out of reach)"
        print(f"{b.body_id:<12} {b.sex}  height {a.height_m:.3f} m  BMI {a.bmi:5.2f}  mass {a.mass_kg:5.1f} kg  "
              f"waist {a.waist_m:.3f} m{flag}")
    print(f"wrote {len(bodies)} bodies to {args.out}")
    return 0


def _fit_on(scheduler, protocol, allow_nearest: bool) -> list:
    """:func:`stimuli.bodies.fit_protocol_bodies` on a Dask cluster: one task per actor, keyed by its body's
    cache key (one body fitted for two actors of the same targets once); each body fitted comes back and
    enters this machine's body cache, so later steps here find it."""
    from shapemotion.execution import dask_client, run_tasks
    from stimuli.bodies import cache

    keys = {actor.id: _body_cache_key(actor) for actor in protocol.actors}
    tasks = {f"body-{actor.id}-{keys[actor.id]}": (actor,) for actor in protocol.actors}
    with dask_client(scheduler) as client:
        fitted = dict(run_tasks(client, _fit_actor, tasks, "bodies", "body"))
    bodies = [fitted[key] for key in tasks]
    for body, key in zip(bodies, keys.values()):
        if cache.load(key, body.body_id) is None:
            cache.save(body, key)
    problems = [b.fit.message for b in bodies if not b.fit.reachable]
    if problems and not allow_nearest:   # as fit_protocol_bodies says it
        raise StimuliError(f"protocol {protocol.name}: {len(problems)} actor(s) cannot be built: "
                           + "; ".join(problems) + " (use --allow-nearest to write the nearest bodies anyway)")
    return bodies


def _fit_actor(actor):
    """On a Dask worker: an actor's body, the nearest one where its targets are out of reach. The Anny
    model stays loaded in the worker process between tasks (``stimuli.bodies.backend``'s cache)."""
    from stimuli.bodies.api import body_for_actor

    return body_for_actor(actor, on_unreachable="nearest")


def _body_cache_key(actor) -> str:
    """The key :func:`stimuli.bodies.fit_body` files an actor's body under."""
    from stimuli.bodies.api import normalise_sex
    from stimuli.bodies.cache import cache_key
    from stimuli.bodies.fit import FITTER_VERSION, Targets

    girths = {k: None if getattr(actor, k, None) is None else float(getattr(actor, k))
              for k in ("waist_m", "hip_m", "chest_m")}
    targets = Targets(sex=normalise_sex(actor.sex), height_m=float(actor.height_m), bmi=float(actor.bmi), **girths)
    return cache_key(targets.key(), FITTER_VERSION)


def _run_single(args) -> int:
    from stimuli.bodies import fit_body
    from stimuli.bodies.api import girth_errors
    from stimuli.commands.checks import human_body

    if args.out.suffix.lower() not in MESH_SUFFIXES:
        raise StimuliError(f"--out {args.out}: a single body is written as a mesh file (.ply, .obj, .glb or .stl)")
    check_output_file(args.out)
    check_output_file(args.json, "--json")
    human_body(args.height, args.bmi)
    body = fit_body(args.sex, args.height, args.bmi, waist_m=args.waist, hip_m=args.hip, chest_m=args.chest,
                    on_unreachable="nearest" if args.allow_nearest else "raise", backend_name=args.backend,
                    smplx_dir=args.smplx_dir)
    if args.out.suffix.lower() == ".ply":
        body.save_ply(args.out)
    else:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        body.to_trimesh().export(args.out)
    a = body.anthropometry
    print(f"{body.body_id}: height {a.height_m:.3f} m, BMI {a.bmi:.2f}, mass {a.mass_kg:.1f} kg, waist {a.waist_m:.3f} m,"
          f" hip {a.hip_m:.3f} m, chest {a.chest_m:.3f} m -> {args.out}")
    if not body.fit.reachable:
        print(f"warning: {body.fit.message}")
    errors = girth_errors(body)
    missed = {k: e for k, e in errors.items() if abs(e) > GIRTH_TOLERANCE_M}
    for name, error in missed.items():  # girths are soft targets: say when one is missed
        print(f"warning: {name} target {body.targets[name]:.3f} m missed by {error * 100:+.1f} cm (the body model "
              f"cannot reach it at this height and BMI; tolerance ±{GIRTH_TOLERANCE_M * 100:.0f} cm)")
    if args.json:
        from stimuli.fileio import atomic_write_text

        report = {"body_id": body.body_id, "sex": body.sex, "targets": body.targets, "phenotype": body.phenotype,
                  "anthropometry": body.anthropometry.as_dict(), "fit": {
                      "reachable": body.fit.reachable and not missed, "height_error_m": body.fit.height_error_m,
                      "bmi_error": body.fit.bmi_error, "girth_errors_m": errors,
                      "girths_reached": not missed},
                  "segments": [s.as_row() for s in body.segments]}
        atomic_write_text(args.json, json.dumps(report, indent=2, sort_keys=True) + "\n")
    return 0
