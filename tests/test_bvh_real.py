"""BVH import on real captures (``../shared/data/mocap``, both folders) and on synthetic messy files.

Every capture imports: frame rate and frame count as the file declares them, the T-pose frames at
the start (and only those) dropped, the feet on the floor, all roles found. Then the messy cases one
at a time: a toe-less skeleton keeps its ankle motion, the metres file equals its CMU-unit sibling,
a synthetic file with CRLF, inches, Mixamo names, a 6-frame T-pose ease-in and a root OFFSET, a leg
scale that splayed rest legs do not change, and unmappable names refused with exit code 2.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from stimuli.errors import StimuliError
from stimuli.motion import quat
from stimuli.motion.bvh import arm_abduction, read_bvh, write_bvh
from stimuli.motion.skeleton import ROLES, leg_length, role_indices

ROOT = Path(__file__).resolve().parents[1]
MOCAP = ROOT.parent / "shared" / "data" / "mocap"
WALK = ROOT / "stimuli" / "data" / "cmu_35_01_walk.bvh"
# file → (frame rate, frames the file declares, leading T-pose frames, naming); from more/SOURCES.md.
CAPTURES = {
    "cmu_35_01_walk.bvh": (120, 359, 1, "cmu"),
    "cmu_35_17_run.bvh": (120, 168, 1, "cmu"),
    "more/cmu_02_01_walk_mb2names_120fps.bvh": (120, 344, 1, "cmu"),
    "more/cmu_131_02_start_walk_stop_maxnames_120fps.bvh": (120, 1247, 0, "cmu-3dsmax"),
    "more/cmu_131_02_start_walk_stop_maxnames_120fps_meters.bvh": (120, 1248, 0, "cmu-3dsmax"),
    "more/cmu_07_01_walk_cc4rig_60fps.bvh": (60, 157, 0, "cc4"),
    "more/cmu_07_02_walk_cc4rig_60fps_NOTOES_derived.bvh": (60, 164, 0, "cc4"),
    "more/cmu_06_10_walk_stop_turn_dribble_cc4rig_60fps.bvh": (60, 557, 0, "cc4"),
    "more/bandai1_walk_normal_001_30fps.bvh": (30, 195, 0, "bandai"),
    "more/bandai1_dash_active_001_run_30fps.bvh": (30, 85, 0, "bandai"),
    # kept aside while the importer was written, checked last (UNSEEN)
    "more/cmu_07_12_brisk_walk_cc4rig_60fps_tpose_frame0.bvh": (60, 132, 1, "cc4"),
    "more/bandai1_run_tired_001_jog_30fps.bvh": (30, 133, 0, "bandai"),
}


def capture(name: str) -> Path:
    path = MOCAP / name
    if not path.is_file():
        pytest.skip(f"{path} absent: the captures live in shared/data/mocap beside the clone")
    return path


def lowest_foot_point(motion) -> np.ndarray:
    """Per frame, the lowest joint of either foot (ankle and everything below it, End Sites included)."""
    roles = role_indices(motion)
    feet = {roles["l_ankle"], roles["r_ankle"]}
    for k in range(motion.n_joints):
        if motion.parents[k] in feet:
            feet.add(k)
    return motion.positions()[:, sorted(feet), 1].min(axis=1)


@pytest.mark.parametrize("name", list(CAPTURES))
def test_every_capture_imports(name):
    fps, frames, lead, naming = CAPTURES[name]
    m = read_bvh(capture(name))
    assert m.fps == fps and m.metadata["naming"] == naming
    # the declared frames, less exactly the T-pose ones: no real motion dropped
    assert m.metadata["dropped_lead_frames"] == lead
    assert m.n_frames == frames - lead
    assert m.duration_s == pytest.approx((frames - lead) / fps)
    assert set(m.metadata["roles"]) == set(ROLES)
    # no T-pose left: the first frame's arms are within the capture's own range
    a = arm_abduction(m)
    assert a[0] <= a[m.n_frames // 4:].max()
    # metres, feet on the floor (a CC4 root OFFSET not added left them ~1 m below), a human pelvis
    low = lowest_foot_point(m)
    assert -0.1 < np.percentile(low, 1) < 0.15
    assert 0.75 < m.positions()[:, role_indices(m)["pelvis"], 1].mean() < 1.2
    assert 1.4 < m.metadata["source_height_m"] < 2.1


def test_toe_less_skeleton_keeps_its_ankle():
    """Without toe joints the ankle's End Site is the toe: the foot bone moves as in the toed sibling."""
    toeless = read_bvh(capture("more/cmu_07_02_walk_cc4rig_60fps_NOTOES_derived.bvh"))
    toed = read_bvh(capture("more/cmu_07_01_walk_cc4rig_60fps.bvh"))
    assert toeless.metadata["roles"]["l_toe"] == "CC_Base_L_Foot_end"
    ranges = [np.ptp(ankle_angles(m), axis=1) for m in (toeless, toed)]
    assert (ranges[0] > 20.0).all()
    assert np.allclose(ranges[0], ranges[1], rtol=0.25)


def ankle_angles(motion) -> np.ndarray:
    """Shank–foot angle per side and frame, degrees (2×T)."""
    p, r = motion.positions(), role_indices(motion)
    out = []
    for s in "lr":
        shank = p[:, r[f"{s}_ankle"]] - p[:, r[f"{s}_knee"]]
        foot = p[:, r[f"{s}_toe"]] - p[:, r[f"{s}_ankle"]]
        cos = np.sum(shank * foot, axis=1) / np.linalg.norm(shank, axis=1) / np.linalg.norm(foot, axis=1)
        out.append(np.degrees(np.arccos(np.clip(cos, -1, 1))))
    return np.array(out)


def test_metres_file_equals_its_cmu_unit_sibling():
    cmu = read_bvh(capture("more/cmu_131_02_start_walk_stop_maxnames_120fps.bvh"))
    metres = read_bvh(capture("more/cmu_131_02_start_walk_stop_maxnames_120fps_meters.bvh"))
    assert (cmu.metadata["unit"], metres.metadata["unit"]) == ("cmu", "m")
    # the metres file repeats the last frame once
    n = cmu.n_frames
    assert np.abs(cmu.positions() - metres.positions()[:n]).max() < 1e-3


def messy_copy(path: Path, tmp_path: Path, lead: int = 6) -> tuple[Path, object]:
    """The bundled walk rewritten as a messy exporter would: Mixamo names, inches, a T-pose and a
    blend out of it over ``lead`` frames before the walk, the hip height in the root OFFSET, CRLF."""
    walk = read_bvh(path)
    rest = np.tile(quat.IDENTITY, (walk.n_joints, 1))
    w = np.arange(lead)[:, None, None] / lead
    blend = quat.slerp(np.broadcast_to(rest, (lead, walk.n_joints, 4)),
                       np.broadcast_to(walk.rotations[0], (lead, walk.n_joints, 4)),
                       np.broadcast_to(w, (lead, walk.n_joints, 1))[..., 0])
    messy = walk.replace(joint_names=[f"mixamorig:{n}" for n in walk.joint_names],
                         rotations=np.concatenate([blend, walk.rotations]),
                         root_translation=np.concatenate([np.repeat(walk.root_translation[:1], lead, 0),
                                                          walk.root_translation]))
    inches = 1 / 0.0254
    write_bvh(messy, tmp_path / "lf.bvh", scale=inches)
    lines = (tmp_path / "lf.bvh").read_text().splitlines()
    hip = float(np.mean(walk.root_translation[:, 1])) * inches
    root_offset = next(i for i, line in enumerate(lines) if line.strip().startswith("OFFSET"))
    lines[root_offset] = f"\tOFFSET 0.000000 {hip:.6f} 0.000000"
    first = lines.index("MOTION") + 3
    for i in range(first, len(lines)):
        values = lines[i].split()
        values[1] = f"{float(values[1]) - hip:.6f}"
        lines[i] = " ".join(values)
    out = tmp_path / "messy.bvh"
    out.write_bytes(("\r\n".join(lines) + "\r\n").encode())
    return out, walk


def test_messy_synthetic_file_imports_like_the_clean_one(tmp_path):
    path, walk = messy_copy(WALK, tmp_path)
    m = read_bvh(path)
    assert m.metadata["naming"] == "mixamo" and m.metadata["unit"] == "in"
    assert m.metadata["dropped_lead_frames"] == 6 and m.metadata["root_offset_added"]
    assert any("OFFSET" in note for note in m.metadata["import_notes"])
    assert m.n_frames == walk.n_frames
    assert np.abs(m.positions() - walk.positions()).max() < 1e-3


def renamed(sides: dict[str, str], centre: dict[str, str]) -> dict[str, str]:
    """CMU joint name → another rig's, ``{S}``/``{s}`` standing for the side (L/R, l/r)."""
    out = dict(centre)
    for cmu, other in sides.items():
        for side, letter in (("Left", "L"), ("Right", "R")):
            out[f"{side}{cmu}"] = other.format(S=letter, s=letter.lower())
    return out


LIMBS = ("UpLeg", "Leg", "Foot", "ToeBase", "Shoulder", "Arm", "ForeArm", "Hand")
RIGS = {
    "biped": renamed(dict(zip(LIMBS, ("Bip01 {S} Thigh", "Bip01 {S} Calf", "Bip01 {S} Foot", "Bip01 {S} Toe0",
                                      "Bip01 {S} Clavicle", "Bip01 {S} UpperArm", "Bip01 {S} Forearm",
                                      "Bip01 {S} Hand"))),
                     {"Hips": "Bip01 Pelvis", "LowerBack": "Bip01 Spine", "Neck1": "Bip01 Neck", "Head": "Bip01 Head"}),
    "daz": renamed(dict(zip(LIMBS, ("{s}Thigh", "{s}Shin", "{s}Foot", "{s}Toe", "{s}Collar", "{s}Shldr", "{s}ForeArm",
                                    "{s}Hand"))),
                   {"Hips": "hip", "LowerBack": "abdomen", "Spine1": "chest", "Neck1": "neck", "Head": "head"}),
    "pattern": renamed(dict(zip(LIMBS, ("thigh_{s}", "shin_{s}", "foot_{s}", "toes_{s}", "clavicle_{s}", "upperarm_{s}",
                                        "forearm_{s}", "hand_{s}"))), {"Hips": "pelvis", "Head": "head"}),
}


@pytest.mark.parametrize("rig", list(RIGS))
def test_other_namings_import_the_same_walk(tmp_path, rig):
    """3ds Max Biped (names with spaces), DAZ and a Blender-like rig: the same roles, the same motion."""
    text = WALK.read_text()
    for cmu, other in RIGS[rig].items():
        text = re.sub(rf"^(\s*(?:ROOT|JOINT)) {cmu}\s*$", rf"\1 {other}", text, flags=re.M)
    (tmp_path / "rig.bvh").write_text(text)
    walk, m = read_bvh(WALK), read_bvh(tmp_path / "rig.bvh")
    assert m.metadata["naming"] == rig
    assert all(RIGS[rig].get(walk.metadata["roles"][role], walk.metadata["roles"][role]) == joint
               for role, joint in m.metadata["roles"].items() if role not in ("spine", "chest"))
    assert np.abs(m.positions() - walk.positions()).max() < 1e-9


def test_frame_rates_read_from_frame_time(tmp_path):
    for fps in (30, 60, 120):
        walk = read_bvh(WALK).resample(fps)
        write_bvh(walk, tmp_path / f"w{fps}.bvh")
        back = read_bvh(tmp_path / f"w{fps}.bvh")
        assert back.fps == fps and back.n_frames == walk.n_frames


def splayed(motion, degrees: float = 30.0):
    """The same world motion on a rig whose rest thighs point ``degrees`` outwards."""
    r = role_indices(motion)
    offsets, rot = motion.offsets.copy(), motion.rotations.copy()
    for s, sign in (("l", 1.0), ("r", -1.0)):
        hip, knee = r[f"{s}_hip"], r[f"{s}_knee"]
        turn = quat.from_axis_angle(np.array([0.0, 0.0, sign * np.radians(degrees)]))
        offsets[knee] = quat.rotate(turn, offsets[knee])
        rot[:, hip] = quat.mul(rot[:, hip], quat.inv(turn))
        rot[:, knee] = quat.mul(turn, rot[:, knee])
    return motion.replace(offsets=offsets, rotations=rot)


def test_leg_length_ignores_splayed_rest_legs():
    walk = read_bvh(WALK)
    wide = splayed(walk)
    assert np.abs(wide.positions() - walk.positions()).max() < 1e-9
    r = role_indices(walk)
    rest_hip = [m.rest_positions()[r["l_hip"], 1] - m.rest_positions()[:, 1].min() for m in (walk, wide)]
    assert rest_hip[1] < 0.96 * rest_hip[0]  # the rest hip height the leg scale came from
    assert leg_length(wide) == pytest.approx(leg_length(walk), abs=1e-3)


@pytest.mark.slow  # fits an Anny body (seconds with a cold cache)
def test_retarget_scales_splayed_legs_like_straight_ones():
    from stimuli.bodies import fit_body
    from stimuli.motion.retarget import retarget

    body = fit_body("M", 1.80, 27.0)
    walk = read_bvh(WALK)
    straight, wide = (retarget(m, body, cleanup=False) for m in (walk, splayed(walk)))
    assert wide.metadata["leg_scale"] == pytest.approx(straight.metadata["leg_scale"], rel=1e-3)
    toeless = retarget(read_bvh(capture("more/cmu_07_02_walk_cc4rig_60fps_NOTOES_derived.bvh")), body,
                       cleanup=False)
    assert (np.ptp(ankle_angles(toeless), axis=1) > 20.0).all()


def test_unmappable_names_exit_2_naming_file_and_roles(tmp_path, run_cli):
    text = WALK.read_text()
    for old, new in (("UpLeg", "Segment1"), ("Leg", "Segment2"), ("Foot", "Segment3")):
        text = text.replace(f"Left{old}", f"L_{new}").replace(f"Right{old}", f"R_{new}")
    bad = tmp_path / "odd_names.bvh"
    bad.write_text(text)
    out = tmp_path / "o.npz"
    code, _, err = run_cli("motion", "import", bad, "--out", out)
    assert code == 2 and not out.exists()
    assert "odd_names.bvh" in err and "l_ankle" in err and "L_Segment3" in err
    with pytest.raises(StimuliError, match="mapping file"):
        read_bvh(bad)


def test_cli_says_what_it_dropped(tmp_path, run_cli):
    path, _ = messy_copy(WALK, tmp_path)
    code, _, err = run_cli("motion", "import", path, "--out", tmp_path / "m.npz")
    assert code == 0
    assert "dropped the first 6 frame(s)" in err and "OFFSET added" in err
