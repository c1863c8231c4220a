"""Bad input on the stimuli side: exit code 2, a message naming the option/file/line, nothing left behind.

One group per kind of input: output paths, seeds, corrupt motion files, BVH frames, render options,
protocol level settings, motion/bodies/physics/preview/survey options. All fast (no body fits,
no rendering): every check runs before the work it protects.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from stimuli.errors import StimuliError
from stimuli.motion import Motion

ROOT = Path(__file__).resolve().parents[1]
EXP1 = ROOT / "protocols" / "exp1_shape_motion.yaml"
EXP2 = ROOT / "protocols" / "exp2_com_vs_average.yaml"
POINTLIGHT = ROOT / "protocols" / "thesis_pointlight.yaml"
VALIDATION = ROOT / "protocols" / "thesis_validation.yaml"
WALK_BVH = ROOT / "stimuli" / "data" / "cmu_35_01_walk.bvh"
BODY = "sex=M,height=1.8,bmi=25"


@pytest.fixture(scope="module")
def walk(tmp_path_factory) -> Path:
    """A short generated walk (.npz) to feed the motion commands."""
    from stimuli.cli import main

    path = tmp_path_factory.mktemp("walk") / "w.npz"
    assert main(["motion", "generate", "--cycles", "1", "--out", str(path)]) == 0
    return path


@pytest.fixture(scope="module")
def design_dir(tmp_path_factory) -> Path:
    from stimuli.cli import main

    out = tmp_path_factory.mktemp("design") / "d"
    assert main(["design", str(EXP1), "--out", str(out)]) == 0
    return out


@pytest.fixture
def work(tmp_path, monkeypatch) -> Path:
    """An empty working folder holding a file ``afile`` and an empty folder ``dd_empty``."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "afile").write_text("")
    (tmp_path / "dd_empty").mkdir()
    return tmp_path


def _tree(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def _fails(run_cli, *args) -> str:
    """Run the CLI; it must exit 2 without a traceback; return stderr on one line."""
    code, _, err = run_cli(*args)
    assert code == 2, (args, err)
    assert "Traceback" not in err
    return " ".join(err.split())


# -- 1. output paths ----------------------------------------------------------------------------

OUTPUT_CASES = [
    (["design", EXP1, "--out", "afile"], "--out afile"),
    (["design", EXP1, "--out", "afile/sub"], "afile is a file"),
    (["survey", "{design}", "--format", "qsf", "--out", "afile/x.qsf"], "afile is a file"),
    (["survey", "{design}", "--format", "qsf", "--out", "dd_empty"], "is a folder"),
    (["survey", "{design}", "--format", "psychopy", "--out", "afile"], "is a file"),
    (["bodies", "--sex", "F", "--height", "1.6", "--bmi", "28", "--out", "afile/b.ply"], "afile is a file"),
    (["bodies", "--sex", "F", "--height", "1.6", "--bmi", "28", "--out", "b.ply", "--json", "afile/x.json"],
     "--json afile/x.json"),
    (["bodies", EXP1, "--out", "afile"], "is a file"),
    (["motion", "generate", "--out", "afile/x.npz"], "afile is a file"),
    (["motion", "generate", "--out", "dd_empty"], "--out dd_empty"),
    (["motion", "generate", "--out", "g.npz", "--bvh", "afile/x.bvh"], "--bvh afile/x.bvh"),
    (["motion", "import", WALK_BVH, "--out", "afile/x.npz"], "afile is a file"),
    (["motion", "export-bvh", "{walk}", "--out", "afile/x"], "afile is a file"),
    (["motion", "average", "{walk}", "{walk}", "--out", "afile/x.npz"], "afile is a file"),
    (["motion", "modify", "{walk}", "--height", "1.8", "--body-fat", "20", "--out", "afile/x.npz"], "afile is a file"),
    (["motion", "metrics", "{walk}", "--json", "afile/x"], "--json afile/x"),
    (["motion", "markers", "{walk}", "--out", "afile/x.csv"], "afile is a file"),
    (["motion", "strip", "{walk}", "--out", "afile/x.png"], "afile is a file"),
    (["motion", "strip", "--protocol", EXP1, "--out", "afile"], "is a file"),
    (["physics", "retarget", "--motion", "{walk}", "--sex", "F", "--height", "1.6", "--weight", "60",
      "--out", "afile/x.npz"], "afile is a file"),
    (["physics", "retarget", "--motion", "{walk}", "--sex", "F", "--height", "1.6", "--weight", "60",
      "--out", "c.npz", "--report", "afile/r.json"], "--report afile/r.json"),
    (["physics", "protocol", EXP2, "--out", "afile"], "is a file"),
    (["render", EXP1, "--out", "afile"], "is a file"),
    (["preview", "--gait", "walk", "--body", BODY, "--out", "afile/x.mp4"], "afile is a file"),
]


@pytest.mark.parametrize("args, message", OUTPUT_CASES)
def test_unusable_output_path_is_named_and_nothing_is_written(work, run_cli, walk, design_dir, args, message):
    subs = {"{walk}": str(walk), "{design}": str(design_dir)}
    before = _tree(work)
    err = _fails(run_cli, *[subs.get(str(a), a) for a in args])
    assert message in err
    assert _tree(work) == before  # no .ply, .npz, .tmp.npz or folder left behind


def test_os_error_with_a_file_name_is_a_user_error(monkeypatch, run_cli):
    """The safety net in main(): an OSError naming a path is printed plainly, exit 2."""
    import stimuli.commands.protocol_cmds as cmds

    def refuse(args):
        raise PermissionError(13, "Permission denied", "out/x.csv")

    monkeypatch.setattr(cmds, "run_validate", refuse)
    err = _fails(run_cli, "validate", EXP1)
    assert "out/x.csv: Permission denied" in err


def test_motion_save_onto_a_folder_leaves_no_temporary_file(walk, tmp_path):
    target = tmp_path / "m.npz"
    target.mkdir()
    with pytest.raises(OSError):
        Motion.load(walk).save(target)
    assert _tree(tmp_path) == {"m.npz"}


# -- 2. seeds -----------------------------------------------------------------------------------

@pytest.mark.parametrize("args", [["design", EXP1, "--seed", "-1", "--out", "d"],
                                  ["motion", "generate", "--seed", "-1", "--out", "g.npz"]])
def test_negative_seed(work, run_cli, args):
    assert "--seed: expected a whole number >= 0, got -1" in _fails(run_cli, *args)
    assert _tree(work) == {"afile", "dd_empty"}


# -- 3. corrupt motion files --------------------------------------------------------------------

def _npz_variant(walk: Path, path: Path, **changes) -> Path:
    fields = dict(np.load(walk))
    fields.update(changes)
    np.savez(path, **fields)
    return path


@pytest.mark.parametrize("kind", ["empty", "text", "metadata"])
def test_corrupt_npz_is_not_a_motion(walk, tmp_path, kind):
    path = tmp_path / "m.npz"
    if kind == "empty":
        path.write_bytes(b"")
    elif kind == "text":
        path.write_text("hello\n")
    else:
        _npz_variant(walk, path, metadata=np.array("not json"))
    with pytest.raises(StimuliError, match=r"m\.npz: not a shapemotion motion \(\.npz\)") as err:
        Motion.load(path)
    assert "pickled" not in str(err.value)


def test_nan_quaternion_names_the_file_and_frame(walk, tmp_path):
    rot = np.load(walk)["rotations"].copy()
    rot[3, 2, 0] = np.nan
    path = _npz_variant(walk, tmp_path / "nan.npz", rotations=rot)
    with pytest.raises(StimuliError, match=r"nan\.npz: rotations hold NaN/inf at frame 3"):
        Motion.load(path)


def test_extra_npz_fields_are_ignored(walk, tmp_path):
    path = _npz_variant(walk, tmp_path / "extra.npz", extra=np.arange(3))
    assert Motion.load(path).n_frames == Motion.load(walk).n_frames


@pytest.mark.parametrize("command", [["motion", "export-bvh", "{m}", "--out", "o.bvh"],
                                     ["motion", "average", "{m}", "{m}", "--out", "a.npz"],
                                     ["motion", "metrics", "{m}"],
                                     ["physics", "retarget", "--motion", "{m}", "--sex", "F", "--height", "1.6",
                                      "--weight", "60", "--out", "c.npz"]])
def test_empty_npz_through_the_cli(work, run_cli, command):
    (work / "m.npz").write_bytes(b"")
    err = _fails(run_cli, *[str(work / "m.npz") if a == "{m}" else a for a in command])
    assert "not a shapemotion motion (.npz)" in err


# -- 4. BVH frames ------------------------------------------------------------------------------

def _bvh_variant(tmp_path: Path, edit) -> Path:
    lines = WALK_BVH.read_text().split("\n")
    edit(lines)
    path = tmp_path / "v.bvh"
    path.write_text("\n".join(lines))
    return path


def _set_frames(n):
    def edit(lines):
        lines[lines.index("Frames: 359")] = f"Frames: {n}"
    return edit


def _row(line_no, change):
    def edit(lines):
        values = lines[line_no - 1].split()
        lines[line_no - 1] = " ".join(change(values))
    return edit


def _shift(lines):
    _row(200, lambda v: v[:-3])(lines)
    _row(201, lambda v: v + ["1", "2", "3"])(lines)


@pytest.mark.parametrize("edit, message", [
    (_set_frames(100), "header announces 100 frames (line 186), the file holds 359 frame rows"),
    (_set_frames(400), "header announces 400 frames (line 186), the file holds 359 frame rows"),
    (_row(200, lambda v: v[:4] + ["nan"] + v[5:]), "line 200 (frame 13): 'nan' is not a finite number"),
    (_shift, "line 200 (frame 13) holds 93 values, the HIERARCHY declares 96 channels"),
    (_row(200, lambda v: v[:4] + ["abc"] + v[5:]), "line 200 (frame 13): 'abc' is not a number"),
    (lambda lines: lines.__setitem__(8, lines[8].replace("Zrotation", "Wrotation")),
     "line 9, joint 'LHipJoint' has unknown channel 'Wrotation'"),
])
def test_bvh_frames_are_checked_line_by_line(tmp_path, edit, message):
    from stimuli.motion.bvh import read_bvh

    with pytest.raises(StimuliError) as err:
        read_bvh(_bvh_variant(tmp_path, edit))
    assert message in str(err.value)


# -- 5. render options --------------------------------------------------------------------------

@pytest.mark.parametrize("args, message", [
    (["render", "--out", "nodir", "--verify"], "nodir/manifest.csv: not found"),
    (["render", "--out", "dd_empty", "--verify"], "dd_empty/manifest.csv: not found"),
    (["render", EXP1, "--out", "r", "--limit", "0"], "--limit: expected a whole number >= 1, got 0"),
    (["render", EXP1, "--out", "r", "--fps", "0"], "--fps: expected a whole number of frames per second from 5 to 240 (the bounds of a protocol's clip.fps), got 0"),
    (["render", EXP1, "--out", "r", "--workers", "0"], "--workers: expected a whole number >= 1"),
    (["render", EXP1, "--out", "r", "--motions", "nodir"], "has no METHOD factor"),
    (["render", EXP2, "--out", "r", "--motions", "nodir"], "--motions nodir: folder not found"),
    (["render", EXP1, "--out", "r", "--video-base-url", "notaurl"], "--video-base-url 'notaurl'"),
    (["physics", "protocol", EXP2, "--out", "pp", "--workers", "0"], "--workers: expected a whole number >= 1"),
    (["physics", "protocol", EXP2, "--out", "pp", "--motions", "nodir"], "--motions nodir: folder not found"),
])
def test_render_and_physics_options(work, run_cli, args, message):
    assert message in _fails(run_cli, *args)
    assert _tree(work) == {"afile", "dd_empty"}


def test_verify_of_a_manifest_without_clips(work, run_cli):
    (work / "dd_empty" / "manifest.csv").write_text("")
    assert "lists no clips" in _fails(run_cli, "render", "--out", "dd_empty", "--verify")


def test_no_clip_kept_means_no_manifest(tmp_path):
    from stimuli.render.pipeline import _update_manifest

    (tmp_path / "manifest.csv").write_text("stimulus_id\nold\n")
    assert _update_manifest(tmp_path, []) is None and not (tmp_path / "manifest.csv").exists()
    assert _update_manifest(tmp_path, [{"stimulus_id": "a"}]).read_text() == "stimulus_id\na\n"


# -- 6. protocol validation ---------------------------------------------------------------------

def _protocol_variant(tmp_path: Path, source: Path, old: str, new: str) -> Path:
    text = source.read_text()
    assert old in text
    path = tmp_path / source.name
    path.write_text(text.replace(old, new, 1))
    return path


@pytest.mark.parametrize("source, old, new, message", [
    (EXP1, "participants: 16", "participants: 16\nparticipants: 12",
     "key 'participants' appears twice in one mapping (first on line"),
    (POINTLIGHT, '{view_deg: 45, modifies: "hip_twist+torso_twist"}', '{view_dg: 45, modifies: "hip_twist+torso_twist"}',
     "factors.0.level_settings.hip_torso_twist.view_dg (line 27): unknown setting"),
    (POINTLIGHT, '{view_deg: 90, modifies: "arm_swing"}', '{view_deg: 720, modifies: "arm_swing"}',
     "factors.0.level_settings.arm_swing.view_deg (line 32): expected a view angle"),
    (POINTLIGHT, 'modifies: "hip_twist+torso_twist"}', 'modifies: "hip_twist+torso_twsit"}',
     "unknown Table 4-1/5-2 row(s) ['torso_twsit']"),
    (POINTLIGHT, '"0.5", "12"', '"zero", "12"', "level 'zero' must be a body-fat %"),
    (POINTLIGHT, "layout: point_light", "layout: point_light\n  floor: false", "display.floor (line 44): point-light walkers are drawn"),
    (VALIDATION, "floor: false ", 'floor: "no" ', "display.floor"),
    (EXP1, "layout: treadmill ", "label_position: below\n  layout: treadmill ", "display.label_position (line 54): no labels to draw"),
    (POINTLIGHT, 'label_colour: "#ff0000"', "label_colour: red", "label_colour"),
    (VALIDATION, "motion: lean_walk", "motion: lean_wlak", "factors.0.level_settings.lean_mocap.motion (line 29): expected one of"),
    (VALIDATION, "motion: lean_walk", 'motion: "bvh:nothere.bvh"', "nothere.bvh not found"),
    (EXP1, 'background: "#ffffff"', 'background: "notacolour"', "clip.background (line"),
    # the renderer draws SPEC's 15 markers; 12 used to pass validation and be ignored
    (POINTLIGHT, "point_light_markers: 15", "point_light_markers: 12", "point_light_markers must be 15"),
    (POINTLIGHT, "point_light_markers: 15", "point_light_markers: 15.0", "display.point_light_markers (line 45)"),
    (EXP1, "layout: treadmill", "layout: treadmill\n  point_light_markers: 15",
     "point_light_markers is only used with layout point_light, not treadmill"),
])
def test_validate_catches_protocol_mistakes(work, run_cli, source, old, new, message):
    path = _protocol_variant(work, source, old, new).relative_to(work)
    err = _fails(run_cli, "validate", path)
    assert err.startswith(f"shapemotion: error: {path}: ") and message in err


def test_validate_a_folder(tmp_path, run_cli):
    assert "is a folder; expected a protocol YAML file" in _fails(run_cli, "validate", tmp_path)


def test_bundled_protocols_still_validate(run_cli):
    for path in sorted((ROOT / "protocols").glob("*.yaml")):
        assert run_cli("validate", path)[0] == 0, path


# -- 7. motion options --------------------------------------------------------------------------

@pytest.mark.parametrize("args, message", [
    (["motion", "generate", "--bmi", "500", "--out", "g.npz"], "--bmi: 500 is outside the human range"),
    (["motion", "generate", "--cadence", "0", "--out", "g.npz"], "--cadence: 0 is outside the human range 40–260"),
    (["motion", "generate", "--protocol", EXP1, "--actor", "F_Hi1", "--height", "1.9", "--out", "g.npz"],
     "--height: the body comes from --actor F_Hi1"),
    (["motion", "generate", "--protocol", EXP1, "--out", "g.npz"], "also give --actor"),
    (["motion", "import", WALK_BVH, "--fps", "0", "--out", "i.npz"], "--fps: expected a frame rate > 0"),
    (["motion", "import", WALK_BVH, "--height", "0", "--out", "i.npz"], "--height: 0 is outside the human range"),
    (["motion", "import", WALK_BVH, "--height", "-1", "--out", "i.npz"], "--height: -1 is outside"),
    (["motion", "import", WALK_BVH, "--cycles", "2", "--out", "i.npz"], "--cycles: only used with --loop"),
    (["motion", "import", WALK_BVH, "--out", "i.bvh"], "--out i.bvh: a motion is written as .npz"),
    (["motion", "export-bvh", "{walk}", "--scale", "0", "--out", "e.bvh"], "--scale: expected a length multiplier > 0"),
    (["motion", "export-bvh", "{walk}", "--scale", "-100", "--out", "e.bvh"], "--scale"),
    (["motion", "average", "{walk}", "{walk}", "--cycles", "0", "--out", "a.npz"], "--cycles: expected a whole number"),
    (["motion", "average", "{walk}", "{jog}", "--out", "a.npz"], "different gaits"),
    (["motion", "modify", "{walk}", "--height", "1.8", "--body-fat", "20", "--chest", "-1", "--out", "m.npz"], "--chest"),
    (["motion", "modify", "{walk}", "--height", "1.8", "--body-fat", "20", "--wthr", "0", "--out", "m.npz"], "--wthr"),
    (["motion", "modify", "{walk}", "--height", "1.8", "--body-fat", "20", "--base-scale", "-10", "--out", "m.npz"],
     "--base-scale"),
    (["motion", "modify", "{walk}", "--height", "18", "--body-fat", "20", "--out", "m.npz"], "--height: 18 is outside"),
    (["motion", "modify", "{walk}", "--height", "1.8", "--body-fat", "90", "--out", "m.npz"], "--body-fat: 90 is outside"),
    (["motion", "retarget", "{walk}", "--body", "sex=M,height=1.8,bmi=25,bmi=30", "--out", "r.npz"], "bmi is given twice"),
    (["motion", "retarget", "{walk}", "--body", "sex=M;height=1.8;bmi=25", "--out", "r.npz"], "comma-separated key=value"),
    (["motion", "retarget", "{walk}", "--body", "sex=M,height=1_8,bmi=25", "--out", "r.npz"], "height must be a number, got '1_8'"),
    (["motion", "strip", "--protocol", VALIDATION, "--out", "s"], "declares no gaits"),
    (["motion", "strip", "{walk}", "--protocol", EXP1, "--out", "s"], "not both"),
    (["motion", "strip", "{walk}", "--frames", "0", "--out", "s.png"], "--frames: expected a whole number >= 1"),
    (["motion", "strip", "{walk}", "--frames", "-3", "--out", "s.png"], "--frames"),
    (["motion", "strip", "{walk}", "--out", "s.csv"], "a strip is an image"),
    (["motion", "markers", "{walk}", "--out", "m.txt"], "the markers are written as a .csv file"),
])
def test_motion_options(work, run_cli, walk, args, message):
    from stimuli.cli import main

    subs = {"{walk}": str(walk)}
    if "{jog}" in args:
        assert main(["motion", "generate", "--gait", "jog", "--cycles", "1", "--out", str(work / "j.npz")]) == 0
        subs["{jog}"] = str(work / "j.npz")
    before = _tree(work)
    assert message in _fails(run_cli, *[subs.get(str(a), a) for a in args])
    assert _tree(work) == before


def test_markers_refuse_and_metrics_retarget_a_body_the_motion_is_not_on(work, run_cli, walk):
    """Every Anny rig has the same joint names: a motion on a man of 1.80 m measured on a woman of 1.50 m
    used to pass (Float 18 cm instead of 0.3). The markers refuse it; the metrics measure it retargeted
    onto that body and say so."""
    from stimuli.cli import main

    assert main(["motion", "retarget", str(walk), "--body", BODY, "--out", str(work / "r.npz")]) == 0
    err = _fails(run_cli, "motion", "markers", work / "r.npz", "--body", "sex=F,height=1.50,bmi=40", "--out", "m.csv")
    assert "must be on its rig (it is on body M_h180_b25.0)" in " ".join(err.split()), err
    code, out, err = run_cli("motion", "metrics", work / "r.npz", "--body", "sex=F,height=1.50,bmi=40")
    assert code == 0 and "retargeted onto that body" in " ".join(err.split()) and "(it is on body M_h180_b25.0)" in err
    assert json.loads(out)["float_mm"] < 10.0, out
    assert run_cli("motion", "markers", work / "r.npz", "--body", BODY, "--out", work / "new" / "m.csv")[0] == 0
    assert (work / "new" / "m.csv").read_text().startswith("frame,time_s,marker,x,y,z")   # folder made, no traceback


def test_metrics_json_writes_null_for_nan(work, run_cli, walk, monkeypatch):
    import stimuli.motion.quality as quality

    monkeypatch.setattr(quality, "motion_quality", lambda m, body=None: {"float_cm": float("nan"), "n": 1})
    code, _, _ = run_cli("motion", "metrics", walk, "--json", "q.json")
    assert code == 0
    assert json.loads((work / "q.json").read_text(), parse_constant=lambda c: pytest.fail(c)) == {"float_cm": None,
                                                                                                     "n": 1}


# -- 8. bodies options --------------------------------------------------------------------------

@pytest.mark.parametrize("args, message", [
    (["--sex", "F", "--height", "1.6", "--bmi", "28", "--hip", "0.1", "--out", "b.ply"], "hip_m = 0.1 m is not a human girth"),
    (["--sex", "F", "--height", "1.6", "--bmi", "28", "--waist", "5", "--out", "b.ply"], "waist_m = 5.0 m"),
    (["--sex", "F", "--height", "1.6", "--bmi", "500", "--out", "b.ply"], "--bmi: 500 is outside the human range"),
    (["--sex", "F", "--height", "160", "--bmi", "28", "--out", "b.ply"], "--height: 160 is outside"),
    ([EXP1, "--out", "bx", "--json", "x.json", "--waist", "0.9"], "--waist, --json: only for a single body"),
    ([EXP1, "--out", "x.ply"], "give a folder name, not a mesh file"),
])
def test_bodies_options(work, run_cli, args, message):
    assert message in _fails(run_cli, "bodies", *args)
    assert _tree(work) == {"afile", "dd_empty"}


# -- 9. physics retarget options ----------------------------------------------------------------

@pytest.mark.parametrize("extra, message", [
    (["--height", "1.6", "--reference-weight", "0"], "--reference-weight: weight 0.0 kg is not physical"),
    (["--height", "160"], "--height: 160 is outside the human range 1.2–2.3 m (metres"),
])
def test_physics_retarget_options(work, run_cli, walk, extra, message):
    err = _fails(run_cli, "physics", "retarget", "--motion", walk, "--sex", "F", "--weight", "60", *extra,
                 "--out", "c.npz")
    assert message in err


# -- 10. preview and survey options -------------------------------------------------------------

@pytest.mark.parametrize("extra, message", [
    (["--duration", "0"], "--duration: expected a duration > 0"),
    (["--duration", "-1"], "--duration"),
    (["--camera", "0,0,4,0"], "field of view 0° must lie between 5 and 150"),
    (["--camera", "0,0,-4,40"], "distance -4 m"),
    (["--speed", "-2"], "--speed: expected a belt speed >= 0"),
    (["--body", "sex=M,height=1.8,bmi=25,bmi=30"], "bmi is given twice"),
])
def test_preview_options(work, run_cli, extra, message):
    args = ["preview", "--gait", "walk", "--body", BODY, "--out", "p.mp4", *extra]
    assert message in _fails(run_cli, *args)
    assert _tree(work) == {"afile", "dd_empty"}


@pytest.mark.parametrize("extra, message", [
    (["--format", "qsf", "--out", "s.qsf", "--post-url", "http://x.org/save"], "--post-url: only the jspsych format"),
    (["--format", "qsf", "--out", "s.qsf", "--video-base-url", "notaurl"], "expected an absolute address with a host"),
    (["--format", "jspsych", "--out", "js", "--video-base-url", "not a url"], "without spaces"),
    (["--format", "psychopy", "--out", "pp", "--video-base-url", "https://x.org"], "does not use a URL"),
])
def test_survey_options(work, run_cli, design_dir, extra, message):
    assert message in _fails(run_cli, "survey", design_dir, *extra)
    assert _tree(work) == {"afile", "dd_empty"}


def test_check_output_helpers(tmp_path):
    from stimuli.fileio import check_output_dir, check_output_file

    (tmp_path / "f").write_text("")
    assert check_output_file(tmp_path / "new" / "x.csv") == tmp_path / "new" / "x.csv"
    assert check_output_dir(tmp_path / "new") == tmp_path / "new"
    assert check_output_file(None) is None
    with pytest.raises(StimuliError, match="--json .*is a folder"):
        check_output_file(tmp_path, "--json")
    with pytest.raises(StimuliError, match="is a file, not a folder"):
        check_output_dir(tmp_path / "f" / "sub")
    if os.geteuid() != 0:  # root writes anywhere
        (tmp_path / "ro").mkdir(mode=0o500)
        with pytest.raises(StimuliError, match="not writable"):
            check_output_file(tmp_path / "ro" / "x.csv")
