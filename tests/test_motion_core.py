"""Motion object, quaternions, BVH/AMASS import-export, namings, loops (stimuli.motion)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from stimuli.bodies.rig import quaternions_to_matrices
from stimuli.errors import StimuliError
from stimuli.motion import Motion, quat
from stimuli.motion.amass import SMPL_JOINTS, read_amass, write_amass
from stimuli.motion.bvh import read_bvh, write_bvh
from stimuli.motion.events import gait_events
from stimuli.motion.loop import make_loop, seam_error, to_treadmill, trim_cycles
from stimuli.motion.skeleton import detect_roles, load_mapping

DATA = Path(__file__).resolve().parents[1] / "stimuli" / "data"
WALK = DATA / "cmu_35_01_walk.bvh"
RUN = DATA / "cmu_35_17_run.bvh"


def chain_motion(t: int = 5) -> Motion:
    rng = np.random.default_rng(0)
    rot = quat.from_axis_angle(rng.normal(0, 0.5, (t, 3, 3)))
    return Motion(fps=30.0, joint_names=["a", "b", "c"], parents=[-1, 0, 1],
                  offsets=[[0, 0, 0], [0, 1, 0], [0.5, 0, 0]], rotations=rot,
                  root_translation=rng.normal(0, 1, (t, 3)), metadata={"source": "test"})


# ---------------------------------------------------------------- quaternions
@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-3, 3), min_size=6, max_size=6))
def test_quat_mul_matches_scipy(v):
    a, b = np.array(v[:3]), np.array(v[3:])
    got = quat.mul(quat.from_axis_angle(a), quat.from_axis_angle(b))
    ref = Rotation.from_rotvec(a) * Rotation.from_rotvec(b)
    assert np.allclose(quaternions_to_matrices(got), ref.as_matrix(), atol=1e-9)
    x = np.array([0.3, -1.0, 2.0])
    assert np.allclose(quat.rotate(got, x), ref.apply(x), atol=1e-9)


def _unroll_frame_by_frame(q: np.ndarray) -> np.ndarray:
    """The definition: each frame flipped when its dot product with the previous, as flipped, is negative."""
    q = np.array(q, float)
    for t in range(1, len(q)):
        flip = np.sum(q[t] * q[t - 1], axis=-1) < 0
        q[t][flip] *= -1
    return q


def test_quat_unroll_is_the_frame_by_frame_definition_to_the_bit():
    """Vectorised, with runs of flips, zero and NaN dot products (a frame after one keeps its sign)."""
    rng = np.random.default_rng(7)
    for trial in range(30):
        q = rng.standard_normal((60, 5, 4))
        q[10] = 0.0
        q[20, 2] = np.nan
        q[30:33] *= -1
        got, want = quat.unroll(q), _unroll_frame_by_frame(q)
        assert np.array_equal(got, want, equal_nan=True) and np.array_equal(np.signbit(got), np.signbit(want))
    assert np.array_equal(quat.unroll(q.swapaxes(0, 1), axis=1), want.swapaxes(0, 1), equal_nan=True)
    assert quat.unroll(np.zeros((0, 4))).shape == (0, 4)


def test_forward_kinematics_by_depth_equals_joint_by_joint_to_the_bit():
    motion = read_bvh(WALK)
    grot, gpos = motion.global_transforms()
    want_rot, want_pos = np.empty_like(grot), np.empty_like(gpos)
    want_rot[:, 0], want_pos[:, 0] = motion.rotations[:, 0], motion.root_translation
    for k in range(1, motion.n_joints):
        p = motion.parents[k]
        want_rot[:, k] = quat.mul(want_rot[:, p], motion.rotations[:, k])
        want_pos[:, k] = want_pos[:, p] + quat.rotate(want_rot[:, p], motion.offsets[k])
    assert np.array_equal(grot, want_rot) and np.array_equal(gpos, want_pos)


def test_quat_product_and_rotation_broadcast_over_leading_axes():
    rng = np.random.default_rng(8)
    a, b, v = rng.standard_normal((3, 1, 4)), rng.standard_normal((1, 5, 4)), rng.standard_normal((5, 3))
    assert quat.mul(a, b).shape == (3, 5, 4) and quat.rotate(a, v).shape == (3, 5, 3)
    assert np.allclose(quat.mul(a, b)[2, 4], quat.mul(a[2, 0], b[0, 4]))
    assert np.allclose(quat.rotate(a, v)[1, 2], quat.rotate(a[1, 0], v[2]))


def test_quat_mean_is_sign_invariant_and_exact_for_identical():
    q = quat.from_axis_angle(np.array([0.2, 0.4, -0.1]))
    samples = np.stack([q, -q, q])
    assert np.allclose(np.abs(np.sum(quat.mean(samples) * q)), 1.0)
    # Mean of ±10° about one axis is the identity.
    pm = quat.from_axis_angle(np.array([[0, 0, 0.17], [0, 0, -0.17]]))
    assert quat.angle(quat.mean(pm)) < 1e-9


def test_from_euler_is_intrinsic_bvh_order():
    # BVH "Zrotation Xrotation" = Rz · Rx, intrinsic.
    q = quat.from_euler(np.array([30.0, 0.0, 45.0]), "ZYX")
    ref = Rotation.from_euler("z", 30, degrees=True) * Rotation.from_euler("x", 45, degrees=True)
    assert np.allclose(quaternions_to_matrices(q), ref.as_matrix())


# ---------------------------------------------------------------- Motion + npz
def test_forward_kinematics_of_a_chain():
    m = chain_motion(1)
    m.rotations[:] = quat.IDENTITY
    m.rotations[0, 0] = quat.from_axis_angle(np.array([0, 0, np.pi / 2]))  # root turns 90° about z
    p = m.positions()[0]
    assert np.allclose(p[1] - p[0], [-1, 0, 0])
    assert np.allclose(p[2] - p[1], [0, 0.5, 0])


def test_npz_round_trip(tmp_path):
    m = chain_motion()
    m.metadata.update(gait="walk", cadence_spm=np.float64(112.0))
    path = m.save(tmp_path / "m.npz")
    back = Motion.load(path)
    assert back.joint_names == m.joint_names and back.fps == m.fps
    assert np.allclose(back.rotations, m.rotations) and np.allclose(back.root_translation, m.root_translation)
    assert back.metadata["cadence_spm"] == 112.0
    data = np.load(path)
    assert set(data.files) == {"fps", "joint_names", "parents", "offsets", "rotations", "root_translation", "metadata"}
    assert json.loads(str(data["metadata"]))["gait"] == "walk"


def test_npz_errors_name_the_field(tmp_path):
    np.savez(tmp_path / "bad.npz", fps=30.0, joint_names=np.array(["a"]))
    with pytest.raises(StimuliError, match="missing field.*parents"):
        Motion.load(tmp_path / "bad.npz")
    m = chain_motion()
    m.root_translation[2, 1] = np.nan
    with pytest.raises(StimuliError, match="root_translation contains NaN"):
        m.validate()


def test_resample_keeps_the_path():
    m = chain_motion(31)
    up = m.resample(120.0)
    assert up.n_frames == 121
    assert np.allclose(up.positions()[::4], m.positions(), atol=1e-9)


# ---------------------------------------------------------------- namings and mappings
CMU_LIKE = ["Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "RightUpLeg", "RightLeg", "RightFoot",
            "Spine", "Spine1", "Neck", "Head", "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand"]


@pytest.mark.parametrize("names,naming,role,joint", [
    (CMU_LIKE, "cmu", "l_knee", "LeftLeg"),
    (["mixamorig:" + n for n in CMU_LIKE], "mixamo", "l_elbow", "mixamorig:LeftForeArm"),
    (["Hips", "LeftHip", "LeftKnee", "LeftAnkle", "RightHip", "RightKnee", "RightAnkle", "Chest", "Abdomen",
      "Neck", "Head", "LeftCollar", "LeftShoulder", "LeftElbow", "LeftWrist"], "poser", "l_shoulder", "LeftShoulder"),
    (["hip", "abdomen", "chest", "neck", "head", "lThigh", "lShin", "lFoot", "rThigh", "rShin", "rFoot",
      "lCollar", "lShldr", "lForeArm", "lHand"], "daz", "l_elbow", "lForeArm"),
])
def test_naming_detection(names, naming, role, joint):
    found = detect_roles(names)
    assert found["naming"] == naming and found["roles"][role] == joint


def test_detected_roles_are_remembered_but_each_caller_gets_its_own_copy():
    first = detect_roles(CMU_LIKE)
    first["roles"]["l_knee"] = "changed by a caller"
    assert detect_roles(CMU_LIKE)["roles"]["l_knee"] == "LeftLeg"
    with pytest.raises(StimuliError, match="track.bvh"):      # the message names the file asked about
        detect_roles(["root", "thigh_l"], where="track.bvh")


def test_unknown_naming_asks_for_a_mapping(tmp_path):
    names = ["root", "thigh_l", "shin_l", "foot_l", "thigh_r", "shin_r", "foot_r"]
    with pytest.raises(StimuliError, match="mapping file"):
        detect_roles(names)
    mapping = tmp_path / "map.yaml"
    mapping.write_text("pelvis: root\nl_hip: thigh_l\nl_knee: shin_l\nl_ankle: foot_l\n"
                       "r_hip: thigh_r\nr_knee: shin_r\nr_ankle: foot_r\n")
    assert load_mapping(mapping, names)["roles"]["l_knee"] == "shin_l"
    mapping.write_text("pelvis: root\nl_knee: nope\n")
    with pytest.raises(StimuliError, match="'nope'"):
        load_mapping(mapping, names)


# ---------------------------------------------------------------- BVH
def test_cmu_bvh_imports_in_metres():
    m = read_bvh(WALK)
    assert m.metadata["naming"] == "cmu" and m.metadata["dropped_reference_frame"]
    assert m.fps == 120.0 and m.n_frames == 358
    p = m.positions()
    # Feet reach the ground, the pelvis is at a human hip height, the walk covers ~1.3 m/s.
    assert abs(p[..., 1].min()) < 0.03
    assert 0.85 < p[:, 0, 1].mean() < 1.1
    disp = np.linalg.norm((p[-1, 0] - p[0, 0])[[0, 2]]) / (m.n_frames / m.fps)
    assert 1.0 < disp < 1.6


def _rewrite_channels(src: Path, dst: Path, order: str, scale: float) -> None:
    """The same motion written with another rotation order and unit (via our exporter)."""
    write_bvh(read_bvh(src), dst, order=order, scale=scale)


@pytest.mark.parametrize("order,scale", [("XYZ", 100.0), ("YXZ", 1.0), ("ZXY", 1000.0)])
def test_bvh_round_trip_any_order_and_unit(tmp_path, order, scale):
    ref = read_bvh(WALK)
    _rewrite_channels(WALK, tmp_path / "x.bvh", order, scale)
    back = read_bvh(tmp_path / "x.bvh")
    assert back.joint_names == ref.joint_names
    assert np.allclose(back.positions(), ref.positions(), atol=2e-4)


def test_z_up_bvh_is_turned_y_up(tmp_path):
    ref = read_bvh(WALK)
    from stimuli.motion.bvh import _conjugate
    z_up = _conjugate(ref, quat.from_axis_angle(np.array([np.pi / 2, 0, 0])))  # y → z
    write_bvh(z_up, tmp_path / "z.bvh")
    back = read_bvh(tmp_path / "z.bvh")
    assert np.allclose(back.positions(), ref.positions(), atol=2e-4)


@pytest.mark.parametrize("text,msg", [
    ("HIERARCHY\nROOT Hips\n{\nOFFSET 0 0\n", "HIERARCHY section followed by MOTION"),
    ("HIERARCHY\nROOT Hips\n{\nOFFSET 0 0\nCHANNELS 1 Xposition\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n0\n", "line"),
    ("not a bvh at all", "not a readable BVH"),
])
def test_bad_bvh_is_a_user_error(tmp_path, text, msg):
    (tmp_path / "bad.bvh").write_text(text)
    with pytest.raises(StimuliError, match=msg):
        read_bvh(tmp_path / "bad.bvh")


def test_truncated_bvh_names_the_frames(tmp_path):
    lines = WALK.read_text().splitlines()
    (tmp_path / "cut.bvh").write_text("\n".join(lines[:200]) + "\n")
    with pytest.raises(StimuliError, match="359 frames"):
        read_bvh(tmp_path / "cut.bvh")


# ---------------------------------------------------------------- AMASS
def test_amass_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    t = 20
    poses = np.zeros((t, 156))
    poses[:, 3:66] = rng.normal(0, 0.2, (t, 63))
    poses[:, :3] = [np.pi / 2, 0, 0]  # AMASS: root turned so that the body stands in a z-up world
    trans = np.column_stack([np.linspace(0, 1, t), np.zeros(t), np.full(t, 0.95)])
    np.savez(tmp_path / "a.npz", poses=poses, trans=trans, mocap_framerate=60.0, betas=np.zeros(16),
             gender="female")
    m = read_amass(tmp_path / "a.npz")
    assert m.joint_names == SMPL_JOINTS and m.fps == 60.0 and m.metadata["gender"] == "female"
    p = m.positions()
    # y-up: the head is above the pelvis; the walk went along the AMASS x axis.
    assert (p[:, SMPL_JOINTS.index("head"), 1] > p[:, 0, 1] + 0.4).all()
    write_amass(m, tmp_path / "b.npz")
    back = read_amass(tmp_path / "b.npz")
    assert np.allclose(back.positions(), p, atol=1e-9)


def test_amass_errors(tmp_path):
    np.savez(tmp_path / "a.npz", poses=np.zeros((3, 30)), trans=np.zeros((3, 3)), mocap_framerate=30.0)
    with pytest.raises(StimuliError, match="at least 22 joints"):
        read_amass(tmp_path / "a.npz")
    np.savez(tmp_path / "b.npz", poses=np.zeros((3, 66)), trans=np.zeros((3, 3)))
    with pytest.raises(StimuliError, match="mocap_framerate"):
        read_amass(tmp_path / "b.npz")


# ---------------------------------------------------------------- cycles, treadmill, loops
def test_cmu_gait_events_and_trim():
    m = read_bvh(WALK)
    ev = gait_events(m)
    assert len(ev["l_hs"]) >= 2 and len(ev["r_hs"]) >= 2
    # Left and right heel strikes alternate.
    assert ev["l_hs"][0] < ev["r_hs"][1] < ev["l_hs"][1]
    one = trim_cycles(m, 1)
    assert one.n_frames == ev["l_hs"][1] - ev["l_hs"][0] + 1
    with pytest.raises(StimuliError, match="asked for 5"):
        trim_cycles(m, 5)


def test_short_clip_is_a_user_error():
    m = read_bvh(WALK).slice(0, 40)
    with pytest.raises(StimuliError, match="fewer than one whole gait cycle"):
        make_loop(m)


def test_treadmill_records_belt_speed_and_stays_in_place():
    m = to_treadmill(trim_cycles(read_bvh(WALK), 1))
    assert 1.1 < m.metadata["belt_speed_mps"] < 1.5
    root = m.root_translation
    assert np.ptp(root[:, 2]) < 0.1 and np.ptp(root[:, 0]) < 0.1


@pytest.mark.parametrize("path", [WALK, RUN])
def test_loops_are_seamless(path):
    loop = make_loop(read_bvh(path), cycles=2)
    err = seam_error(loop)
    assert loop.metadata["looped"] and loop.metadata["cycles"] == 2
    # The wrap-around is as smooth as the inside of the clip.
    assert err["ratio"] < 1.0
    assert err["seam_step_m"] <= err["interior_step_p99_m"]
    # Without the correction the seam of the same trimmed clip is worse.
    raw = to_treadmill(trim_cycles(read_bvh(path), 1)).slice(0, None)
    raw = raw.slice(0, raw.n_frames - 1)
    raw.metadata["looped"] = True
    assert seam_error(raw)["seam_accel_m"] > err["seam_accel_m"]


def test_smplx_layout_and_frame_rate_key(tmp_path):
    """SMPL-X files: 165 pose values (body first) and ``mocap_frame_rate``."""
    poses = np.zeros((4, 165))
    poses[:, :3] = [np.pi / 2, 0, 0]
    poses[:, 66:] = 9.0  # jaw, eyes, hands: ignored
    np.savez(tmp_path / "x.npz", poses=poses, trans=np.zeros((4, 3)), mocap_frame_rate=np.float64(120.0))
    m = read_amass(tmp_path / "x.npz")
    assert m.fps == 120.0 and m.n_joints == 22
    p = m.positions()[0]
    # Standing upright in y-up: head above pelvis above ankles.
    assert p[SMPL_JOINTS.index("head"), 1] > p[0, 1] > p[SMPL_JOINTS.index("left_ankle"), 1]


# ---------------------------------------------------------------- foot clean-up
def test_flat_feet_of_a_clip_that_does_not_loop_keep_their_own_heading():
    """Retargeting passes cyclic=False for motions that are not loops, and flatten_feet ignored it: a
    contact at the clip's end was joined to the one at its start, so a turning walker's first
    footprint turned towards the last one's heading (28° in its middle frame instead of 6°)."""
    from stimuli.motion.footfix import flatten_feet
    from stimuli.motion.generate import canonical_skeleton

    names, parents, offsets = canonical_skeleton(1.75)
    t = 40
    rot = np.tile([1.0, 0, 0, 0], (t, len(names), 1))
    yaw = np.radians(np.linspace(0.0, 90.0, t))  # the whole body turns a quarter circle
    rot[:, 0] = quat.from_axis_angle(yaw[:, None] * [0.0, 1.0, 0.0])
    m = Motion(30.0, names, parents, offsets, rot, np.zeros((t, 3)), {"source": "test"})
    contact = np.zeros(t, bool)
    contact[:6] = contact[-6:] = True
    ankle = names.index("l_ankle")

    def heading(cyclic, frame):
        out = flatten_feet(m, m.rotations, m.root_translation, {"l": contact, "r": contact}, cyclic)
        grot = m.global_transforms(out, m.root_translation)[0]
        fwd = quat.rotate(grot[frame, ankle], np.array([0.0, 0.0, 1.0]))
        return np.degrees(np.arctan2(fwd[0], fwd[2]))

    def mean_deg(frames):
        return np.degrees(np.arctan2(np.sin(yaw[frames]).mean(), np.cos(yaw[frames]).mean()))

    # Frames 2 and 36 are flat (mid-stance) in their own 6-frame contacts, frame 38 in the loop's 12-frame one.
    assert heading(False, 2) == pytest.approx(mean_deg(slice(0, 6)), abs=1e-6)
    assert heading(False, 36) == pytest.approx(mean_deg(slice(34, 40)), abs=1e-6)
    assert heading(True, 38) == pytest.approx(mean_deg(contact), abs=1e-6)  # a loop's contact goes on across the seam


def test_leg_ik_bends_a_straight_or_hyperextended_knee_forward():
    """The Bandai walk's knee is straight at heel strike (−0.1°, a hair past straight): the clean-up's
    leg IK bent it further about its own bend plane, backwards, to 23–36° of hyperextension, and the
    physics reference's knee flipped +18° → −31° → +16° in three frames (the walk flew 12.8 %). A knee
    that must bend more now bends forward, whichever side of straight it starts on; one that
    straightens keeps its side; a bent knee is bent as before."""
    from stimuli.motion.footfix import two_bone_ik
    from stimuli.motion.generate import canonical_skeleton
    from stimuli.motion.metrics import signed_knee_angles

    names, parents, offsets = canonical_skeleton(1.75)
    knee, ankle = names.index("l_knee"), names.index("l_ankle")
    # Knee rotation per frame; the rest pose has 2.5° of flexion, so −4° is 1.5° past straight.
    start = np.radians([-4.0, 20.0, -4.0, -8.0, 30.0, -8.0])
    rot = np.tile([1.0, 0, 0, 0], (len(start), len(names), 1))
    rot[:, knee] = quat.from_axis_angle(start[:, None] * [1.0, 0.0, 0.0])
    m = Motion(30.0, names, parents, offsets, rot, np.zeros((len(start), 3)) + [0, 1, 0], {"source": "test"})
    grot, gpos = m.global_transforms()
    hip = gpos[:, names.index("l_hip")]
    ankle_pos = gpos[:, ankle]
    # Pull the ankle 3 cm towards the hip, except in frame 3 (5.5° past straight), pushed 1 mm away,
    # and frame 5 (the same), left where it is.
    pull = np.array([0.03, 0.03, 0.03, -0.001, 0.03, 0.0])
    target = ankle_pos + pull[:, None] * (hip - ankle_pos) / np.linalg.norm(hip - ankle_pos, axis=1, keepdims=True)
    out = m.replace(rotations=two_bone_ik(m, rot, m.root_translation, "l", target, grot[:, ankle]))
    reached = out.positions()[:, ankle]
    assert np.abs(reached[[0, 1, 2, 4, 5]] - target[[0, 1, 2, 4, 5]]).max() < 1e-6
    before, after = signed_knee_angles(m)["l"], signed_knee_angles(out)["l"]
    assert (before[[0, 2, 3, 5]] < 0).all(), before
    assert (after[[0, 2]] > 10.0).all(), after                    # hyperextended, bent more: forward
    assert after[1] > before[1] and after[4] > before[4]         # bent knees bend further forward
    assert before[3] <= after[3] <= 0.0                          # straightening keeps its side
    assert after[5] == pytest.approx(before[5], abs=1e-6)         # left alone, as it was
