"""The stage the stimuli are filmed on, measured in rendered pixels (issue 22, items 1, 5 and 6):
both side-by-side figures lit alike, a contact shadow under the feet, the whole treadmill and a
body filling the frame, no floor edge, and the belt at the protocol's speed on every body.
Frames are small (320×180, a few frames) so the file runs in well under a minute."""

from __future__ import annotations

import numpy as np
import pytest

EXP1_CAMERA = (35.0, 10.0, 4.0, 40.0)    # azimuth, elevation, distance, vertical fov (the protocols)
EXP2_CAMERA = (20.0, 10.0, 5.0, 45.0)


@pytest.fixture(scope="module")
def heavy():
    from stimuli.bodies import fit_body

    return fit_body("M", 1.83, 35.8)     # M_Hi2, the largest body of Exp 1


@pytest.fixture(scope="module")
def short():
    from stimuli.bodies import fit_body

    return fit_body("F", 1.60, 19.5)     # F_Lo2, the shortest and leanest


def _look(layout, camera, width=320, height=180, duration=0.2, background="#ffffff", floor=True):
    from stimuli.render.clip import Look

    azimuth, elevation, distance, fov = camera
    return Look(layout, width, height, 15, duration, azimuth, elevation, distance, fov, background, floor=floor)


def _figures(body, look, n, amplitude=1.0, speed=0.0):
    from stimuli.render.clip import Figure
    from stimuli.render.procedural import stepping_pose

    rot, root = stepping_pose(body, look.n_frames, cycles=1, amplitude=amplitude)
    return [Figure(body, rot, root, speed) for _ in range(n)]


def _frames(look, figures):
    from stimuli.render.clip import render_frames

    return np.stack(list(render_frames(look, figures))).astype(int)


# -- item 1: lighting --------------------------------------------------------------------------------

def test_side_by_side_figures_are_lit_alike(heavy):
    """The same motion in both slots: the figures' grey levels agree within 1 (the lights used to stay
    put while each figure turned ±20° to face the camera: 115.1 vs 120.9 mean, 115 vs 122 median)."""
    look = _look("side_by_side", EXP2_CAMERA, background="#00ff00", floor=False)
    frames = _frames(look, _figures(heavy, look, 2))
    grey = np.abs(frames[..., 1] - frames[..., 0]) <= 2      # the body is grey, the background green
    luminance = frames.mean(axis=-1)
    half = frames.shape[2] // 2
    sides = [luminance[:, :, :half][grey[:, :, :half]], luminance[:, :, half:][grey[:, :, half:]]]
    assert min(len(s) for s in sides) > 2000, "both figures are in the picture"
    assert abs(sides[0].mean() - sides[1].mean()) <= 1.0
    assert abs(np.median(sides[0]) - np.median(sides[1])) <= 1.0


# -- item 5: grounding and framing -----------------------------------------------------------------

def _body_rows(body, look, figures):
    """Rows the body's skinned vertices reach over the clip, every slot (top, bottom)."""
    from stimuli.render.clip import apply_pose, centred_root, placements

    poses, view = placements(look, len(figures), body.anthropometry.height_m)
    rows = []
    for figure, pose in zip(figures, poses):
        vertices = body.skin(figure.rotations, centred_root(figure)).reshape(-1, 3)
        rows.append(view.project(apply_pose(pose, vertices))[:, 1])
    rows = np.concatenate(rows)
    return rows.min(), rows.max()


@pytest.mark.parametrize("layout, camera, n", [("treadmill", EXP1_CAMERA, 1), ("side_by_side", EXP2_CAMERA, 2)])
def test_body_fills_the_frame_and_the_treadmill_is_whole(short, heavy, layout, camera, n):
    """The shortest body fills >= 60 % of the frame's height (Exp 2 showed ~45 %), and the treadmill
    does not touch the frame's edges (Exp 1's near end was cut by the bottom edge)."""
    look = _look(layout, camera)
    for body in (short, heavy):
        figures = _figures(body, look, n)
        top, bottom = _body_rows(body, look, figures)
        fill = (bottom - top) / look.height
        assert fill >= 0.60, f"{body.body_id}: the body spans {fill:.0%} of the frame's height"
        assert top > 2, "the head is not cut either"
        frame = _frames(look, figures)[0]
        dark = frame.mean(axis=-1) < 150      # treadmill (and body shadow side); the floor is >= 190, sky 255
        edges = np.concatenate([dark[0], dark[-1], dark[:, 0], dark[:, -1]])
        assert not edges.any(), f"{body.body_id}: {edges.sum()} dark pixels on the frame's edges"


@pytest.mark.parametrize("layout, camera, n", [("treadmill", EXP1_CAMERA, 1), ("side_by_side", EXP2_CAMERA, 2)])
def test_floor_has_no_edge_above_the_checkerboard(layout, camera, n):
    """Above the checkerboard (farther than 17 m) the floor melts into the background: no step
    between neighbouring rows exceeds 2 grey levels (the square floor's far edge was a tilted line,
    a step of ~37 levels from its grey to the white background)."""
    from stimuli.render.clip import placements
    from stimuli.render.scene import Stage
    from stimuli.render.treadmill import DECK_HEIGHT_M

    look = _look(layout, camera, width=640, height=360)
    _, view = placements(look, n, 1.75)
    stage = Stage(view)
    stage.add_checker_floor(np.zeros(3), -DECK_HEIGHT_M)
    frame = stage.render().astype(int)
    ahead = -view.pose[:3, 2] * np.array([1.0, 0.0, 1.0])
    far = 17.0 * ahead / np.linalg.norm(ahead) + [0.0, -DECK_HEIGHT_M, 0.0]
    row = int(np.floor(view.project(far)[1]))
    assert 5 < row < look.height, "the far floor is in the picture (the test measures something)"
    steps = np.abs(np.diff(frame[:row], axis=0)).max()
    assert steps <= 2, f"a step of {steps} grey levels between rows above row {row}"


def test_contact_shadow_darkens_the_belt_under_the_feet(short, monkeypatch):
    """With the contact shadow the belt under the standing figure is clearly darker than without;
    away from the figure (the belt's ends) nothing changes."""
    from stimuli.render import treadmill

    look = _look("treadmill", EXP1_CAMERA)
    figures = _figures(short, look, 1, amplitude=0.0)
    shaded = _frames(look, figures)[0].mean(axis=-1)
    monkeypatch.setattr(treadmill, "CONTACT_SHADOW", 0.0)
    plain = _frames(look, figures)[0].mean(axis=-1)
    darker = plain - shaded
    assert (darker >= -0.5).all(), "the shadow only darkens"
    assert (darker > 5).sum() > 150, "a visible patch of belt is darker"
    ys, xs = np.nonzero(darker > 5)
    from stimuli.render.clip import placements

    _, view = placements(look, 1, short.anthropometry.height_m)
    feet = view.project(np.zeros(3))             # the figure stands over the slot's origin
    assert abs(np.median(xs) - feet[0]) < 20 and abs(np.median(ys) - feet[1]) < 20, "under the figure"


# -- item 6: belt speed ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def exp1():
    from pathlib import Path

    from stimuli.protocol import load_protocol

    return load_protocol(Path(__file__).resolve().parents[1] / "protocols" / "exp1_shape_motion.yaml")


@pytest.mark.parametrize("gait", ["walk", "jog"])
def test_belt_runs_at_the_protocols_speed_on_every_body(exp1, gait):
    """Lean and heavy, short and tall bodies (own motion and a swapped one): the belt runs at the
    protocol's speed within 0.1 % (it ran 1.30–1.39 m/s walking, 2.41–2.58 jogging, by body), and the
    feet ride the belt: few frame pairs skate relative to it (HUMOS skate)."""
    from stimuli.motion.loop import cycles_for_clip
    from stimuli.motion.metrics import foot_joints, skate_humos
    from stimuli.render.clip import Look
    from stimuli.render.sources import _generated, actor_motion, body_of, on_rig
    from stimuli.render.timing import belt_matched_speed

    look = Look("treadmill", 320, 180, exp1.clip.fps, exp1.clip.duration_s)
    spec = exp1.gaits[gait]
    for body_actor, motion_actor in (("F_Lo2", "F_Lo2"), ("M_Hi2", "M_Hi2"), ("M_Hi2", "F_Lo2"), ("F_Hi1", "M_Lo1")):
        body = body_of(exp1, body_actor)
        _, _, belt = actor_motion(exp1, motion_actor, gait, body, look)
        assert belt == pytest.approx(spec.speed_mps, rel=0.001), f"{body_actor} with {motion_actor}'s {gait}"
        actor = next(a for a in exp1.actors if a.id == motion_actor)
        args = (gait, spec.cadence_spm)
        rest = (exp1.seed, float(look.fps), cycles_for_clip(look.duration_s, spec.cadence_spm))
        matched = belt_matched_speed(spec.speed_mps, spec.cadence_spm, rest[2], rest[1], actor.height_m, body,
                                     look.duration_s)
        shown = on_rig(_generated(actor.model_dump_json(), *args, matched, *rest), body)
        skate = skate_humos(foot_joints(shown), shown.fps, shown.metadata["belt_speed_mps"])
        assert skate <= 5.0, f"{body_actor} with {motion_actor}'s {gait}: {skate:.1f} % of frame pairs skate"


def test_a_generated_gait_is_made_once_per_clip(exp1, monkeypatch):
    """The speed that keeps the belt at the protocol's comes from the skeleton and the loop's frame
    count (timing.belt_matched_speed), not from a probe gait generated first at the protocol's speed;
    the generator's own leg length reads what the rest skeleton gives, within 0.07 %."""
    from stimuli.motion import style
    from stimuli.motion.generate import generated_leg_length
    from stimuli.motion.skeleton import leg_length
    from stimuli.render import sources
    from stimuli.render.clip import Look

    made = []
    real = style.actor_gait
    monkeypatch.setattr(style, "actor_gait", lambda *a, **k: made.append(a[1]) or real(*a, **k))
    sources._generated.cache_clear()
    look = Look("treadmill", 320, 180, exp1.clip.fps, exp1.clip.duration_s)
    sources.actor_motion(exp1, "F_Hi1", "jog", sources.body_of(exp1, "M_Lo2"), look)
    sources._generated.cache_clear()
    assert made == ["jog"]
    actor = next(a for a in exp1.actors if a.id == "F_Hi1")
    for gait, spec in exp1.gaits.items():
        motion = real(actor, gait, spec.cadence_spm, spec.speed_mps, exp1.seed, 30.0, 4)
        assert leg_length(motion) == pytest.approx(generated_leg_length(actor.height_m), rel=7e-4)


def _protocol(name):
    from pathlib import Path

    return Path(__file__).resolve().parents[1] / "protocols" / f"{name}.yaml"


def _with_camera(tmp_path, name, camera):
    import yaml

    data = yaml.safe_load(_protocol(name).read_text())
    data["clip"]["camera"] = camera
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_validate_warns_that_the_framing_rule_replaces_a_given_distance(tmp_path, run_cli):
    """camera.distance_m given for a treadmill or side-by-side layout: validate says it is not used and
    what the framing rule uses instead; the bundled protocols (which leave it out) and a row layout
    (where it is used) get no such warning."""
    for name in ("exp1_shape_motion", "exp2_com_vs_average"):
        code, out, _ = run_cli("validate", _with_camera(tmp_path, name, {"azimuth_deg": 35, "distance_m": 6.0}))
        lines = [line for line in out.splitlines() if line.startswith("warning: clip.camera.distance_m")]
        assert code == 0 and len(lines) == 1, out
        layout = "treadmill" if name.startswith("exp1") else "side_by_side"
        assert f"6 m is not used on the {layout} layout" in lines[0] and "leave distance_m out" in lines[0]
        low, high = (float(x) for x in lines[0].split(" m from the body")[0].split(", ")[-1].split("–"))
        assert 2.0 < low < high < 5.0    # the shortest and the tallest actor's framed distance
    for name in ("exp1_shape_motion", "exp2_com_vs_average", "thesis_mesh"):
        code, out, _ = run_cli("validate", _protocol(name))
        assert code == 0 and "clip.camera.distance_m" not in out, name
    code, out, _ = run_cli("validate", _with_camera(tmp_path, "thesis_mesh", {"distance_m": 8.0, "fov_deg": 18}))
    assert code == 0 and "clip.camera.distance_m" not in out


def test_same_protocol_and_seed_give_the_same_clip_bytes(tmp_path):
    """Two renders of the same Exp-1 clip (the heaviest body's jog: its arms are cleared frame by frame),
    the gait generated afresh each time, give the same SHA-256 (the draw order that makes other
    processes agree: test_render_scene)."""
    from stimuli.render import sources
    from stimuli.render.manifest import read_manifest
    from stimuli.render.pipeline import render_protocol

    shas = []
    for run in ("a", "b"):
        sources._generated.cache_clear()
        render_protocol(_protocol("exp1_shape_motion"), tmp_path / run, resolution="160x90", fps=10,
                        only="M-jog-Hi2-Hi2", workers=1, progress=False, sheet=False)
        shas.append({sid: row["sha256"] for sid, row in read_manifest(tmp_path / run).items()})
    assert len(shas[0]) == 1 and shas[0] == shas[1]
