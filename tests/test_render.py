"""Rendering: video files, frames of each layout (real Anny bodies, procedural poses), point-light
markers. Clips are tiny (160×90 … 320×180, ≤ 1 s) so the file runs in about a minute."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from stimuli.errors import StimuliError


def _decode(path):
    from stimuli.render.video import read_video

    return read_video(path)


@pytest.fixture(scope="module")
def body():
    from stimuli.bodies import fit_body

    return fit_body("F", 1.60, 28.1)


def _look(layout="treadmill", width=160, height=90, fps=15, duration=1.0, azimuth=35.0, background="#ffffff"):
    from stimuli.render.clip import Look

    return Look(layout, width, height, fps, duration, azimuth, 10.0, 4.0, 40.0, background)


def _figure(body, look, amplitude=1.0, speed=0.0, label=""):
    from stimuli.render.clip import Figure
    from stimuli.render.procedural import stepping_pose

    rot, root = stepping_pose(body, look.n_frames, cycles=1, amplitude=amplitude)
    return Figure(body, rot, root, speed, label)


# -- video files ------------------------------------------------------------------------------------

def _moving_square(n, w=160, h=90):
    for i in range(n):
        frame = np.full((h, w, 3), 255, np.uint8)
        frame[30:60, 5 + 6 * i:35 + 6 * i] = (200, 40, 40)
        yield frame


def test_video_has_exact_frames_size_fps_and_faststart(tmp_path):
    from stimuli.render.video import write_video

    info = write_video(_moving_square(15), tmp_path / "a.mp4", 15, 160, 90, 15, poster=tmp_path / "a.png")
    frames, meta = _decode(info.path)
    assert frames.shape == (15, 90, 160, 3)
    assert meta["fps"] == 15 and meta["codec"] == "h264" and meta["pix_fmt"].startswith("yuv420p")
    data = info.path.read_bytes()
    assert 0 <= data.find(b"moov") < data.find(b"mdat"), "+faststart puts the index before the media data"
    assert (tmp_path / "a.png").exists()
    # the square moves right by 6 px per frame: the decoded frames keep the order
    red = [np.argwhere((f[..., 0] > 150) & (f[..., 1] < 100))[:, 1].mean() for f in frames]
    assert np.all(np.diff(red) > 4)


def test_video_with_wrong_frame_count_or_interrupted_leaves_nothing(tmp_path):
    from stimuli.render.video import write_video

    with pytest.raises(RuntimeError, match="expected 20"):
        write_video(_moving_square(15), tmp_path / "b.mp4", 15, 160, 90, 20)

    def interrupted():
        yield from _moving_square(3)
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_video(interrupted(), tmp_path / "c.mp4", 15, 160, 90, 15, poster=tmp_path / "c.png")
    assert not [p for p in tmp_path.iterdir() if p.suffix == ".mp4"]
    assert not [p for p in tmp_path.iterdir() if ".tmp" in p.name]


def test_odd_resolution_is_a_user_error():
    from stimuli.render.settings import parse_resolution

    assert parse_resolution("640x360") == (640, 360)
    for bad in ("641x360", "640", "axb", "8x8"):
        with pytest.raises(StimuliError, match="--resolution"):
            parse_resolution(bad)


# -- frames ----------------------------------------------------------------------------------------

def _frames(look, figures):
    from stimuli.render.clip import render_frames

    return np.stack(list(render_frames(look, figures)))


def test_treadmill_body_fully_in_frame_every_frame_and_moving(body):
    from stimuli.render.clip import centred_root, placements

    look = _look(width=320, height=180)
    figure = _figure(body, look, speed=1.2)
    frames = _frames(look, [figure])
    assert frames.shape == (look.n_frames, 180, 320, 3)
    # geometry: every skinned vertex of every frame projects inside the image
    poses, view = placements(look, 1, body.anthropometry.height_m)
    vertices = body.skin(figure.rotations, centred_root(figure))
    xy = view.project(vertices.reshape(-1, 3) @ poses[0][:3, :3].T + poses[0][:3, 3])
    assert xy[:, 0].min() > 1 and xy[:, 0].max() < 319 and xy[:, 1].min() > 1 and xy[:, 1].max() < 179
    # pixels: the grey body is there in every frame, and the picture changes from frame to frame
    grey = (np.abs(frames.astype(int) - 158).max(axis=-1) < 40).sum(axis=(1, 2))
    assert grey.min() > 800
    steps = np.abs(np.diff(frames.astype(int), axis=0)).mean(axis=(1, 2, 3))
    assert steps.min() > 0.05


def test_belt_moves_at_speed_and_clip_loops_without_a_jump(body):
    look = _look(width=320, height=180)
    still = _figure(body, look, amplitude=0.0, speed=1.2)
    frames = _frames(look, [still]).astype(int)
    steps = [np.abs(frames[i + 1] - frames[i]).mean() for i in range(len(frames) - 1)]
    assert min(steps) > 0.02, "with a standing body only the belt moves, in every frame"
    wrap = np.abs(frames[0] - frames[-1]).mean()
    assert wrap < 1.5 * max(steps), "last frame → first frame is an ordinary step (seamless loop)"
    stopped = _frames(look, [_figure(body, look, amplitude=0.0, speed=0.0)]).astype(int)
    assert np.abs(np.diff(stopped, axis=0)).max() <= 2, "nothing moves when the belt stands still"


def test_belt_period_divides_the_travel():
    from stimuli.render.treadmill import belt_period

    for speed, duration, fps in ((1.2, 4.0, 30), (2.2, 4.0, 30), (0.9, 12.0, 25)):
        period = belt_period(speed, duration, fps)
        turns = speed * duration / period
        assert abs(turns - round(turns)) < 1e-9 and speed / fps < period / 3


def _blobs(frame, threshold=100):
    mask = frame.max(axis=-1) > threshold
    return ndimage.label(mask)[1]


def test_point_light_clip_has_exactly_15_bright_dots(body):
    from stimuli.motion.markers import MARKERS, body_markers
    from stimuli.render.clip import centred_root, placements
    from stimuli.render.pointlight import DOT_RADIUS_M

    assert len(MARKERS) == 15

    look = _look("point_light", width=480, height=270, azimuth=30.0, background="#000000")
    figure = _figure(body, look)
    frames = _frames(look, [figure])
    counts = np.array([_blobs(f) for f in frames])
    # Where the projected dots are apart (no natural overlap, e.g. a heel passing behind a knee),
    # the frame must show exactly 15 blobs; no frame may ever show more.
    _, view = placements(look, 1, body.anthropometry.height_m)
    xy = view.project(body_markers(body, figure.rotations, centred_root(figure)))
    gaps = np.linalg.norm(xy[:, :, None] - xy[:, None], axis=-1) + np.eye(15) * 1e9
    radius_px = 0.5 * look.height / np.tan(np.radians(look.fov_deg) / 2) * DOT_RADIUS_M / look.distance_m
    apart = gaps.min(axis=(1, 2)) > 2 * radius_px + 3
    assert apart.sum() >= 3, "the test pose should show separated dots in several frames"
    assert (counts[apart] == 15).all() and counts.max() == 15, counts
    assert frames[..., 0].mean() < 20, "white dots on black"


def test_row_of_labelled_walkers_each_in_its_own_column(body):
    look = _look("row", width=480, height=180, azimuth=45.0)
    figures = [_figure(body, look, label=x) for x in "ABCD"]
    frames = _frames(look, figures)
    dark_text = (frames[0, :20].max(axis=-1) < 160).any(axis=0)   # labels along the top
    columns = ndimage.label(ndimage.binary_dilation(dark_text, iterations=3))[1]
    assert columns == 4
    body_px = (np.abs(frames[0].astype(int) - 158).max(axis=-1) < 40)
    quarters = [body_px[:, k * 120:(k + 1) * 120].sum() for k in range(4)]
    assert min(quarters) > 200, quarters


@pytest.mark.parametrize("module", ["camera", "clip", "preview", "scene", "settings", "sources", "treadmill"])
def test_docstring_examples(module):
    import doctest
    import importlib

    result = doctest.testmod(importlib.import_module(f"stimuli.render.{module}"))
    assert result.attempted > 0 and result.failed == 0


@pytest.mark.parametrize("target", [("M", 1.83, 35.8), ("F", 1.60, 19.5)])
def test_redrawn_region_holds_every_vertex_of_every_frame(target):
    """Only the dynamic region is redrawn per frame: any skin outside it would be cut off."""
    from stimuli.bodies import fit_body
    from stimuli.render.clip import apply_pose, centred_root, dynamic_region, placements

    heavy = fit_body(*target)
    for azimuth in (0.0, 35.0, 90.0):
        look = _look(width=320, height=180, azimuth=azimuth)
        figure = _figure(heavy, look)
        poses, view = placements(look, 1, heavy.anthropometry.height_m)
        root = centred_root(figure)
        x0, y0, x1, y1 = dynamic_region(view, [figure], [root], poses, [], False)
        xy = view.project(apply_pose(poses[0], heavy.skin(figure.rotations, root).reshape(-1, 3)))
        assert xy[:, 0].min() >= x0 and xy[:, 0].max() <= x1 and xy[:, 1].min() >= y0 and xy[:, 1].max() <= y1


def test_inputs_hash_follows_look_stimulus_and_motion_files(tmp_path, protocol_path):
    from stimuli.design import build_design
    from stimuli.protocol import load_protocol
    from stimuli.render.settings import inputs_hash, look_for

    protocol = load_protocol(protocol_path("exp2_com_vs_average"))
    first, second = build_design(protocol).stimuli[:2]
    look = look_for(protocol, first)
    motion = tmp_path / "nocom.npz"
    motion.write_bytes(b"one")
    base = inputs_hash(protocol, first, look, [motion])
    assert base == inputs_hash(protocol, first, look, [motion])
    assert base != inputs_hash(protocol, second, look, [motion])
    assert base != inputs_hash(protocol, first, look_for(protocol, first, resolution="640x360"), [motion])
    # A stepping-pose clip is not the real one; protocol renders keep the hashes they had.
    assert base == inputs_hash(protocol, first, look, [motion], poses="protocol")
    assert base != inputs_hash(protocol, first, look, [motion], poses="procedural")
    motion.write_bytes(b"two")
    assert base != inputs_hash(protocol, first, look, [motion])


def test_preview_library_checks_its_settings_before_fitting(tmp_path, monkeypatch):
    """The checks moved with the CLI once; ``preview()`` called from Python wrote to any suffix and took
    zero frames. They run before a body is fitted."""
    from stimuli.errors import StimuliError
    from stimuli.render import preview as module

    monkeypatch.setattr("stimuli.bodies.fit_body", lambda *a, **k: pytest.fail("fitted before checking"))
    for kwargs, message in [({"out": tmp_path / "c.avi"}, "expected a .mp4"),
                            ({"out": tmp_path / "c.mp4", "fps": 0}, "--fps: expected a frame rate > 0"),
                            ({"out": tmp_path / "c.mp4", "duration_s": 0.01, "fps": 5}, "gives no frame")]:
        with pytest.raises(StimuliError, match=message):
            module.preview(sex="M", height_m=1.8, bmi=25.0, **kwargs)
    assert not list(tmp_path.iterdir())
