"""Caches never answer with a stale result: every input that changes an output changes its key, and
an entry is written whole or not at all.

Each test reproduces a gap that gave an old clip, COM motion, survey or message for a new input.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]


def _protocol(tmp_path: Path, name: str, **changes) -> Path:
    """A bundled protocol with top-level fields replaced, written to tmp_path (key order kept)."""
    data = yaml.safe_load((ROOT / "protocols" / f"{name}.yaml").read_text())
    data.update(changes)
    path = tmp_path / f"{name}_{len(list(tmp_path.glob('*.yaml')))}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _hashes(path: Path) -> dict[str, str]:
    from stimuli.design import build_design
    from stimuli.protocol import load_protocol
    from stimuli.render.settings import inputs_hash, look_for

    protocol = load_protocol(path)
    return {s.stimulus_id: inputs_hash(protocol, s, look_for(protocol, s)) for s in build_design(protocol).stimuli}


# -- clips (render manifest's inputs_hash) ------------------------------------------------------------

def test_clip_hash_follows_the_seed_of_generated_motions(tmp_path):
    """The seed draws each actor's individual style, so Exp 1's clips change with it: another seed
    kept every clip of the old one. Clips that show no generated motion keep their hash."""
    exp1 = _hashes(_protocol(tmp_path, "exp1_shape_motion"))
    other = _hashes(_protocol(tmp_path, "exp1_shape_motion", seed=7))
    assert all(exp1[sid] != other[sid] for sid in exp1)
    exp2 = _hashes(_protocol(tmp_path, "exp2_com_vs_average"))   # NoCOM/COM files: their bytes are hashed
    assert exp2 == _hashes(_protocol(tmp_path, "exp2_com_vs_average", seed=7))


def test_familiarization_clip_hash_follows_the_first_declared_gait(tmp_path):
    """A familiarization clip shows the first declared gait; the hash held the gaits sorted, so a
    protocol whose jog now comes first kept the walking clip."""
    exp1 = yaml.safe_load((ROOT / "protocols" / "exp1_shape_motion.yaml").read_text())
    walk_first = _hashes(_protocol(tmp_path, "exp1_shape_motion", familiarization={"enabled": True}))
    jog_first = _hashes(_protocol(tmp_path, "exp1_shape_motion", familiarization={"enabled": True},
                                  gaits=dict(reversed(list(exp1["gaits"].items())))))
    familiar = [sid for sid in walk_first if sid.startswith("fam-")]
    assert familiar and all(walk_first[sid] != jog_first[sid] for sid in familiar)
    assert all(walk_first[sid] == jog_first[sid] for sid in walk_first if sid not in familiar)


def test_upstream_digest_covers_the_renderers_own_code(tmp_path, monkeypatch):
    """Only the shaders and a hand-bumped RENDER_VERSION stood for the renderer: a new body colour in
    render/scene.py kept every clip rendered in the old one."""
    from stimuli import fileio
    from stimuli.render.settings import upstream_digest

    copy = tmp_path / "stimuli"
    shutil.copytree(ROOT / "stimuli", copy, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(fileio, "__file__", str(copy / "fileio.py"))
    before = upstream_digest.__wrapped__()
    scene = copy / "render" / "scene.py"
    scene.write_text(scene.read_text().replace("BODY_GREY = (0.62, 0.62, 0.62)", "BODY_GREY = (0.3, 0.3, 0.3)"))
    assert upstream_digest.__wrapped__() != before


def test_rendering_again_with_another_seed_gives_the_fresh_clip(tmp_path):
    """End to end: the clip kept in the folder is the one a fresh render of the new protocol makes."""
    import csv

    from stimuli.render.pipeline import render_protocol

    clip = {"duration_s": 1.1, "cycles": 1, "fps": 30, "width": 320, "height": 180}
    options = dict(resolution="160x90", fps=10, workers=1, progress=False, limit=1, sheet=False)

    def sha(out):
        with open(out / "manifest.csv", newline="") as handle:
            return [row["sha256"] for row in csv.DictReader(handle)]

    render_protocol(_protocol(tmp_path, "exp1_shape_motion", clip=clip), tmp_path / "out", **options)
    first = sha(tmp_path / "out")
    changed = _protocol(tmp_path, "exp1_shape_motion", clip=clip, seed=7)
    again = render_protocol(changed, tmp_path / "out", **options)
    render_protocol(changed, tmp_path / "fresh", **options)
    assert again.rendered and sha(tmp_path / "out") == sha(tmp_path / "fresh") != first


# -- motions written into caches (Motion.save) -----------------------------------------------------

_SAVER = textwrap.dedent('''
    import sys, time
    from pathlib import Path
    from stimuli.motion import Motion
    source, target, role, seconds = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
    motion, problems, end = Motion.load(source), [], time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            motion.save(target) if role == "write" else (Path(target).exists() and Motion.load(target))
        except Exception as exc:
            problems.append(type(exc).__name__)
    print(len(problems), sorted(set(problems)))
''')


def test_two_processes_saving_one_motion_never_expose_a_broken_file(tmp_path):
    """Motion.save wrote through one fixed temporary name: two processes saving the same cache entry
    wrote into one file, the loser's rename failed and readers found the motion empty."""
    from stimuli.motion.generate import GaitParams, generate

    source = tmp_path / "walk.npz"
    generate(GaitParams(gait="walk", cadence_spm=112, speed_mps=1.2), height_m=1.6, fps=30, cycles=2).save(source)
    target = tmp_path / "cache" / "entry.npz"
    procs = [subprocess.Popen([sys.executable, "-c", _SAVER, str(source), str(target), role, "2.0"],
                              stdout=subprocess.PIPE, text=True, cwd=ROOT)
             for role in ("write", "write", "read")]
    outputs = [p.communicate(timeout=120)[0].strip() for p in procs]
    assert outputs == ["0 []"] * 3
    assert [p.name for p in target.parent.iterdir()] == ["entry.npz"]   # no temporary file left


def test_motion_save_writes_what_numpy_writes(tmp_path):
    """Saving through a buffer keeps the bytes of numpy's own file (the physics cache keys NoCOM motions
    by their bytes, and the demo's outputs are byte-identical across clones)."""
    from stimuli.motion.generate import GaitParams, generate

    motion = generate(GaitParams(gait="walk", cadence_spm=112, speed_mps=1.2), height_m=1.6, fps=30, cycles=2)
    np.savez_compressed(tmp_path / "numpy.npz", fps=np.float64(motion.fps),
                        joint_names=np.array(motion.joint_names, dtype=str), parents=motion.parents.astype(np.int32),
                        offsets=motion.offsets, rotations=motion.rotations, root_translation=motion.root_translation,
                        metadata=np.array(json.dumps(motion.metadata, sort_keys=True)))
    assert motion.save(tmp_path / "saved.npz").read_bytes() == (tmp_path / "numpy.npz").read_bytes()


# -- COM motions (physics protocol step) ---------------------------------------------------------

_FULL_DISK = textwrap.dedent('''
    import resource, signal, sys
    from types import SimpleNamespace
    import stimuli.bodies, stimuli.motion, stimuli.physics.analysis_fig7, stimuli.physics.retarget
    from stimuli.physics import protocol_step

    # The simulation is replaced by a fall (so only the report is written), the disk by one that
    # takes 64 KB more: the report (about 1 MB here) is cut short, as on a full disk.
    stimuli.bodies.fit_body = lambda *args, **kwargs: None
    report = {"fell": True, "samples": list(range(150_000))}
    fall = SimpleNamespace(report=report, sim=SimpleNamespace(fell=True))
    sys.modules["stimuli.physics.retarget"].retarget = lambda *args, **kwargs: fall
    args = dict(motion=sys.argv[1], out_report=sys.argv[2], out_motion=sys.argv[2] + ".npz", sex="F", height_m=1.6,
                bmi=22.0, girths={}, reference=[1.6, 22.0], weight_kg=56.3, actor="F_X", gait="walk")
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (64 * 1024, resource.RLIM_INFINITY))
    try:
        protocol_step._job(args)
    except OSError as exc:
        print("write failed:", exc.strerror)
''')


def test_a_cut_short_report_leaves_no_cache_entry(tmp_path):
    """The report marks a COM motion's cache entry finished. Written in place, a write cut short left
    a truncated report that every later run took for a finished entry and crashed on (JSONDecodeError)."""
    pytest.importorskip("resource")
    from stimuli.motion.generate import GaitParams, generate

    motion = tmp_path / "nocom.npz"
    generate(GaitParams(gait="walk", cadence_spm=112, speed_mps=1.2), height_m=1.6, fps=30, cycles=2).save(motion)
    report = tmp_path / "cache" / "entry.json"
    report.parent.mkdir()
    run = subprocess.run([sys.executable, "-c", _FULL_DISK, str(motion), str(report)], capture_output=True,
                         text=True, cwd=ROOT, timeout=300)
    assert "write failed: File too large" in run.stdout, run.stdout + run.stderr
    assert not report.exists(), f"a truncated report of {report.stat().st_size} bytes passes for a finished entry"
    assert list(report.parent.iterdir()) == []


def _fallen_report(actor) -> dict:
    """A physics report of a COM motion that fell (the fields the protocol step reads)."""
    body = {"sex": actor.sex, "height_m": actor.height_m, "weight_kg": actor.weight_kg, "bmi": actor.bmi}
    return {"actor": actor.id, "gait": "walk", "body": body, "reference_body": dict(body), "b_m": 0.0,
            "b_paper_m": 0.0, "tracking_rms_deg_overall": 30.0, "root_drift": {"vertical_max_m": 0.4},
            "fell": True, "fall_reason": "pelvis below 60% of its target height", "flight_fraction": 0.0}


def _small_exp2(tmp_path, monkeypatch, waist_of_f_hi1=None):
    """Exp 2 cut to 2 actors per sex and the walk, its NoCOM walks in ``tmp/nocom``, every COM entry
    cached as a fall (nothing to simulate); returns (protocol path, NoCOM folder, the job specs keyed)."""
    from stimuli.motion.style import actor_gait
    from stimuli.physics import protocol_step
    from stimuli.protocol import load_protocol

    from conftest import write_small_exp2

    path = write_small_exp2(tmp_path / "exp2_small.yaml", waist_of_f_hi1)
    protocol = load_protocol(path)
    motions = tmp_path / "nocom"
    for actor in (protocol.actors[0], protocol.actors[2]):   # one NoCOM walk per sex, with its own body
        walk = actor_gait(actor, "walk", 112, 1.2, 1, 30.0, 2)
        walk.metadata.update(sex=actor.sex, height_m=actor.height_m, bmi=actor.bmi)
        walk.save(motions / f"{actor.sex}_walk.npz")
    cache = tmp_path / "cache"
    cache.mkdir()
    specs = []
    monkeypatch.setattr(protocol_step, "cache_dir", lambda: cache)
    monkeypatch.setattr(protocol_step, "_key",
                        lambda motion, spec, gains: specs.append(spec) or f"{spec['actor']}_{spec['gait']}")
    for actor in protocol.actors:   # every entry cached, as a fall: nothing to simulate
        (cache / f"{actor.id}_walk.json").write_text(json.dumps(_fallen_report(actor)))
    return path, motions, specs


def test_a_com_motion_that_falls_removes_the_earlier_runs_file(tmp_path, monkeypatch):
    """A second physics run into the same folder whose ragdoll falls (e.g. after retuned gains) kept the
    first run's motions/COM_<actor>_<gait>.npz, which the renderer (--motions) then showed as the COM clip."""
    from stimuli.errors import StimuliError
    from stimuli.physics import protocol_step

    path, motions, _ = _small_exp2(tmp_path, monkeypatch)
    out = tmp_path / "physics"
    earlier = out / "motions" / "COM_F_Hi1_walk.npz"
    shutil.copytree(motions, out / "motions")
    (out / "motions" / "F_walk.npz").rename(earlier)   # an earlier run's COM motion
    with pytest.raises(StimuliError, match="the ragdoll fell for 4 COM motion"):
        protocol_step.run_protocol(path, out, motions_dir=motions)
    assert not earlier.exists()
    assert json.loads((out / "reports" / "COM_F_Hi1_walk.json").read_text())["fell"]


def test_com_bodies_are_fitted_with_the_actors_girths(tmp_path, monkeypatch):
    """The renderer shows an actor's body fitted with its girths (body_for_actor); the physics step
    built the ragdoll from a body fitted to height and BMI alone, and its cache key ignored girths."""
    from stimuli.errors import StimuliError
    from stimuli.physics import protocol_step

    path, motions, specs = _small_exp2(tmp_path, monkeypatch, waist_of_f_hi1=0.95)
    with pytest.raises(StimuliError, match="fell"):
        protocol_step.run_protocol(path, tmp_path / "physics", motions_dir=motions)
    girths = {spec["actor"]: spec["girths"] for spec in specs}
    assert girths == {"F_Hi1": {"waist_m": 0.95}, "F_Lo2": {}, "M_Hi1": {}, "M_Lo2": {}}
    fitted = []

    def fit_body(*args, **kwargs):
        fitted.append(kwargs)
        raise RuntimeError("fitted")

    monkeypatch.setattr("stimuli.bodies.fit_body", fit_body)
    spec = next(s for s in specs if s["actor"] == "F_Hi1")
    with pytest.raises(RuntimeError, match="fitted"):
        protocol_step._job(dict(spec, motion=str(motions / "F_walk.npz"), out_motion="", out_report=""))
    assert fitted[0] == {"waist_m": 0.95}


# -- survey exports (render's survey step, demo) --------------------------------------------------

def _export(tmp_path, folder, seed):
    from stimuli.design import build_design, write_design
    from stimuli.protocol import load_protocol
    from stimuli.survey import export_all

    write_design(build_design(load_protocol(_protocol(tmp_path, "exp1_shape_motion", seed=seed))), folder)
    return export_all(folder, video_base_url="https://example.org/clips")


def test_export_all_writes_the_jspsych_site_of_the_new_design(tmp_path):
    """An existing jsPsych folder was always kept: after a new design (another seed) its site ran the old
    trial orders while the QSF and PsychoPy files beside it had the new ones."""
    from stimuli.survey.jspsych import node_modules

    if not (node_modules() / "jspsych").is_dir():
        pytest.skip("jsPsych is not installed (npm ci)")
    _export(tmp_path, tmp_path / "out", 1)
    unchanged = _export(tmp_path, tmp_path / "out", 1)
    assert "left as it is" in unchanged[2].notes[0]
    again = _export(tmp_path, tmp_path / "out", 2)
    _export(tmp_path, tmp_path / "fresh", 2)
    config = "survey/jspsych/config.js"
    assert (tmp_path / "out" / config).read_text() == (tmp_path / "fresh" / config).read_text()
    assert "written again" in again[2].notes[0]
    assert not [p for p in (tmp_path / "out" / "survey").iterdir() if p.name.startswith(".")]


def test_export_all_never_replaces_a_jspsych_folder_holding_other_files(tmp_path):
    """A lab's own files (a data script, collected data) in the site are never deleted; the note says
    the site may be out of date."""
    from stimuli.survey.jspsych import node_modules

    if not (node_modules() / "jspsych").is_dir():
        pytest.skip("jsPsych is not installed (npm ci)")
    _export(tmp_path, tmp_path / "out", 1)
    site = tmp_path / "out" / "survey" / "jspsych"
    (site / "data").mkdir()
    (site / "data" / "p1.csv").write_text("participant\n1\n")
    before = (site / "config.js").read_text()
    again = _export(tmp_path, tmp_path / "out", 2)
    assert (site / "data" / "p1.csv").read_text() == "participant\n1\n" and (site / "config.js").read_text() == before
    assert "data/p1.csv" in again[2].notes[0] and "left as it is" in again[2].notes[0]


# -- bodies --------------------------------------------------------------------------------------

def test_a_cached_unreachable_body_is_reported_under_its_own_id(tmp_path, monkeypatch):
    """The cached fit report kept the message of the body id it was first fitted as, so a protocol
    actor out of reach was reported under another actor's (or a --sex/--height/--bmi body's) id."""
    from stimuli.bodies import backend, fit_body
    from stimuli.bodies.api import BodyFitError

    monkeypatch.setenv("ANNY_CACHE_DIR", str(backend.anny_cache_dir()))  # keep Anny's model cache where it is
    monkeypatch.setenv("SHAPEMOTION_CACHE", str(tmp_path))
    errors = {}
    for body_id in ("F_first", "F_second"):
        with pytest.raises(BodyFitError) as info:
            fit_body("F", 1.6, 58, body_id=body_id)
        errors[body_id] = info.value
    assert errors["F_second"].nearest.fit.cached
    assert str(errors["F_second"]) == str(errors["F_first"]).replace("body F_first:", "body F_second:")
    assert str(errors["F_second"]).startswith("body F_second:")


def test_an_averages_simulations_start_before_the_next_average_and_a_bad_one_leaves_no_output(tmp_path, monkeypatch):
    """The workers simulate the women's average while the men's is made (they sat idle for the ~8 s of
    the averages); a failure in the next average still leaves no output folder behind."""
    from stimuli.errors import StimuliError
    from stimuli.motion.style import actor_gait
    from stimuli.physics import protocol_step
    from stimuli.protocol import load_protocol

    from conftest import write_small_exp2

    path = write_small_exp2(tmp_path / "exp2_small.yaml")
    actor = load_protocol(path).actors[0]
    walk = actor_gait(actor, "walk", 112, 1.2, 1, 30.0, 2)
    walk.metadata.update(sex="F", height_m=actor.height_m, bmi=actor.bmi)

    def nocom_motion(protocol, sex, gait, motions_dir):
        if sex == "M":
            raise StimuliError("the men's capture is broken")
        return walk

    submitted = []
    monkeypatch.setattr(protocol_step, "nocom_motion", nocom_motion)
    monkeypatch.setattr(protocol_step, "cache_dir", lambda: tmp_path / "cache")
    monkeypatch.setattr(protocol_step._LazyPool, "submit", lambda self, fn, job: submitted.append(job["name"]))
    with pytest.raises(StimuliError, match="men's capture is broken"):
        protocol_step.run_protocol(path, tmp_path / "physics")
    assert submitted == ["COM_F_Hi1_walk", "COM_F_Lo2_walk"]
    assert not (tmp_path / "physics").exists()
    staged = list((tmp_path / "cache").glob("nocom_*.npz"))   # the jobs' copy, named by its content
    assert len(staged) == 1 and staged[0].read_bytes() == walk.to_bytes()
