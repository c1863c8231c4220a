"""The character mesh survey of Shewhorak (2017), chapter 5: protocols/thesis_mesh.yaml and the rows
of Table 5-2 that it adds to the point-light survey's Table 4-1 (``stimuli.motion.modifier``)."""

from __future__ import annotations

from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy import ndimage

from stimuli.design import build_design
from stimuli.errors import StimuliError
from stimuli.motion import quat
from stimuli.motion.modifier import (STRENGTH_BODY_FAT, TABLE_4_1, _arm_angles, _lateral_bend, _yaw,
                                     modify_strengths, table_strengths)
from stimuli.motion.skeleton import role_indices
from stimuli.protocol import load_protocol

PROTOCOLS = Path(__file__).resolve().parents[1] / "protocols"
STRENGTHS = ["0.5", "12", "23.5", "35", "46.5", "58"]
# Table 5-4's survey order with Table 5-2's 'Angle View' (0° FL read as 0°: walkers stay on the spot).
TABLE_5_4 = [("upper_body", 45), ("lower_body", 0), ("walking_base", 0), ("torso_swagger", 0), ("arm_bob", 0),
             ("speed_cadence", 0), ("hip_torso_twist", 45), ("decreased_hip_twist", 45), ("whole_body", 0),
             ("arm_abduction_swing", 45)]
# Table 5-2's parameters per video, as rows of STRENGTH_ROWS.
TABLE_5_2_VIDEOS = {
    "upper_body": {"hip_twist_decreased", "torso_twist_decreased", "arm_abduction", "arm_bob", "arm_swing_decreased"},
    "lower_body": {"speed_cadence", "hip_twist_decreased", "walking_base"},
    "walking_base": {"walking_base"},
    "torso_swagger": {"torso_swagger"},
    "arm_bob": {"arm_bob_isolated"},
    "speed_cadence": {"speed_cadence"},
    "hip_torso_twist": {"hip_twist", "torso_twist"},
    "decreased_hip_twist": {"hip_twist_decreased"},
    "whole_body": {"speed_cadence", "hip_twist_decreased", "torso_twist_decreased", "walking_base", "arm_abduction",
                   "arm_bob_whole_body", "arm_swing_decreased"},
    "arm_abduction_swing": {"arm_abduction", "arm_swing_decreased"},
}
# The rows as Table 5-2 prints them (0.5 … 58 % body fat).
PRINTED = {
    "hip_twist_decreased": (1.25, 1, 0.75, 0.5, 0.25, 0),
    "torso_twist_decreased": (1.25, 1, 0.75, 0.5, 0.25, 0),
    "arm_swing_decreased": (1.25, 1, 0.75, 0.5, 0.25, 0),
    "torso_swagger": (0.8, 1, 1.2, 1.4, 1.6, 1.8),
    "arm_bob_isolated": (-0.79136, 0.104319, 1, 1.895681, 2.791363, 3.687044),
    "arm_bob_whole_body": (0.55, 1, 1.45, 1.895681, 2.34, 2.79),
    # reused from Table 4-1, unchanged
    "arm_abduction": (-3.19355, 0, 3.19355, 6.3871, 9.58065, 12.7742),
    "arm_bob": (0.6, 1, 1.4, 1.895681, 2.3, 2.8),
    "speed_cadence": (1.1, 1, 0.9, 0.805026, 0.7, 0.6),
    "walking_base": (-1, 0, 1, 2, 3, 4),
    "hip_twist": (-0.8, 1, 2.8, 4.644041, 6.5, 8.3),
}


@pytest.fixture(scope="module")
def mesh():
    return load_protocol(PROTOCOLS / "thesis_mesh.yaml")


@pytest.fixture(scope="module")
def walk():
    """The lean base walk (the bundled CMU capture, one looped cycle)."""
    from stimuli.motion.bvh import read_bvh
    from stimuli.motion.loop import make_loop
    from stimuli.render.thesis_sources import BASE_WALK

    return make_loop(read_bvh(BASE_WALK), cycles=1)


# -- the protocol --------------------------------------------------------------------------------

def test_ten_videos_in_table_5_4_order_with_table_5_2_views(mesh):
    factor = mesh.factor("PARAMETER")
    assert mesh.blocks.trials == "fixed" and mesh.blocks.by == []
    assert [(level, factor.level_settings[level]["view_deg"]) for level in factor.levels] == TABLE_5_4
    rows = {level: set(factor.level_settings[level]["modifies"].split("+")) for level in factor.levels}
    assert rows == TABLE_5_2_VIDEOS
    assert mesh.factor("STRENGTH").levels == STRENGTHS and mesh.factor("STRENGTH").role == "alternatives"


def test_six_obese_mesh_walkers_and_the_point_light_question(mesh):
    """Meshes in a row (no point lights), all on MP's obese deformation; the point-light wording."""
    assert mesh.display.layout == "row" and mesh.display.point_light_markers is None
    body = next(a for a in mesh.actors if a.id == mesh.display.body)
    assert (body.sex, body.height_m, body.body_fat_pct, body.bmi) == ("M", 1.758, 35.0, 38.0)
    pointlight = load_protocol((PROTOCOLS / "thesis_pointlight.yaml"))
    assert mesh.response.type == "afc" and mesh.response.question == pointlight.response.question
    assert mesh.display.labels == list("ABCDEF")
    assert mesh.participants % 6 == 0 and abs(mesh.participants - 67) < 6   # n = 67 in the thesis


def test_every_participant_sees_table_5_4_in_order_with_balanced_positions(mesh):
    d = build_design(mesh)
    assert len(d.stimuli) == 60 and d.participants == 66   # 10 videos × 6 Latin-square rows
    positions = defaultdict(Counter)
    for participant in range(1, d.participants + 1):
        tests = [t for t in d.trials if t.participant == participant and t.kind == "test"]
        shown = [d.stimulus(t.stimulus_id) for t in tests]
        assert [s.levels["PARAMETER"] for s in shown] == [level for level, _ in TABLE_5_4]
        assert [t.trial for t in tests] == list(range(1, 11)) and {t.repetition for t in tests} == {1}
        for s in shown:
            assert sorted(s.arrangement) == sorted(STRENGTHS)
            for position, strength in enumerate(s.arrangement):
                positions[(s.levels["PARAMETER"], position)][strength] += 1
    assert len(positions) == 60
    assert all(counts == Counter({lv: 11 for lv in STRENGTHS}) for counts in positions.values())


def test_an_unknown_row_is_refused_listing_the_valid_names(tmp_path):
    data = yaml.safe_load((PROTOCOLS / "thesis_mesh.yaml").read_text())
    data["factors"][0]["level_settings"]["torso_swagger"]["modifies"] = "torso_swager"
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    with pytest.raises(StimuliError, match="torso_swager") as err:
        load_protocol(tmp_path / "p.yaml")
    assert "torso_swagger" in str(err.value) and "arm_bob_isolated" in str(err.value)
    with pytest.raises(StimuliError, match=r"hip_twist_decreased.*arm_bob_whole_body"):
        table_strengths("walking_base+swagger", 35)


# -- the rows ------------------------------------------------------------------------------------

@pytest.mark.parametrize("row", sorted(PRINTED))
def test_rows_hold_table_5_2_values(row):
    values = [table_strengths(row, bf)[row] for bf in STRENGTH_BODY_FAT]
    assert values == pytest.approx(PRINTED[row], abs=1e-12)
    identity = 0.0 if row in ("arm_abduction", "walking_base") else 1.0
    # every row leaves the walk unchanged at the lean 12 %, except the isolated arm bob, kept as printed
    unchanged_at = 23.5 if row == "arm_bob_isolated" else 12.0
    assert table_strengths(row, unchanged_at)[row] == identity


def test_table_4_1_rows_are_unchanged():
    assert TABLE_4_1["arm_swing_mild"][1] == (0.6, 1.0, 1.3, 1.6, 1.9, 2.2)
    assert TABLE_4_1["arm_swing"][1] == (0.5, 1.0, 1.5, 2.0, 2.5, 3.0)
    assert TABLE_4_1["spinal_erectness"][1] == (-5.0, 0.0, 5.0, 10.0, 15.0, 20.0)
    assert TABLE_4_1["torso_twist"] == TABLE_4_1["hip_twist"] == ("swing", PRINTED["hip_twist"])


def _chest_bend(m, rot=None):
    roles = role_indices(m)
    grot = m.global_transforms(m.rotations if rot is None else rot, m.root_translation)[0]
    chest = roles["chest"]
    return _lateral_bend(quat.mul(quat.inv(grot[:, m.parents[chest]]), grot[:, chest]))


def _chest_twist(m):
    grot = m.global_transforms(m.rotations, m.root_translation)[0]
    chest = role_indices(m)["chest"]
    return _yaw(grot[:, chest]) - _yaw(grot[:, m.parents[chest]])


def _flexion(m, side: str):
    roles, rest = role_indices(m), m.rest_positions()
    arm = rest[roles[f"{side}_elbow"]] - rest[roles[f"{side}_shoulder"]]
    return _arm_angles(m.rotations[:, roles[f"{side}_shoulder"]], 1.0 if side == "l" else -1.0,
                       arm / np.linalg.norm(arm))


def test_torso_swagger_scales_the_chest_lateral_bend_about_its_mean(walk):
    bend = _chest_bend(walk)
    assert np.degrees(np.ptp(bend)) > 1.0       # the capture sways: something to scale
    out = modify_strengths(walk, table_strengths("torso_swagger", 35))
    after = _chest_bend(out)
    assert np.allclose(after - bend.mean(), 1.4 * (bend - bend.mean()), atol=1e-9)
    # a roll, not a twist: the chest's heading over its parent barely changes; no other joint turns
    assert np.abs(np.degrees(_chest_twist(out) - _chest_twist(walk))).max() < 0.5
    changed = np.nonzero(np.abs(out.rotations - walk.rotations).max(axis=(0, 2)) > 1e-12)[0]
    assert changed.tolist() == [role_indices(walk)["chest"]]


def test_decreased_swing_at_58_flattens_the_arm_swing(walk):
    out = modify_strengths(walk, table_strengths("arm_swing_decreased", 58))
    for side in "lr":
        abd, flex = _flexion(walk, side)
        abd2, flex2 = _flexion(out, side)
        assert np.degrees(np.ptp(flex)) > 10 and np.degrees(np.ptp(flex2)) < 1e-6
        assert np.allclose(flex2, flex.mean())
        # the abduction stays (turning the arm forwards or back moves its sideways angle a little)
        assert np.degrees(np.abs(abd2 - abd)).max() < 0.1
    more = modify_strengths(walk, table_strengths("arm_swing_decreased", 0.5))
    flex, flex3 = _flexion(walk, "l")[1], _flexion(more, "l")[1]
    assert np.allclose(flex3 - flex.mean(), 1.25 * (flex - flex.mean()), atol=1e-9)


def test_decreased_twists_scale_pelvis_and_chest_headings(walk):
    pelvis = role_indices(walk)["pelvis"]
    yaw = _yaw(walk.global_transforms(walk.rotations, walk.root_translation)[0][:, pelvis])
    out = modify_strengths(walk, table_strengths("hip_twist_decreased", 58))
    yaw0 = _yaw(out.global_transforms(out.rotations, out.root_translation)[0][:, pelvis])
    assert np.degrees(np.ptp(yaw)) > 3 and np.degrees(np.ptp(yaw0)) < 1e-6
    half = modify_strengths(walk, table_strengths("torso_twist_decreased", 35))
    twist = _chest_twist(walk)
    assert np.allclose(_chest_twist(half) - twist.mean(), 0.5 * (twist - twist.mean()), atol=1e-9)


def test_isolated_arm_bob_reverses_at_0_5_and_is_unchanged_at_23_5(walk):
    abd = _flexion(walk, "l")[0]
    out = modify_strengths(walk, table_strengths("arm_bob_isolated", 0.5))
    assert np.allclose(_flexion(out, "l")[0] - abd.mean(), -0.79136 * (abd - abd.mean()), atol=1e-9)
    same = modify_strengths(walk, table_strengths("arm_bob_isolated", 23.5))
    assert np.allclose(same.rotations, walk.rotations, atol=1e-12)


def test_new_rows_leave_the_walk_unchanged_at_12_percent(walk):
    rows = "hip_twist_decreased+torso_twist_decreased+arm_swing_decreased+torso_swagger+arm_bob_whole_body"
    out = modify_strengths(walk, table_strengths(rows, 12))
    assert np.abs(out.positions() - walk.positions()).max() < 1e-6


def test_rows_on_one_curve_multiply(walk):
    """Two rows scaling the same curve compose (scalings about one mean multiply)."""
    flex = _flexion(walk, "r")[1]
    out = modify_strengths(walk, {"arm_swing": 2.0, "arm_swing_decreased": 0.75})
    assert np.allclose(_flexion(out, "r")[1] - flex.mean(), 1.5 * (flex - flex.mean()), atol=1e-9)


# -- one clip through the renderer (about 4 s; 6 s with the body not yet cached) ---------------

def test_one_video_renders_six_separate_mesh_walkers(tmp_path):
    from stimuli.render import render_protocol
    from stimuli.render.video import read_video

    data = yaml.safe_load((PROTOCOLS / "thesis_mesh.yaml").read_text())
    data["clip"].update(duration_s=2, cycles=1)
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    report = render_protocol(tmp_path / "m.yaml", tmp_path / "out", resolution="320x90", fps=5,
                             only="torso_swagger-", limit=1, workers=1, progress=False, sheet=False)
    assert len(report.rendered) == 1 and not report.failed
    frames = read_video(tmp_path / "out" / "clips" / f"{report.rendered[0]}.mp4")[0]
    assert frames.shape == (10, 90, 320, 3)
    for frame in frames:
        grey = frame.astype(int).max(axis=-1)
        # display.floor: false: black throughout. A floor fills whole rows from the horizon down; six
        # heavy walkers with their arms out fill up to half of a row at chest height (0.43-0.48).
        assert (np.percentile(grey, 30, axis=1) < 20).all()
        lit = grey > 40
        parts, n = ndimage.label(lit)
        boxes = ndimage.find_objects(parts)
        # the walkers: tall shaded shapes (the labels A-F above them are a few pixels high)
        walkers = sorted((b for b in boxes if b[0].stop - b[0].start >= 15), key=lambda b: b[1].start)
        assert len(walkers) == 6, [(b[0].start, b[0].stop, b[1].start, b[1].stop) for b in boxes]
        assert all(a[1].stop < b[1].start for a, b in zip(walkers, walkers[1:])), "walkers overlap"
        # meshes, not dots: each a filled, grey-shaded figure
        for box in walkers:
            patch = grey[box][lit[box]]
            assert patch.size > 60 and np.median(patch) < 230


def test_labels_below_on_the_floor_are_drawn_dark(tmp_path):
    """Labels beneath the walkers sit on the light checker floor; their default colour was chosen against
    the black background (white), which left them barely visible."""
    from stimuli.render import render_protocol
    from stimuli.render.video import read_video

    text = (PROTOCOLS / "thesis_mesh.yaml").read_text()
    old = "  floor: false               # on the black background alone, as the thesis rendered them\n"
    assert old in text
    data = yaml.safe_load(text.replace(old, "  label_position: below\n"))
    data["clip"].update(duration_s=1, cycles=1)
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    report = render_protocol(tmp_path / "m.yaml", tmp_path / "out", resolution="640x180", fps=5,
                             only="torso_swagger-", limit=1, workers=1, progress=False, sheet=False)
    frame = read_video(tmp_path / "out" / "clips" / f"{report.rendered[0]}.mp4")[0][0].astype(int)
    strip = frame[int(0.9 * 180):, :, :].max(axis=-1)          # the labels' band, on the floor
    assert np.median(strip) > 150, "the floor under the labels is light"
    assert (strip < 60).sum() > 30, "dark lettering on it"
