"""``shapemotion demo``: the whole chain on the bundled protocols, step by step.

protocol → design → bodies (contact sheet) → COM physics for Exp 2 (Fig. 7) → clips of both paper
experiments (contact sheets of posters) → survey exports → simulated responses → ANOVA report.
Every step is cached or resumable, so a second run takes a fraction of the first.
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from pathlib import Path

from stimuli.design import build_design, write_design
from stimuli.protocol import load_protocol

PROTOCOL_DIR = Path(__file__).resolve().parents[1] / "protocols"
BUNDLED = ["exp1_shape_motion", "exp2_com_vs_average", "thesis_pointlight", "thesis_mesh", "thesis_validation",
           "exp1_own_captures"]
# exp1_own_captures: Exp 1's design on real CMU captures (protocols/captures), 16 clips.
RENDERED = ["exp1_shape_motion", "exp2_com_vs_average", "exp1_own_captures"]
DEMO_RESOLUTION, DEMO_FPS = (480, 270), 30   # keeps the two paper sets to a few minutes on 2 cores
# The captures' set at the quick size: its 16 clips took 76 s at 480×270/30 fps and 48 s at 320×180/15 fps
# (both with the 2 cores shared, load 5; 25 s at 320×180/15 fps on a quieter machine).
DEMO_SIZES = {"exp1_own_captures": ((320, 180), 15)}


def bundled_protocol(name: str) -> Path:
    return PROTOCOL_DIR / f"{name}.yaml"


@contextmanager
def _step(label: str):
    """Print a step's name and, when it ends, its wall time."""
    start = time.perf_counter()
    print(f"[{label}] …", flush=True)
    yield
    print(f"[{label}] done in {time.perf_counter() - start:.1f} s", flush=True)


def run_demo(out: Path, quick: bool = False) -> dict[str, list[Path]]:
    """Run every step for the bundled protocols; print and return what was made.

    ``quick``: tiny clips (320 px, 15 fps) and only a few of them — for tests and a first look.
    """
    out = Path(out)
    made: dict[str, list[Path]] = {}
    with _step("design"):
        for name in BUNDLED:
            design = build_design(load_protocol(bundled_protocol(name)))
            made[f"design/{name}"] = write_design(design, out / name)
            tests = sum(s.kind == "test" for s in design.stimuli)
            print(f"  {name}: {tests} test stimuli, {len(design.trials)} trials for {design.participants} "
                  f"participants → {out / name}")
    with _step("bodies"):
        from stimuli.bodies import fit_protocol_bodies, write_bodies

        exp1 = load_protocol(bundled_protocol("exp1_shape_motion"))
        made["bodies"] = write_bodies(fit_protocol_bodies(exp1, progress=False), out / "bodies", title=exp1.name)
        print(f"  {len(exp1.actors)} bodies fitted to Table 2 (+ practice actors) → {out / 'bodies' / 'contact_sheet.png'}")
    physics_dir = out / "exp2_com_vs_average" / "physics"
    with _step("physics"):
        from stimuli.physics.protocol_step import run_protocol

        result = run_protocol(bundled_protocol("exp2_com_vs_average"), physics_dir)
        made["physics"] = [Path(f) for f in result["figures"]]
        fell = sum(r["fell"] for r in result["reports"])
        print(f"  {len(result['reports'])} COM motions ({fell} fell), Fig. 7 → {made['physics'][0]}")
        for line in result["warnings"]:   # e.g. a motions folder whose walks hop
            print(f"    warning: {line}")
    with _step("render"):
        from stimuli.render import render_protocol

        for name in RENDERED:
            # quick renders only a few clips, so they go beside the design: the survey needs a full manifest
            target = out / "quick_clips" / name if quick else out / name
            resolution, fps = DEMO_SIZES.get(name, (DEMO_RESOLUTION, DEMO_FPS))
            report = render_protocol(bundled_protocol(name), target, resolution=None if quick else resolution,
                                     fps=None if quick else fps, quick=quick, limit=4 if quick else None,
                                     motions_dir=physics_dir if name == "exp2_com_vs_average" else None,
                                     progress=not quick)
            made[f"render/{name}"] = [report.manifest, report.contact_sheet]
            print(f"  {name}: {len(report.rendered)} clips rendered, {len(report.skipped)} up to date → "
                  f"{report.contact_sheet}")
            for line in report.warnings:   # e.g. a gait whose cadence the looping clip changes
                print(f"    warning: {line}")
    with _step("survey"):
        from stimuli.survey import export_all

        for name in BUNDLED:
            results = export_all(out / name)
            made[f"survey/{name}"] = [r.path for r in results]
            print(f"  {name}: {', '.join(r.format for r in results)} → {out / name / 'survey'}")
    with _step("analysis"):
        from analysis.report import demo_report

        for name in BUNDLED:
            protocol = load_protocol(bundled_protocol(name))
            report = demo_report(out / name, out / name / "results", seed=protocol.seed)
            made[f"analysis/{name}"] = [report]
            print(f"  {name}: simulated {protocol.participants} participants → {report}")
    return made
