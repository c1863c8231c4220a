"""Plausibility metrics on motions whose true values are known (stimuli.motion.metrics).

Each definition (HUMOS/GMD skate, PhysDiff/PHC slip, Penetrate, Float, dynamic stability) is
checked on synthetic motions built so that the answer is known in advance, then on the bundled
CMU walk, which a sound metric must find plausible.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from stimuli.motion import metrics as M
from stimuli.motion.generate import GaitParams, generate
from stimuli.motion.metrics import plausibility_from_joints

ROOT = Path(__file__).resolve().parents[1]
WALK = ROOT / "stimuli" / "data" / "cmu_35_01_walk.bvh"


def sliding_foot(fps: float, speed: float, height: float, seconds: float = 2.0) -> np.ndarray:
    """T×1×3: one foot joint moving forward (+z) at ``speed`` m/s, ``height`` m above the floor."""
    t = np.arange(int(round(seconds * fps)) + 1) / fps
    return np.stack([np.zeros_like(t), np.full_like(t, height), speed * t], axis=1)[:, None]


@pytest.fixture(scope="module")
def standing():
    """The generator's skeleton in its rest pose (upright, feet side by side) for 2 s at 30 fps,
    its lowest point on the floor."""
    walk = generate(GaitParams(gait="walk", cadence_spm=112, speed_mps=1.2), height_m=1.75, fps=30, cycles=1)
    n = 60
    rot = np.zeros((n, walk.n_joints, 4))
    rot[..., 0] = 1.0
    root = np.tile([0.0, -walk.rest_positions()[:, 1].min(), 0.0], (n, 1))
    meta = {k: v for k, v in walk.metadata.items() if k not in ("looped", "treadmill", "belt_speed_mps", "contacts")}
    still = walk.replace(rotations=rot, root_translation=root)
    still.metadata = {**meta, "looped": False}
    return still


def shifted(motion, dy: float = 0.0, vz: float = 0.0):
    """``motion`` raised by ``dy`` m and carried forward at ``vz`` m/s."""
    root = motion.root_translation.copy()
    root[:, 1] += dy
    root[:, 2] += vz * np.arange(motion.n_frames) / motion.fps
    return motion.replace(root_translation=root)


@pytest.mark.parametrize("fps", [30.0, 60.0, 120.0])
def test_resampling_to_20_fps_keeps_time_and_position(fps):
    """A point moving at 1 m/s sampled at 30/60/120 fps is 5 cm further each 20-fps frame, at the
    times HumanML3D's 20 fps would have sampled it; 2 s give 41 frames."""
    p = M.resample_points(sliding_foot(fps, 1.0, 0.0), fps)
    assert p.shape == (41, 1, 3)
    assert np.allclose(p[:, 0, 2], np.arange(41) / 20.0, atol=1e-12)


@pytest.mark.parametrize("fps", [30.0, 60.0, 120.0])
def test_humos_skate_of_a_foot_sliding_on_the_floor(fps):
    """GMD/HUMOS: foot joint below 5 cm and faster than 0.5 m/s in the pair and its 5-pair mean."""
    assert M.skate_humos(sliding_foot(fps, 1.0, 0.03), fps) == 100.0
    assert M.skate_humos(sliding_foot(fps, 0.4, 0.03), fps) == 0.0      # slower than 0.5 m/s
    assert M.skate_humos(sliding_foot(fps, 1.0, 0.06), fps) == 0.0      # above 5 cm: swinging
    # On a belt running at 1 m/s towards −z, a foot carried back at 1 m/s stands still on it.
    assert M.skate_humos(sliding_foot(fps, -1.0, 0.03), fps, belt_speed=1.0) == 0.0
    # Sliding during the first second only: 20 of the 40 pairs at 20 fps, less the pairs whose
    # 5-pair mean falls to 0.6 m/s or below at the end of the slide (GMD's window): 19–20.
    foot = sliding_foot(fps, 1.0, 0.03)
    half = len(foot) // 2
    foot[half:, 0, 2] = foot[half, 0, 2]
    assert 100 * 19 / 40 <= M.skate_humos(foot, fps) <= 100 * 20 / 40


@pytest.mark.parametrize("fps", [30.0, 60.0, 120.0])
def test_phc_slip_of_a_foot_sliding_on_the_floor(fps):
    """0.4 m/s on the floor is 20 mm per 20-fps frame, whatever the clip's own rate; a foot 2 cm up
    does not touch (no contact pair: 0)."""
    assert M.skate_slip_mm(sliding_foot(fps, 0.4, 0.0), fps) == pytest.approx(20.0, abs=1e-9)
    assert M.skate_slip_mm(sliding_foot(fps, 0.4, 0.02), fps) == 0.0


def test_standing_pose_is_stable_and_on_the_floor(standing):
    q = plausibility_from_joints(standing)
    assert q["unstable_pct"] == 0.0 and q["stability_flight_pct"] == 0.0, q
    assert q["penetrate_mm"] == pytest.approx(0.0, abs=1e-6) and q["float_mm"] == pytest.approx(0.0, abs=1e-6), q
    assert q["skate_humos_pct"] == 0.0 and q["skate_phc_mm"] == pytest.approx(0.0, abs=1e-9), q


def test_float_and_penetrate_of_a_raised_and_a_sunk_pose(standing):
    """Lifted by 2 cm: Float 20 mm, no contact (the slip has no pair to measure); sunk by 1 cm:
    Penetrate 10 mm on every frame, Float 0."""
    up = plausibility_from_joints(shifted(standing, dy=0.02))
    assert up["float_mm"] == pytest.approx(20.0, abs=1e-6) and up["penetrate_mm"] == 0.0, up
    down = plausibility_from_joints(shifted(standing, dy=-0.01))
    assert down["penetrate_mm"] == pytest.approx(10.0, abs=1e-6), down
    assert down["penetrate_max_mm"] == pytest.approx(10.0, abs=1e-6) and down["float_mm"] == 0.0, down
    # The earlier names carry the same figures.
    assert up["float_cm"] == pytest.approx(2.0) and down["penetrate_cm"] == pytest.approx(1.0)


def test_a_standing_pose_slid_over_the_floor_skates_on_every_definition(standing):
    """The whole pose carried forward at 1 m/s, feet on the floor: every pair skates (HUMOS), each
    touching sole point slips 50 mm per 20-fps frame (PhysDiff/PHC)."""
    q = plausibility_from_joints(shifted(standing, vz=1.0))
    assert q["skate_humos_pct"] == 100.0 and q["skate_pct"] == 100.0, q
    assert q["skate_phc_mm"] == pytest.approx(50.0, abs=1e-6), q


def test_stability_counts_a_zmp_outside_the_feet_and_flight_apart():
    """A still point mass over a 20 cm square foot: stable; 10 cm beyond its edge: unstable on every
    frame; the same foot 30 cm in the air: flight, not unstable."""
    square = np.array([[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [0.2, 0.0, 0.2], [0.0, 0.0, 0.2]])
    foot = np.tile(square, (30, 1, 1))
    masses = np.array([1.0])
    inside = np.tile([[0.1, 1.0, 0.1]], (30, 1, 1))
    outside = np.tile([[0.3, 1.0, 0.1]], (30, 1, 1))
    assert M.dynamic_stability({"l": foot}, inside, masses, 30.0) == {"unstable_pct": 0.0, "stability_flight_pct": 0.0}
    assert M.dynamic_stability({"l": foot}, outside, masses, 30.0)["unstable_pct"] == 100.0
    # 1.5 cm beyond the edge is inside the 2 cm tolerance.
    near = np.tile([[0.215, 1.0, 0.1]], (30, 1, 1))
    assert M.dynamic_stability({"l": foot}, near, masses, 30.0)["unstable_pct"] == 0.0
    airborne = foot + [0.0, 0.3, 0.0]
    moving = airborne + (np.arange(30) / 30.0 * 2.0)[:, None, None] * [0.0, 0.0, 1.0]   # 2 m/s: not planted
    flight = M.dynamic_stability({"l": moving, "r": foot + [0.0, 0.0, 0.0]}, inside, masses, 30.0)
    assert flight["unstable_pct"] == 0.0
    only_air = M.dynamic_stability({"l": moving}, inside, masses, 30.0)
    assert only_air["stability_flight_pct"] == 100.0 and np.isnan(only_air["unstable_pct"])


def test_zmp_of_an_accelerating_mass_moves_against_the_acceleration():
    """A point mass 1 m up accelerating at 1 m/s² forward has its ZMP 1/9.81 m behind it."""
    t = np.arange(121) / 60.0
    x = 0.5 * 1.0 * t**2
    pts = np.stack([np.zeros_like(t), np.ones_like(t), x], axis=1)[:, None]
    z = M.zmp_multibody(pts, np.array([1.0]), 60.0)
    mid = slice(30, 90)   # away from the filter's edges
    assert np.allclose(x[mid] - z[mid, 2], 1.0 / M.GRAVITY, atol=1e-3)


def test_the_bundled_cmu_walk_is_plausible():
    """The real capture, as imported: no HUMOS skate, a stable walk (well under 50 % of its supported
    frames), almost no flight; looped for the treadmill it stays under 50 % too."""
    from stimuli.motion.bvh import read_bvh
    from stimuli.motion.loop import make_loop

    walk = read_bvh(WALK)
    q = plausibility_from_joints(walk)
    assert q["skate_humos_pct"] <= 5.0 and q["unstable_pct"] < 30.0 and q["stability_flight_pct"] < 5.0, q
    loop = plausibility_from_joints(make_loop(walk))
    assert loop["skate_humos_pct"] <= 5.0 and loop["unstable_pct"] < 50.0, loop


def test_metrics_cli_writes_the_new_fields(tmp_path, capsys):
    from stimuli.cli import main

    walk = generate(GaitParams(gait="walk", cadence_spm=112, speed_mps=1.2), height_m=1.75, fps=30, cycles=2)
    walk.save(tmp_path / "w.npz")
    assert main(["motion", "metrics", str(tmp_path / "w.npz"), "--json", str(tmp_path / "q.json")]) == 0
    q = json.loads((tmp_path / "q.json").read_text())
    for key in ("skate_humos_pct", "skate_phc_mm", "penetrate_mm", "penetrate_max_mm", "float_mm", "unstable_pct",
                "stability_flight_pct", "skate_pct", "dynamically_unstable_pct"):
        assert isinstance(q[key], float), key
    assert q["skate_humos_pct"] <= 5.0 and q["unstable_pct"] < 50.0, q
