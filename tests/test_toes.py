"""The toes bend at the ball (``stimuli.motion.toes``): a retargeted foot rolls over its ball with
its toes on the floor, then over the toe tips, where it used to stand on the tips of straight toes
with the ball 20–70 mm up (docs/readme_motion.md, "Toes that bend at the ball")."""

from __future__ import annotations

import numpy as np
import pytest

from stimuli.motion import quat
from stimuli.motion.footfix import sole_positions
from stimuli.motion.motion import Motion
from stimuli.motion.toes import MAX_TOE_BEND_DEG, TOE_RELAX_DEG_S, level_toes, toe_joints


def legs(pitch_deg: float, n: int = 10) -> tuple[Motion, dict]:
    """Two legs whose feet pitch ``pitch_deg`` toe-down, and sole points with ball and tip on the toe."""
    names = ["pelvis", "l_hip", "l_knee", "l_ankle", "l_toe", "r_hip", "r_knee", "r_ankle", "r_toe"]
    rot = np.tile([1.0, 0, 0, 0], (n, 9, 1))
    rot[:, [3, 7]] = quat.from_axis_angle(np.array([np.radians(pitch_deg), 0.0, 0.0]))
    motion = Motion(fps=30.0, joint_names=names, parents=[-1, 0, 1, 2, 3, 0, 5, 6, 7],
                    offsets=[[0, 0, 0], [0.1, 0, 0], [0, -0.45, 0], [0, -0.42, 0], [0, -0.05, 0.15],
                             [-0.1, 0, 0], [0, -0.45, 0], [0, -0.42, 0], [0, -0.05, 0.15]],
                    rotations=rot, root_translation=np.tile([0, 0.95, 0], (n, 1)))
    points = {s: [(ankle, np.array([0, -0.07, -0.05])), (toe, np.array([0, -0.02, 0.0])),
                  (toe, np.array([0, -0.02, 0.05]))] for s, ankle, toe in (("l", 3, 4), ("r", 7, 8))}
    return motion, points


def toe_line_pitch(motion: Motion, rot: np.ndarray, points: dict, side: str) -> np.ndarray:
    """Degrees the ball → tip line points below the horizontal, per frame."""
    grot, gpos = motion.global_transforms(rot, motion.root_translation)
    sole = sole_positions(grot, gpos, points[side])
    line = sole[:, 2] - sole[:, 1]
    return np.degrees(np.arctan2(-line[:, 1], np.linalg.norm(line[:, [0, 2]], axis=1)))


def test_planted_toes_lie_level_and_relax_after_toe_off():
    motion, points = legs(30.0)
    contact = np.array([True] * 5 + [False] * 5)
    out = level_toes(motion, motion.rotations, motion.root_translation, {"l": contact, "r": contact}, points,
                     cyclic=False)
    bend = np.degrees(quat.angle(out[:, toe_joints(motion, "l")[0]]))
    assert np.allclose(toe_line_pitch(motion, out, points, "l")[:5], 0.0, atol=1e-6)
    assert np.allclose(bend[:5], 30.0)
    step = TOE_RELAX_DEG_S / motion.fps                      # 10° a frame at 30 fps
    assert np.allclose(bend[5:], np.maximum(30.0 - step * np.arange(1, 6), 0.0))
    assert np.allclose(out[:, [0, 1, 2, 3]], motion.rotations[:, [0, 1, 2, 3]])   # nothing else moves


def test_toes_bend_no_further_than_their_limit_nor_down():
    steep, points = legs(70.0)
    planted = {s: np.ones(steep.n_frames, bool) for s in "lr"}
    out = level_toes(steep, steep.rotations, steep.root_translation, planted, points)
    assert np.allclose(np.degrees(quat.angle(out[:, 8])), MAX_TOE_BEND_DEG)
    assert np.allclose(toe_line_pitch(steep, out, points, "r"), 70.0 - MAX_TOE_BEND_DEG, atol=1e-6)
    up, points = legs(-20.0)                                  # toes up at heel strike: left as they are
    out = level_toes(up, up.rotations, up.root_translation, planted, points)
    assert np.allclose(out, up.rotations)


@pytest.fixture(scope="module")
def walk_on_body():
    from stimuli.bodies import fit_body
    from stimuli.motion.generate import GaitParams, generate
    from stimuli.motion.retarget import retarget

    body = fit_body("M", 1.75, 23.0)
    walk = generate(GaitParams(gait="walk", cadence_spm=112, speed_mps=1.3), height_m=1.75, fps=30, cycles=2)
    return body, walk, retarget(walk, body)


@pytest.mark.slow
def test_a_foot_pushes_off_from_its_ball_with_its_toes_on_the_floor(walk_on_body):
    """Heel up in contact, the foot stands on its ball and its bent toes, both on the floor, until
    the toes reach their limit; before, straight toes held the ball 15–50 mm up on this walk."""
    from stimuli.motion.retarget import mesh_sole_points

    body, _, out = walk_on_body
    grot, gpos = out.global_transforms()
    for s in "lr":
        contact = np.asarray(out.metadata["contacts"][s], bool)
        sole = sole_positions(grot, gpos, mesh_sole_points(body)[s])
        bend = np.degrees(quat.angle(out.rotations[:, toe_joints(out, s)[0]]))
        heel_up = contact & (sole[:, 0, 1] > 0.03)
        on_ball = heel_up & (bend < MAX_TOE_BEND_DEG - 1.0)
        assert heel_up.sum() >= 6 and on_ball.sum() >= 4, (s, heel_up.sum(), on_ball.sum())
        assert np.abs(sole[on_ball][:, 1:, 1]).max() < 0.002, sole[on_ball][:, 1:, 1]
        assert np.abs(sole[heel_up][:, 2, 1]).max() < 0.002        # the tip is down to the last frame
        assert bend.max() <= MAX_TOE_BEND_DEG + 1e-6 and bend[on_ball].max() > 20.0


@pytest.mark.slow
def test_the_push_off_keeps_the_generators_ankle(walk_on_body):
    """The generator's ankle follows the CGM2.3 curve; pivoting on the tips of straight toes, the
    clean-up turned the retargeted ankle up to 12° back towards dorsiflexion late in stance (RMS
    6.5°). The shank–foot angle, each about its stance median, now stays within 5° RMS of the
    generator's there."""
    from stimuli.motion.footfix import roll_weight
    from stimuli.motion.skeleton import role_indices

    _, walk, out = walk_on_body

    def ankle(m, s):
        p, r = m.positions(), role_indices(m)
        shank = p[:, r[f"{s}_ankle"]] - p[:, r[f"{s}_knee"]]
        foot = p[:, r[f"{s}_toe"]] - p[:, r[f"{s}_ankle"]]
        cos = np.sum(shank * foot, axis=1) / np.linalg.norm(shank, axis=1) / np.linalg.norm(foot, axis=1)
        return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))

    for s in "lr":
        contact = np.asarray(out.metadata["contacts"][s], bool)
        late = roll_weight(contact) > 0
        a, b = ankle(out, s), ankle(walk, s)
        off = (a - np.median(a[contact])) - (b - np.median(b[contact]))
        assert np.sqrt(np.mean(off[late] ** 2)) < 5.0, (s, off[late].round(1))


@pytest.mark.slow
def test_the_toe_bend_is_reported_apart_from_the_joint_change(walk_on_body):
    from stimuli.motion.footfix import joint_change_deg, leg_joint_indices

    _, walk, out = walk_on_body
    meta = out.metadata
    assert 20.0 < meta["toe_bend_max_deg"] <= MAX_TOE_BEND_DEG
    from stimuli.motion.retarget import retarget

    plain = retarget(walk, walk_on_body[0], cleanup=False)
    kept = out.rotations.copy()
    toes = toe_joints(out, "l") + toe_joints(out, "r")
    kept[:, toes] = plain.rotations[:, toes]
    assert meta["joint_change_max_deg"] == round(joint_change_deg(plain.rotations, kept, leg_joint_indices(plain))[0], 2)
    assert meta["joint_change_max_deg"] < meta["toe_bend_max_deg"]
