"""The thesis protocols' motions: point-light rows (Table 4-1 strengths) and validation walks A–D."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import yaml
from scipy import ndimage

from stimuli.errors import StimuliError

STRENGTHS = ("0.5", "12", "23.5", "35", "46.5", "58")


def _short_copy(src, dst, **level_settings):
    """The protocol with 2 s clips (fast tests); ``level_settings`` replace the alternatives' ones."""
    data = yaml.safe_load(src.read_text())
    data["clip"].update(duration_s=2, cycles=1)
    if level_settings:
        factor = next(f for f in data["factors"] if f["role"] == "alternatives")
        factor.setdefault("level_settings", {}).update(level_settings)
    dst.write_text(yaml.safe_dump(data, sort_keys=False))
    return dst


def _stimulus(protocol, part: str):
    from stimuli.design import build_design

    return next(s for s in build_design(protocol).stimuli if part in s.stimulus_id)


def _setup(protocol_path, parameter: str, resolution="960x270", fps=10, duration=2.0):
    """(protocol, stimulus with strengths in declared order, look, figures) of one PARAMETER level.

    The design shows the strengths in shuffled orders; the renderer draws any order, and these
    tests read walker k as strength k."""
    from stimuli.protocol import load_protocol
    from stimuli.render.settings import look_for
    from stimuli.render.sources import protocol_figures

    protocol = load_protocol(protocol_path("thesis_pointlight"))
    stimulus = dataclasses.replace(_stimulus(protocol, f"{parameter}-"), arrangement=STRENGTHS)
    look = dataclasses.replace(look_for(protocol, stimulus, resolution=resolution, fps=fps), duration_s=duration)
    return protocol, stimulus, look, protocol_figures(protocol, stimulus, look)


def _markers(figure):
    from stimuli.motion.markers import MARKERS, body_markers
    from stimuli.render.clip import centred_root

    pos = body_markers(figure.body, figure.rotations, centred_root(figure))
    return {name: pos[:, k] for k, name in enumerate(MARKERS)}


def _heading_deg(q):
    """Heading (°) of world rotations whose rest faces +z."""
    from stimuli.motion import quat

    forward = quat.rotate(q, np.array([0.0, 0.0, 1.0]))
    return np.degrees(np.unwrap(np.arctan2(forward[:, 0], forward[:, 2])))


def _increasing(values, what):
    assert all(b > a for a, b in zip(values, values[1:])), f"{what} should grow with strength: {values}"


def _projected(look, figures):
    """Pixel positions (T, k·15, 2) of every walker's markers, as the renderer places them (one tile each)."""
    from stimuli.motion.markers import body_markers
    from stimuli.render.clip import apply_pose, centred_root, placements, tiles

    tallest = max(f.body.anthropometry.height_m for f in figures)
    xy = []
    for (x0, tile), f in zip(tiles(look, len(figures)), figures):
        (pose,), view = placements(tile, 1, tallest)
        world = body_markers(f.body, f.rotations, centred_root(f))
        pixels = view.project(apply_pose(pose, world.reshape(-1, 3)))[..., :2].reshape(len(world), 15, 2)
        xy.append(pixels + np.array([x0, 0.0]))
    return np.concatenate(xy, axis=1)


def test_a_walker_looks_the_same_in_every_place_of_the_row(protocol_path):
    """One wide camera over the row stretched the outer walkers: the same walker came out 1.47× as wide in
    the outer places as in the middle, more than the strengths' own effect (×1.57), in a survey asking which
    walker looks obese. Each walker now has its own tile."""
    from stimuli.render.clip import render_frames

    _, _, look, figures = _setup(protocol_path, "arm_abduction", resolution="1920x540", fps=5, duration=1.0)
    same = [dataclasses.replace(figures[1], label=f.label) for f in figures]   # the 12 % walker six times
    frames = np.stack(list(render_frames(look, same)))
    lit = frames.max(axis=-1) > 100
    lit[:, int(0.85 * look.height):] = False                                   # not the labels beneath
    widths = []
    for k in range(6):
        columns = np.nonzero(lit[:, :, k * 320:(k + 1) * 320].any(axis=(0, 1)))[0]
        widths.append(int(columns.max() - columns.min()))
    assert max(widths) - min(widths) <= 1, widths
    above_labels = frames[:, :int(0.85 * look.height)]
    assert np.array_equal(above_labels[:, :, :320], above_labels[:, :, 640:960])   # the same walker, the same pixels


def test_point_light_row_shows_six_walkers_of_15_dots(protocol_path):
    from stimuli.render.clip import render_frames
    from stimuli.render.pointlight import DOT_RADIUS_M

    _, _, look, figures = _setup(protocol_path, "arm_abduction", resolution="1920x540", fps=5)
    assert look.azimuth_deg == 0.0 and len(figures) == 6
    frames = np.stack(list(render_frames(look, figures)))
    xy = _projected(look, figures)
    radius_px = 0.5 * look.height / np.tan(np.radians(look.fov_deg) / 2) * DOT_RADIUS_M / look.distance_m
    bottom = int(xy[..., 1].max() + 2 * radius_px + 2)       # the labels A–F are beneath the dots, in red
    labels = np.array([ndimage.label(f[bottom:].max(axis=-1) > 100)[1] for f in frames])
    text = frames[:, bottom:][frames[:, bottom:].max(axis=-1) > 100]
    assert (text[:, 0] > 2 * text[:, 1].astype(int)).all(), "red lettering beneath each walker (section 4.3)"
    assert (labels == 6).all(), labels
    counts = np.array([ndimage.label(f[:bottom].max(axis=-1) > 100)[1] for f in frames])
    gaps = np.linalg.norm(xy[:, :, None] - xy[:, None], axis=-1) + np.eye(90) * 1e9
    apart = gaps.min(axis=(1, 2)) > 2 * radius_px + 3
    assert apart.sum() >= 2, "some frames should show all 90 dots apart"
    assert (counts[apart] == 90).all() and counts.max() == 90, counts
    assert frames[..., 0].mean() < 20, "white dots on black"


def test_point_light_row_through_the_renderer(protocol_path, tmp_path):
    from stimuli.render import render_protocol
    from stimuli.render.video import read_video

    src = _short_copy(protocol_path("thesis_pointlight"), tmp_path / "pl.yaml")
    report = render_protocol(src, tmp_path / "out", resolution="160x90", fps=5, only="speed_cadence-", limit=1,
                             workers=1, progress=False, sheet=False)
    assert len(report.rendered) == 1 and not report.failed
    frames = read_video(tmp_path / "out" / "clips" / f"{report.rendered[0]}.mp4")[0]
    assert frames.shape[0] == 10 and frames.shape[1:3] == (90, 160)
    lit = frames.max(axis=(0, 3)) > 100
    sixths = [lit[:, k * 160 // 6:(k + 1) * 160 // 6].sum() for k in range(6)]
    assert min(sixths) > 0, f"a walker of the row is missing: {sixths}"


def test_view_angle_follows_the_parameter_level(protocol_path):
    from stimuli.motion.markers import MARKERS

    left, right = MARKERS.index("l_shoulder"), MARKERS.index("r_shoulder")
    shoulder_px = {}
    for parameter, view in (("arm_abduction", 0.0), ("arm_swing", 90.0), ("hip_torso_twist", 45.0)):
        _, _, look, figures = _setup(protocol_path, parameter)
        assert look.azimuth_deg == view
        xy = _projected(look, figures[1:2])                # the unchanged walker (12 %)
        shoulder_px[view] = float(np.abs(xy[:, left, 0] - xy[:, right, 0]).mean())
    # Seen from the front the shoulders are a body width apart on screen, from the side nearly one.
    assert shoulder_px[0.0] > 2 * shoulder_px[45.0] * 0.6 > 0
    assert shoulder_px[90.0] < 0.3 * shoulder_px[0.0], shoulder_px


def test_arm_abduction_and_bob_grow_with_strength(protocol_path):
    _, _, _, figures = _setup(protocol_path, "arm_abduction_bob", fps=30)
    m = [_markers(f) for f in figures]
    out = [float(np.mean(k["l_wrist"][:, 0] - k["l_shoulder"][:, 0] + k["r_shoulder"][:, 0] - k["r_wrist"][:, 0]))
           for k in m]
    _increasing(out, "wrist distance out from the shoulders")
    bob = [float(np.ptp(k["l_wrist"][:, 0] - k["l_shoulder"][:, 0])) for k in m]
    _increasing(bob, "sideways wrist excursion (arm bob)")


def test_arm_abduction_alone_leaves_the_legs_alone(protocol_path):
    _, _, _, figures = _setup(protocol_path, "arm_abduction", fps=30)
    m = [_markers(f) for f in figures]
    wrists = [float(np.mean(k["l_wrist"][:, 0] - k["l_shoulder"][:, 0])) for k in m]
    _increasing(wrists, "left wrist abduction")
    heels = np.array([np.mean(k["l_heel"][:, 0] - k["r_heel"][:, 0]) for k in m])
    assert np.ptp(heels) < 0.005, heels


def test_lower_body_slows_twists_hips_and_widens_the_base(protocol_path):
    # The protocol's 30 s: whole loops fill the clip, so the speeds keep Table 4-1's ratios closely
    # (in a 2 s clip the loop count would round them: 1 loop or 2).
    _, _, _, figures = _setup(protocol_path, "lower_body", fps=10, duration=30.0)
    speeds = np.array([f.belt_speed_mps for f in figures])
    ratios = speeds / speeds[1]
    assert np.allclose(ratios, [1.1, 1.0, 0.9, 0.805026, 0.7, 0.6], atol=0.03), ratios
    m = [_markers(f) for f in figures]
    base = [float(np.mean(k["l_heel"][:, 0] - k["r_heel"][:, 0])) for k in m]
    _increasing(base, "heel spacing")
    twist = [float(np.ptp(_heading_deg(f.rotations[:, 0]))) for f in figures]   # the rig's root: pelvis
    _increasing(twist[1:], "hip twist range")      # 0.5 %: −0.8 × the twist (reversed, smaller)
    assert twist[0] < twist[1]


def test_spinal_erectness_leans_the_trunk_back(protocol_path):
    _, _, _, figures = _setup(protocol_path, "spinal_erectness", fps=30)
    # The walker faces +z: leaning back moves the head behind the hips.
    lean = [-float(np.mean(k["head"][:, 2] - k["hips"][:, 2])) for k in (_markers(f) for f in figures)]
    _increasing(lean, "backward lean of the head over the hips")


def test_parameter_level_without_modifies_is_a_named_error(protocol_path, tmp_path):
    """A PARAMETER level without ``modifies`` or with an unknown Table 4-1 row is refused when the
    protocol is loaded (``validate``), not only when its clip is rendered."""
    from stimuli.protocol import load_protocol

    for level, setting, expected in (("arm_swing", {"view_deg": 90}, "arm_swing"),
                                     ("arm_abduction", None, "belly")):
        data = yaml.safe_load(protocol_path("thesis_pointlight").read_text())
        settings = data["factors"][0]["level_settings"]
        if setting is None:
            settings[level]["modifies"] = "arm_abduction+belly"
        else:
            settings[level] = setting
        (tmp_path / "p.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
        with pytest.raises(StimuliError, match=expected):
            load_protocol(tmp_path / "p.yaml")


# -- validation --------------------------------------------------------------------------------

def test_validation_row_missing_obese_capture_names_the_setting(protocol_path, tmp_path):
    from stimuli.render import render_protocol

    src = _short_copy(protocol_path("thesis_validation"), tmp_path / "v.yaml")
    with pytest.raises(StimuliError, match=r"level_settings\.obese_mocap\.motion") as err:
        render_protocol(src, tmp_path / "out", resolution="160x90", fps=5, workers=1, progress=False, sheet=False)
    assert "bvh:" in str(err.value)


def test_validation_row_renders_the_sources_on_ae(protocol_path, tmp_path, monkeypatch):
    """With a capture for obese_mocap (here the bundled walk, given relative to the protocol file
    and rendered from another working directory), the row renders; the sources move AE differently."""
    import shutil

    from stimuli.render import render_protocol
    from stimuli.render.thesis_sources import BASE_WALK
    from stimuli.render.video import read_video

    (tmp_path / "captures").mkdir()
    shutil.copy(BASE_WALK, tmp_path / "captures" / "obese.bvh")
    monkeypatch.chdir(BASE_WALK.parent)
    src = _short_copy(protocol_path("thesis_validation"), tmp_path / "v.yaml",
                      obese_mocap={"motion": "bvh:captures/obese.bvh"})
    report = render_protocol(src, tmp_path / "out", resolution="320x120", fps=5, workers=1, progress=False,
                             sheet=False)
    assert len(report.rendered) == 1 and not report.failed
    frames = read_video(tmp_path / "out" / "clips" / f"{report.rendered[0]}.mp4")[0]
    assert frames.shape == (10, 120, 320, 3)
    body = np.abs(frames[0].astype(int) - 158).max(axis=-1) < 40      # grey bodies on white
    quarters = [body[:, k * 80:(k + 1) * 80].sum() for k in range(4)]
    assert min(quarters) > 20, quarters


def test_validation_sources_differ_as_described(protocol_path):
    from stimuli.motion.modifier import thesis_parameters
    from stimuli.protocol import load_protocol
    from stimuli.render.settings import look_for
    from stimuli.render.sources import _alternative_figure

    protocol = load_protocol(protocol_path("thesis_validation"))
    stimulus = _stimulus(protocol, "lean_mocap")
    look = dataclasses.replace(look_for(protocol, stimulus, resolution="160x90", fps=30), duration_s=2.0)
    figs = {level: _alternative_figure(protocol, stimulus, look, "source", level, "")
            for level in ("lean_mocap", "keyframed", "modifier")}
    assert all(f.body.body_id == "AE" for f in figs.values())
    m = {level: _markers(f) for level, f in figs.items()}

    def abduction(k):
        return float(np.mean(k["l_wrist"][:, 0] - k["l_shoulder"][:, 0]))

    def base(k):
        return float(np.mean(k["l_heel"][:, 0] - k["r_heel"][:, 0]))

    ae = next(a for a in protocol.actors if a.id == "AE")
    p = thesis_parameters(ae.height_m, ae.body_fat_pct, ae.chest_m, ae.waist_m / ae.hip_m)
    assert p["abduction_offset_deg"] > 0 and p["base_offset_mm"] > 0
    assert abduction(m["modifier"]) > abduction(m["lean_mocap"]) + 0.02
    # each heel moves out by the modifier's offset (mm): the spacing grows by twice it
    grown = base(m["modifier"]) - base(m["lean_mocap"])
    assert abs(grown - 2 * p["base_offset_mm"] / 1000) < 0.01, grown
    # the keyframed stand-in is a different walk altogether (the generator's), not the capture
    assert np.abs(m["keyframed"]["l_knee"] - m["lean_mocap"]["l_knee"]).max() > 0.05


def test_bvh_capture_is_part_of_the_inputs_hash(protocol_path, tmp_path):
    from stimuli.protocol import load_protocol
    from stimuli.render.sources import motion_files

    src = _short_copy(protocol_path("thesis_validation"), tmp_path / "v.yaml",
                      obese_mocap={"motion": "bvh:captures/obese.bvh"})
    protocol = load_protocol(src)
    files = motion_files(protocol, _stimulus(protocol, "lean_mocap"))
    assert files == [tmp_path.resolve() / "captures" / "obese.bvh"]  # relative to the protocol file
