"""Actors' own captures in a protocol (``actors[].motions``, issue 20 item 1).

The field is validated with the other protocol fields (actor, gait and YAML line named); ``validate``
imports and loops every capture before anything is rendered (a missing file, an unparsable BVH or a
capture without a steady cycle of its gait: exit 2 naming actor, gait, file and what was found); a
gait without a capture is generated; the manifest records each clip's motion source; a changed
capture changes the clip's inputs hash; the bundled ``exp1_own_captures`` makes Exp. 1's design.
"""

from __future__ import annotations

import csv
import hashlib
import shutil
from pathlib import Path

import pytest

from stimuli.cli import main
from stimuli.design import build_design
from stimuli.errors import StimuliError
from stimuli.motion.captures import MOTION_COLUMNS, actor_motion, looped_capture, motion_record
from stimuli.protocol import load_protocol, parse_protocol
from stimuli.render.manifest import motion_columns, with_all_columns
from stimuli.render.pipeline import plan

ROOT = Path(__file__).resolve().parents[1]
OWN = ROOT / "protocols" / "exp1_own_captures.yaml"
CAPTURES = ROOT / "protocols" / "captures"
# YAML lines of the two captured actors' motions, as the messages must name them
LINES = {actor: next(i for i, line in enumerate(OWN.read_text().splitlines(), 1) if capture in line)
         for actor, capture in (("M_Lo", "cmu_35_01_walk.bvh"), ("F_Lo", "cmu_02_01_walk"))}


@pytest.fixture
def lab(tmp_path):
    """A copy of the bundled protocol and its captures in a folder of its own (files may be changed)."""
    shutil.copytree(CAPTURES, tmp_path / "captures")
    protocol = tmp_path / "own.yaml"
    protocol.write_text(OWN.read_text())
    return protocol


def edit(path: Path, old: str, new: str) -> Path:
    text = path.read_text()
    assert old in text, old
    path.write_text(text.replace(old, new, 1))
    return path


def validate(path: Path, capsys) -> tuple[int, str]:
    code = main(["validate", str(path)])
    out = capsys.readouterr()
    return code, " ".join((out.out + out.err).split())   # the error paragraph is wrapped to the terminal


# -- the protocol field -------------------------------------------------------------------------

def test_a_capture_is_a_file_name_or_a_file_with_its_range():
    p = load_protocol(OWN)
    lo = next(a for a in p.actors if a.id == "M_Lo")
    assert lo.motions["walk"].file == "captures/cmu_35_01_walk.bvh" and lo.motions["walk"].start_s is None
    text = OWN.read_text().replace("motions: {walk: captures/cmu_35_01_walk.bvh,",
                                   "motions: {walk: {file: captures/cmu_35_01_walk.bvh, start_s: 0.5, end_s: 2.9},")
    walk = next(a for a in parse_protocol(text).actors if a.id == "M_Lo").motions["walk"]
    assert (walk.start_s, walk.end_s) == (0.5, 2.9)


@pytest.mark.parametrize("old, new, expected", [
    ("captures/cmu_35_01_walk.bvh,", "captures/cmu_35_01_walk.c3d,",
     ["actors.0.motions.walk.file (line {M_Lo}; actor M_Lo, gait walk)", "not a motion capture", ".bvh", ".npz"]),
    ("captures/cmu_35_01_walk.bvh,", "{file: captures/cmu_35_01_walk.bvh, start_s: 3.0, end_s: 2.0},",
     ["actors.0.motions.walk.end_s (line {M_Lo}; actor M_Lo, gait walk)", "must come after start_s"]),
    ("captures/cmu_35_01_walk.bvh,", "{file: captures/cmu_35_01_walk.bvh, start: 1},",
     ["actors.0.motions.walk.start (line {M_Lo}; actor M_Lo, gait walk)", "unknown field", "file, start_s, end_s"]),
    ("{walk: captures/cmu_02_01_walk_mb2names_120fps.bvh}", "{walk: {file: captures/x.bvh, start_s: -1}}",
     ["actors.2.motions.walk.start_s (line {F_Lo}; actor F_Lo, gait walk)", "greater than or equal to 0"]),
    ("jog: captures/cmu_35_17_run.bvh", "sprint: captures/cmu_35_17_run.bvh",
     ["actors.M_Lo.motions.sprint (line {M_Lo};", "actor M_Lo", "'sprint'", "not declared under gaits"]),
])
def test_a_bad_capture_field_names_the_actor_gait_and_line(old, new, expected):
    with pytest.raises(StimuliError) as err:
        parse_protocol(OWN.read_text().replace(old, new, 1), "own.yaml")
    for part in expected:
        part = part.format(**LINES)
        assert part in str(err.value), (part, str(err.value))


# -- validate: every capture imported and looped before rendering --------------------------------

def test_validate_lists_each_capture_it_looped(capsys):
    code, out = validate(OWN, capsys)
    assert code == 0, out
    assert "capture M_Lo walk: captures/cmu_35_01_walk.bvh: 2 cycle(s) from 0.62-2.86 s" in out
    assert "capture M_Lo jog: captures/cmu_35_17_run.bvh" in out and "capture F_Lo walk:" in out


def test_validate_refuses_a_missing_capture(lab, capsys):
    (lab.parent / "captures" / "cmu_35_17_run.bvh").unlink()
    code, out = validate(lab, capsys)
    assert code == 2
    assert "actors.M_Lo.motions.jog (line" in out and "captures/cmu_35_17_run.bvh: file not found" in out


def test_validate_refuses_an_unparsable_capture(lab, capsys):
    (lab.parent / "captures" / "cmu_02_01_walk_mb2names_120fps.bvh").write_text("HIERARCHY\nROOT Hips {\n")
    code, out = validate(lab, capsys)
    assert code == 2
    assert "actors.F_Lo.motions.walk (line" in out and "cmu_02_01_walk_mb2names_120fps.bvh" in out
    assert "not a readable BVH file" in out


def test_validate_reads_an_amass_capture_with_the_amass_reader(lab, capsys):
    import numpy as np

    np.savez(lab.parent / "captures" / "f_walk.npz", poses=np.zeros((3, 30)), trans=np.zeros((3, 3)),
             mocap_framerate=30.0)
    edit(lab, "{walk: captures/cmu_02_01_walk_mb2names_120fps.bvh}", "{walk: captures/f_walk.npz}")
    code, out = validate(lab, capsys)
    assert code == 2 and "actors.F_Lo.motions.walk (line" in out and "f_walk.npz" in out
    assert "at least 22 joints" in out   # read_amass's own check of the SMPL body joints


def test_validate_refuses_a_capture_without_a_steady_cycle_of_its_gait(lab, capsys):
    """The run named as a walk: no steady walk in it; the message names the ranges it found."""
    edit(lab, "motions: {walk: captures/cmu_35_01_walk.bvh,", "motions: {walk: captures/cmu_35_17_run.bvh,")
    code, out = validate(lab, capsys)
    assert code == 2
    assert "actors.M_Lo.motions.walk (line" in out and "captures/cmu_35_17_run.bvh" in out
    assert "no loop" in out and "It holds: run" in out and " s at " in out   # the ranges, with times and speeds


def test_validate_refuses_a_range_that_holds_no_cycle(lab, capsys):
    edit(lab, "motions: {walk: captures/cmu_35_01_walk.bvh,",
         "motions: {walk: {file: captures/cmu_35_01_walk.bvh, start_s: 0.0, end_s: 0.6},")
    code, out = validate(lab, capsys)
    assert code == 2 and "actors.M_Lo.motions.walk" in out and "between 0.0 and 0.6 s" in out


# -- motions: capture or generator --------------------------------------------------------------

def test_an_actor_without_a_capture_gets_the_generators_gait():
    from stimuli.motion.style import actor_gait

    p = load_protocol(OWN)
    hi = next(a for a in p.actors if a.id == "F_Hi")
    lo = next(a for a in p.actors if a.id == "F_Lo")
    spec = p.gaits["walk"]
    generated = actor_motion(p, hi, "walk", 30.0, 4)
    assert generated.metadata.get("source") != "capture" and "capture_range_s" not in generated.metadata
    expected = actor_gait(hi, "walk", spec.cadence_spm, spec.speed_mps, p.seed, 30.0, 4)
    assert generated.n_frames == expected.n_frames and (generated.rotations == expected.rotations).all()
    captured = actor_motion(p, lo, "walk", 30.0, 4)   # its capture, at the capture's own rate
    assert captured.metadata["capture_range_s"] == [0.608, 2.817] and captured.fps == 120.0
    # a jog F_Lo did not capture falls back to the generator too
    assert "capture_range_s" not in actor_motion(p, lo, "jog", 30.0, 5).metadata


# -- manifest and inputs hash -------------------------------------------------------------------

def test_the_manifest_records_each_clips_motion_source():
    p = load_protocol(OWN)
    stimuli = {s.stimulus_id: s for s in build_design(p).stimuli}
    captured = motion_columns(p, stimuli["M-walk-Hi-Lo"])   # M_Hi's body, M_Lo's walk
    assert captured["motion_source"] == "capture" and captured["motion_file"] == "captures/cmu_35_01_walk.bvh"
    assert captured["motion_sha256"] == hashlib.sha256((CAPTURES / "cmu_35_01_walk.bvh").read_bytes()).hexdigest()
    assert captured["motion_range_s"] == "0.617-2.858"
    generated = motion_columns(p, stimuli["M-jog-Lo-Hi"])   # M_Hi has no capture
    assert generated["motion_source"] == "generator" and generated["motion_file"] == generated["motion_sha256"] == ""
    assert "actor=M_Hi;sex=M;height_m=1.79;bmi=32.1;gait=jog;cadence_spm=136.4;speed_mps=2.2;seed=2023" == \
        generated["motion_params"]
    # Exp 2's clips show averages, not one actor's gait: the columns stay empty
    exp2 = load_protocol(ROOT / "protocols" / "exp2_com_vs_average.yaml")
    assert set(motion_columns(exp2, build_design(exp2).stimuli[0]).values()) == {""}
    # rows of an older manifest get the new columns, empty, in order after theirs
    old = {"stimulus_id": "x", "cadence_spm": "112"}
    assert list(with_all_columns(old)) == ["stimulus_id", "cadence_spm", *MOTION_COLUMNS]


def test_a_changed_capture_changes_the_inputs_hash_of_its_clips_only(lab, tmp_path):
    def digests():
        p = load_protocol(lab)
        return {job.stimulus.stimulus_id: job.digest for job in plan(p, build_design(p).stimuli, tmp_path / "out")}

    before = digests()
    with open(lab.parent / "captures" / "cmu_02_01_walk_mb2names_120fps.bvh", "a") as handle:
        handle.write("\n")   # one more byte: the same motion, another file
    after = digests()
    changed = sorted(sid for sid in before if before[sid] != after[sid])
    assert changed == ["F-walk-Hi-Lo", "F-walk-Lo-Lo"]   # the clips showing F_Lo's walk


def test_a_changed_range_changes_the_inputs_hash(lab, tmp_path):
    p = load_protocol(lab)
    first = {j.stimulus.stimulus_id: j.digest for j in plan(p, build_design(p).stimuli, tmp_path)}
    edit(lab, "motions: {walk: captures/cmu_02_01_walk_mb2names_120fps.bvh}",
         "motions: {walk: {file: captures/cmu_02_01_walk_mb2names_120fps.bvh, start_s: 0.5}}")
    p = load_protocol(lab)
    second = {j.stimulus.stimulus_id: j.digest for j in plan(p, build_design(p).stimuli, tmp_path)}
    assert first["F-walk-Lo-Lo"] != second["F-walk-Lo-Lo"]
    assert looped_capture(p, "F_Lo", "walk").metadata["capture_range_s"][0] >= 0.5


# -- the bundled protocol ------------------------------------------------------------------------

def test_exp1_own_captures_makes_exp1s_design(tmp_path, capsys):
    p = load_protocol(OWN)
    design = build_design(p)
    tests = [s for s in design.stimuli if s.kind == "test"]
    assert len(tests) == 16   # SEX 2 × GAIT 2 × BODY 2 × MOTION 2
    assert {(s.body_actor, s.motion_actor) for s in tests if s.levels["SEX"] == "M"} == \
        {("M_Hi", "M_Hi"), ("M_Hi", "M_Lo"), ("M_Lo", "M_Hi"), ("M_Lo", "M_Lo")}
    assert [f.name for f in p.factors] == ["SEX", "GAIT", "BODY", "MOTION"]
    assert [f.role for f in p.factors] == ["between", "within", "within", "within"]
    assert sum(motion_record(p, a.id, g)["motion_source"] == "capture" for a in p.actors for g in p.gaits) == 3
    assert main(["design", str(OWN), "--out", str(tmp_path / "d")]) == 0
    assert (tmp_path / "d" / "trials.csv").read_text().count("\n") == 1 + 8 * 16


def test_the_captures_carry_their_attribution():
    readme = (CAPTURES / "README.md").read_text()
    assert "mocap.cs.cmu.edu" in readme and "NSF EIA-0196217" in readme
    for path in CAPTURES.glob("*.bvh"):
        assert path.name in readme
        assert hashlib.md5(path.read_bytes()).hexdigest() in readme   # unchanged from the source set


@pytest.mark.slow  # renders 3 clips (about 35 s on 2 shared cores)
def test_render_quick_records_captures_in_the_manifest(tmp_path):
    assert main(["render", str(OWN), "--out", str(tmp_path), "--quick", "--only",
                 "M-walk-Hi-Lo,M-jog-Lo-Lo,F-jog-Hi-Hi", "--no-survey"]) == 0
    with open(tmp_path / "manifest.csv", newline="") as handle:
        rows = {row["stimulus_id"]: row for row in csv.DictReader(handle)}
    assert set(rows) == {"M-walk-Hi-Lo", "M-jog-Lo-Lo", "F-jog-Hi-Hi"}
    assert rows["M-walk-Hi-Lo"]["motion_source"] == rows["M-jog-Lo-Lo"]["motion_source"] == "capture"
    assert rows["M-jog-Lo-Lo"]["motion_file"] == "captures/cmu_35_17_run.bvh"
    assert rows["F-jog-Hi-Hi"]["motion_source"] == "generator"
    # a capture keeps its own cadence: the run's 162 steps/min, not the protocol's jog (136.4)
    assert float(rows["M-jog-Lo-Lo"]["cadence_spm"]) == pytest.approx(163.6, abs=0.5)
    assert float(rows["F-jog-Hi-Hi"]["cadence_spm"]) == pytest.approx(136.4, abs=0.1)


@pytest.mark.slow  # fits the mean body and retargets four walks (about 10 s)
def test_exp2s_average_is_made_of_the_captures_where_actors_name_them(tmp_path):
    """Two of Exp 2's four M actors name captures: all four walks go onto the mean body's rig (captures
    come on other skeletons) and are averaged there; the average records the actors' mean body."""
    from stimuli.motion.average import protocol_average

    shutil.copytree(CAPTURES, tmp_path / "captures")
    text = (ROOT / "protocols" / "exp2_com_vs_average.yaml").read_text()
    for actor, capture in (("M_Lo1", "cmu_35_01_walk.bvh"), ("M_Lo2", "cmu_02_01_walk_mb2names_120fps.bvh")):
        line = next(line for line in text.splitlines() if f"{{id: {actor}," in line)
        text = text.replace(line, line.replace("}", f", motions: {{walk: captures/{capture}}}}}"))
    (tmp_path / "exp2.yaml").write_text(text)
    p = load_protocol(tmp_path / "exp2.yaml")
    average = protocol_average(p, "M", "walk", fps=30, cycles=4)
    assert average.joint_names[0] == "root" and average.fps == 30.0   # the Anny rig, not a capture's
    distances = average.metadata["dtw_distances"]
    assert len(distances) == 4 and distances[2][3] > 0   # the two captures differ from each other
    assert average.metadata["actors"] == ["M_Hi1", "M_Hi2", "M_Lo1", "M_Lo2"]
    assert average.metadata["height_m"] == pytest.approx((1.79 + 1.83 + 1.81 + 1.82) / 4)
    # without captures the average is made from the generated gaits alone, on their own skeleton
    plain = protocol_average(load_protocol(ROOT / "protocols" / "exp2_com_vs_average.yaml"), "M", "walk", fps=30,
                             cycles=4)
    assert plain.joint_names[0] != "root"


MOCAP = ROOT.parent / "shared" / "data" / "mocap"


@pytest.mark.slow  # fits the mean body, retargets four runs and cleans their average (about 15 s)
def test_exp2s_average_of_real_runs_stands_on_the_belt(tmp_path):
    """The men's jog average of Exp 2 made of a CMU run and two Bandai runs (1.7-3.7 m/s): its stance
    feet move with the belt and stay out of the floor, as each run's do. Averaged joint by joint and
    left as it was, 29 % of its frames skated and a foot sank 48 mm (each run: 0 % and 0 mm)."""
    from stimuli.motion.average import protocol_average
    from stimuli.motion.loop import cycle_seams
    from stimuli.motion.metrics import plausibility_from_joints

    if not MOCAP.is_dir():
        pytest.skip(f"no captures at {MOCAP} (shared/ sits beside the clone)")
    runs = {"M_Hi1": "cmu_35_17_run.bvh", "M_Hi2": "more/bandai1_run_tired_001_jog_30fps.bvh",
            "M_Lo1": "more/bandai1_dash_active_001_run_30fps.bvh", "M_Lo2": "cmu_35_17_run.bvh"}
    text = (ROOT / "protocols" / "exp2_com_vs_average.yaml").read_text()
    for actor, capture in runs.items():
        line = next(line for line in text.splitlines() if f"{{id: {actor}," in line)
        text = text.replace(line, line.replace("}", f", motions: {{jog: {MOCAP / capture}}}}}"))
    (tmp_path / "exp2.yaml").write_text(text)
    average = protocol_average(load_protocol(tmp_path / "exp2.yaml"), "M", "jog", fps=30, cycles=2)
    assert average.joint_names[0] == "root" and len(average.metadata["dtw_distances"]) == 4   # the runs, on Anny
    quality = plausibility_from_joints(average)
    assert quality["skate_humos_pct"] <= 5.0 and quality["penetrate_max_mm"] <= 5.0, quality
    # Bandai's tired jog loops two cycles that differ and the runs' loops begin at other phases: the
    # average's pelvis jumped 33 mm in one frame at every seam (and a knee 24°). The joints' join read
    # 1.78 while the clean-up's toe lift ended within a frame at the CMU run's toe off (now 1.36).
    seams = cycle_seams(average, 2)
    assert seams["root_ratio"] < 1.5 and seams["joint_ratio"] < 1.5, seams


def test_render_refuses_a_bad_capture_before_making_anything(lab, tmp_path, capsys):
    (lab.parent / "captures" / "cmu_35_17_run.bvh").write_text("not a capture")
    out = tmp_path / "clips"
    assert main(["render", str(lab), "--out", str(out), "--quick"]) == 2
    message = " ".join(capsys.readouterr().err.split())
    assert "actors.M_Lo.motions.jog (line" in message and "not a readable BVH file" in message
    assert not out.exists()
