"""The one point-light marker set: the CSV of ``shapemotion motion markers`` and the dots a clip draws."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from stimuli.motion.generate import GaitParams, generate
from stimuli.motion.markers import HEEL_HEIGHT_M, MARKERS, body_markers, skeleton_markers

BODY = "sex=M,height=1.8,bmi=25"


@pytest.fixture(scope="module")
def body():
    from stimuli.bodies import fit_body

    return fit_body("M", 1.8, 25.0)


@pytest.fixture(scope="module")
def walk():
    return generate(GaitParams(gait="walk", cadence_spm=112, speed_mps=1.2), height_m=1.8, fps=30, cycles=1)


def test_markers_csv_holds_the_dots_the_clip_draws(body, walk, tmp_path, run_cli, monkeypatch):
    """The CSV put the upper-leg markers at the hips (21 cm from the clip's mid-thigh dots), the head
    5 cm and the heels 1–2 cm away from the dots drawn; with --body it holds exactly those dots."""
    from stimuli.motion import Motion
    from stimuli.motion.retarget import retarget
    from stimuli.render import pointlight
    from stimuli.render.clip import Figure, Look, apply_pose, centred_root, placements, render_frames

    on_body = retarget(walk, body).slice(0, 4)
    on_body.save(tmp_path / "r.npz")
    code, _, err = run_cli("motion", "markers", tmp_path / "r.npz", "--body", BODY, "--out", tmp_path / "mk.csv")
    assert code == 0, err
    csv = pd.read_csv(tmp_path / "mk.csv")
    assert list(csv["marker"][:15]) == MARKERS
    written = csv[["x", "y", "z"]].to_numpy().reshape(on_body.n_frames, 15, 3)

    drawn, real = [], pointlight.DotFigure    # the markers render_frames hands the dots, in the slot's frame

    def recording(stage, markers, *args):
        drawn.append(markers)
        return real(stage, markers, *args)

    monkeypatch.setattr(pointlight, "DotFigure", recording)
    look = Look("point_light", 160, 90, 30, on_body.n_frames / 30, background="#000000")
    m = Motion.load(tmp_path / "r.npz")
    figure = Figure(body, m.rotations, m.root_translation, 0.0)
    list(render_frames(look, [figure]))
    poses, _ = placements(look, 1, body.anthropometry.height_m)
    shift = centred_root(figure) - m.root_translation       # the clip centres the walker over its slot
    assert np.allclose(drawn[0], apply_pose(poses[0], written + shift[:, None]), atol=2e-6)


def test_without_a_body_the_markers_follow_the_same_anatomy(body, walk):
    """At rest, on a body's rig and on a bare skeleton alike: upper legs halfway from hip to knee,
    heels 3 cm above the sole, the head above its joint."""
    def rest(motion):
        return motion.replace(rotations=np.tile([1.0, 0, 0, 0], motion.rotations.shape[:2] + (1,)),
                              root_translation=np.tile(motion.rest_positions()[0], (motion.n_frames, 1)))

    bare = rest(walk.slice(0, 1))
    rig = body.rig
    on_body = body_markers(body, np.tile([1.0, 0, 0, 0], (1, rig.n_bones, 1)), rig.rest_heads[:1])
    for markers, floor, hip, knee, head in (
            (skeleton_markers(bare)[0], bare.rest_positions()[:, 1].min(), *(
                bare.rest_positions()[bare.joint_names.index(j)] for j in ("l_hip", "l_knee", "head"))),
            (on_body[0], 0.0, *(rig.rest_heads[rig.index(j)] for j in ("upperleg01.L", "lowerleg01.L", "head")))):
        k = {name: markers[i] for i, name in enumerate(MARKERS)}
        assert np.allclose(k["l_upper_leg"], 0.5 * (hip + knee))
        assert k["l_heel"][1] - floor == pytest.approx(HEEL_HEIGHT_M) == k["r_heel"][1] - floor
        assert k["head"][1] > head[1] + 0.01


def test_markers_of_a_motion_on_another_rig_need_retargeting(walk, tmp_path, run_cli):
    walk.save(tmp_path / "w.npz")
    code, _, err = run_cli("motion", "markers", tmp_path / "w.npz", "--body", BODY, "--out", tmp_path / "mk.csv")
    assert code == 2 and "retarget it first" in err and not (tmp_path / "mk.csv").exists()


def test_markers_cli_note_for_an_anny_rig_without_its_body(body, walk, tmp_path, run_cli):
    from stimuli.motion.retarget import retarget

    retarget(walk, body).slice(0, 2).save(tmp_path / "r.npz")
    code, _, err = run_cli("motion", "markers", tmp_path / "r.npz", "--out", tmp_path / "mk.csv")
    assert code == 0 and "give that body as --body" in err



def test_a_motion_on_another_bodys_rig_is_not_on_this_one(body, walk):
    """Every Anny rig has the same joint names: the markers of a man's motion were computed on a woman's body
    and a clip played it on her mesh unretargeted; the bones tell the rigs apart."""
    from stimuli.bodies import fit_body
    from stimuli.errors import StimuliError
    from stimuli.motion.markers import marker_trajectories
    from stimuli.motion.retarget import is_on_rig, retarget
    from stimuli.render.sources import on_rig

    other = fit_body("F", 1.5, 40.0)
    mine = retarget(walk, body).slice(0, 3)
    assert is_on_rig(mine, body) and not is_on_rig(mine, other)
    with pytest.raises(StimuliError, match="not on the body's rig"):
        marker_trajectories(mine, other)
    shown = on_rig(mine, other)
    assert is_on_rig(shown, other) and on_rig(mine, body) is mine
