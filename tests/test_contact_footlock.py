"""The one foot-contact model (stimuli/motion/contact.py): height and speed over the ground with
hysteresis, every constant in seconds, so 30, 60 and 120 fps of one motion give the same contacts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from stimuli.motion.bvh import read_bvh
from stimuli.motion.contact import contact_mask, foot_contacts, min_durations, runs
from stimuli.motion.generate import GaitParams, generate

DATA = Path(__file__).resolve().parents[1] / "stimuli" / "data"


@pytest.fixture(scope="module")
def cmu_walk():
    return read_bvh(DATA / "cmu_35_01_walk.bvh")   # captured at 120 fps


def _intervals_s(motion):
    """Contact runs per foot in seconds, from the motion's own frame rate."""
    c = foot_contacts(motion)
    return {s: [(a / motion.fps, b / motion.fps) for a, b in runs(c.down[s])] for s in "lr"}


def test_contacts_are_the_same_at_30_60_and_120_fps(cmu_walk):
    ref = _intervals_s(cmu_walk.resample(120.0))
    assert all(len(v) >= 2 for v in ref.values()), ref
    for fps in (30.0, 60.0):
        got = _intervals_s(cmu_walk.resample(fps))
        for s in "lr":
            assert len(got[s]) == len(ref[s]), (fps, s, got[s], ref[s])
            # Starts and ends agree to within one frame of the coarser rate.
            err = np.abs(np.array(got[s]) - np.array(ref[s])).max()
            assert err <= 1.0 / fps + 1e-9, (fps, s, got[s], ref[s])


def _foot(height, z):
    """One foot's sole points (T×2×3): heel and ball 15 cm apart, at ``height`` above the floor."""
    heel = np.stack([np.zeros_like(z), height, z], 1)
    return np.stack([heel, heel + [0.0, 0.0, 0.15]], 1)


@pytest.mark.parametrize("fps", [30.0, 60.0, 120.0])
def test_a_foot_travelling_on_the_floor_leaves_contact(fps):
    """A start-walk-stop capture's foot read "in contact" for 3.5 s while it travelled 3.4 m (gait
    events assume steady walking): a foot sliding at 1.2 m/s on the floor is out of contact."""
    t = np.arange(int(2.0 * fps)) / fps
    z = np.where(t < 0.5, 0.0, (t - 0.5) * 1.2)
    down = contact_mask(_foot(np.zeros_like(t), z), fps)
    assert down[t < 0.45].all()
    assert not down[t > 0.55].any()


def test_hysteresis_keeps_a_foot_down_that_grazes_the_threshold():
    """A planted foot whose lowest point wobbles 2.5–3.5 cm (mesh noise, a rolling heel) stays in
    contact: it left only above the leave height, 5 cm."""
    fps = 60.0
    t = np.arange(120) / fps
    h = 0.03 + 0.005 * np.sin(2 * np.pi * 4 * t)
    down = contact_mask(_foot(h, np.zeros_like(t)), fps)
    assert down[t >= 0.2].all()          # down from its first dip below 3 cm (at 0.19 s) on
    lifted = contact_mask(_foot(np.where(t > 1.0, 0.08, h), np.zeros_like(t)), fps)
    assert not lifted[t > 1.05].any()


@pytest.mark.parametrize("fps", [30.0, 120.0])
def test_short_blips_are_dropped_and_short_gaps_bridged_in_seconds(fps):
    n = int(fps)
    m = np.zeros(n, bool)
    m[n // 4: n // 4 + max(1, int(0.03 * fps))] = True          # a 30 ms touch: noise
    m[n // 2:] = True
    m[n // 2 + int(0.2 * fps): n // 2 + int(0.2 * fps) + max(1, int(0.03 * fps))] = False   # a 30 ms gap
    out = min_durations(m, fps)
    assert not out[: n // 2].any() and out[n // 2:].all()


def test_the_generated_walk_has_the_generators_own_stance_phases():
    walk = generate(GaitParams(), 1.75)
    c = foot_contacts(walk)
    for s in "lr":
        stance = np.asarray(walk.metadata["contacts"][s], bool)
        assert np.mean(c.down[s] == stance) >= 0.95, s
    assert c.belt_speed == pytest.approx(walk.metadata["belt_speed_mps"])


def test_a_looped_clip_wraps_its_contacts():
    """Rolling a loop rolls its contacts: a contact over the seam is one contact, not two cut ones."""
    walk = generate(GaitParams(), 1.75)
    k = walk.n_frames // 3
    rolled = walk.replace(rotations=np.roll(walk.rotations, k, axis=0),
                          root_translation=np.roll(walk.root_translation, k, axis=0))
    a, b = foot_contacts(walk), foot_contacts(rolled)
    for s in "lr":
        assert np.array_equal(np.roll(a.down[s], k), b.down[s]), s


def test_pivot_is_the_lowest_point_while_down(cmu_walk):
    c = foot_contacts(cmu_walk.resample(30.0))
    for s in "lr":
        assert np.all((c.pivot[s] >= 0) == c.down[s])
        d = c.down[s]
        lowest = np.argmin(c.points[s][..., 1], axis=1)
        assert np.array_equal(c.pivot[s][d], lowest[d])


# ---------------------------------------------------------------------------- whole-clip foot locking
mink = pytest.importorskip("mink")   # noqa: E402  (the solve's IK library; the contact model needs none)

from stimuli.motion import quat  # noqa: E402
from stimuli.motion.footfix import lock_feet  # noqa: E402
from stimuli.motion.metrics import knee_angles  # noqa: E402


@pytest.fixture(scope="module")
def walk():
    return generate(GaitParams(), 1.75)


def _slid(walk, amplitude=0.05):
    """The walk with its pelvis surging fore and aft twice per clip: planted feet slide ~1 cm a frame."""
    t = np.arange(walk.n_frames) / walk.n_frames
    root = walk.root_translation.copy()
    root[:, 2] += amplitude * np.sin(2 * np.pi * 2 * t)
    return walk.replace(root_translation=root)


def _stance_slip_mm(motion, contacts):
    """Largest frame-to-frame horizontal travel (mm, over the belt) of a planted foot's stillest sole
    point, over pairs of frames both in contact but the last pair of each contact: at toe off the
    generated walk's straight trailing leg reaches its pinned toe tip only to 3.8 mm (the solve
    reports it as ``pin_error_max_mm``)."""
    from stimuli.motion.footfix import sole_points, sole_positions
    grot, gpos = motion.global_transforms()
    pts = sole_points(motion)
    worst = 0.0
    for s in "lr":
        p = sole_positions(grot, gpos, pts[s])
        step = np.diff(p, axis=0)
        step[..., 2] += contacts.belt_speed / motion.fps
        travel = np.linalg.norm(step[..., [0, 2]], axis=-1).min(axis=1)
        down = contacts.down[s]
        both = down[:-1] & down[1:] & np.roll(down, -2)[:-1]
        worst = max(worst, 1000.0 * float(travel[both].max()))
    return worst


def test_a_sliding_foot_is_pinned_and_joints_change_little(walk):
    contacts = foot_contacts(walk)
    slid = _slid(walk)
    assert _stance_slip_mm(slid, contacts) > 8.0          # the surge slides the planted feet
    locked = lock_feet(slid, contacts)
    assert _stance_slip_mm(locked, contacts) < 2.0
    assert locked.metadata["pin_error_max_mm"] < 5.0
    assert locked.metadata["joint_change_max_deg"] < 30.0
    assert locked.metadata["joint_change_rms_deg"] < 8.0
    assert locked.n_frames == walk.n_frames and np.isfinite(locked.rotations).all()


def test_a_non_looped_clip_keeps_its_ends(walk):
    """No wrap-around: a clip that is not a loop is solved once in time order; its first and last
    frames change no faster than the source does."""
    clip = _slid(walk).slice(5, walk.n_frames - 7)
    clip.metadata["looped"] = False
    locked = lock_feet(clip, foot_contacts(clip))
    for s, k in knee_angles(locked).items():
        k0 = knee_angles(clip)[s]
        for a, b in ((k[:4], k0[:4]), (k[-4:], k0[-4:])):
            assert np.abs(np.diff(a)).max() <= np.abs(np.diff(b)).max() + 6.0, s
    assert locked.metadata["joint_change_max_deg"] < 30.0


def test_knees_stay_within_their_limit(walk):
    """A source knee bent past 160° is brought back to 160°."""
    from stimuli.motion.footfix import KNEE_LIMIT_DEG
    from stimuli.motion.skeleton import role_indices
    knee = role_indices(walk)["l_knee"]
    src = walk.copy()
    bend = quat.from_axis_angle(np.array([np.radians(175.0), 0.0, 0.0]))
    src.rotations[10:14, knee] = quat.mul(src.rotations[10:14, knee], bend)
    src = src.replace()
    before = knee_angles(src)["l"]
    assert before.max() > KNEE_LIMIT_DEG
    after = knee_angles(lock_feet(src, foot_contacts(walk)))["l"]
    assert after.max() <= KNEE_LIMIT_DEG + 0.5


@pytest.mark.slow
def test_the_cmu_walk_on_a_body_with_the_foot_lock():
    """Needs stimuli.bodies (a fitted Anny body): Skate (HUMOS) ≤ 5 %, Penetrate and Float ≤ 10 mm."""
    from stimuli.bodies import fit_body
    from stimuli.motion.loop import make_loop
    from stimuli.motion.quality import motion_quality
    from stimuli.motion.retarget import retarget
    body = fit_body("M", 1.80, 27.0)
    src = make_loop(read_bvh(DATA / "cmu_35_01_walk.bvh"), cycles=2).resample(30.0)
    src.metadata["looped"] = True
    m = retarget(src, body, foot_lock=True)
    q = motion_quality(m, body)
    assert q["skate_humos_pct"] <= 5.0 and q["penetrate_mm"] <= 10.0 and q["float_mm"] <= 10.0, q
    # Today's clean-up before the lock already turns the feet flat in mid-stance (~84° on this
    # capture's rig, whose retargeted feet point down); the lock adds little.
    assert m.metadata["pin_error_max_mm"] < 10.0, m.metadata


@pytest.mark.slow
def test_motion_retarget_prints_the_joint_change(tmp_path, capsys):
    """Needs stimuli.bodies. The CLI says how far the clean-up (and the lock) moved the joints."""
    from stimuli.cli import main
    from stimuli.motion import Motion
    walk = generate(GaitParams(), 1.75)
    walk.save(tmp_path / "w.npz")
    assert main(["motion", "retarget", str(tmp_path / "w.npz"), "--body", "sex=M,height=1.8,bmi=27",
                 "--foot-lock", "--out", str(tmp_path / "r.npz")]) == 0
    err = capsys.readouterr().err
    meta = Motion.load(tmp_path / "r.npz").metadata
    assert f"largest {meta['joint_change_max_deg']:.1f}°" in err and meta["foot_locked"]


def test_a_creeping_foot_gets_its_footprint_where_it_is_on_average():
    """A capture's planted foot that creeps 5 cm forward over its contact: anchored where it landed
    (the generator's footprints) the whole creep is corrected at toe off; centred (a capture's) the
    correction is shared, its mean over the contact zero, the same shape either way."""
    from stimuli.motion.footfix import contact_targets

    t_n, fps = 40, 30.0
    contact = np.zeros(t_n, bool)
    contact[10:30] = True
    ankle = np.zeros((t_n, 3))
    ankle[:, 1] = 0.08
    ankle[:, 2] = np.interp(np.arange(t_n), [10, 29], [0.0, 0.05])
    sole = ankle[:, None, :] + np.array([[0.0, -0.08, -0.05], [0.0, -0.08, 0.12], [0.0, -0.08, 0.18]])
    kept, _, _ = contact_targets(sole, ankle, contact, np.zeros(3), fps, cyclic=False)
    centred, _, _ = contact_targets(sole, ankle, contact, np.zeros(3), fps, cyclic=False, centre=True)
    kept_fix, centred_fix = (kept - ankle)[contact, 2], (centred - ankle)[contact, 2]
    assert kept_fix[0] == pytest.approx(0.0, abs=1e-12) and kept_fix[-1] == pytest.approx(-0.05)
    assert centred_fix.mean() == pytest.approx(0.0, abs=1e-12)
    assert centred_fix[0] == pytest.approx(0.025) and centred_fix[-1] == pytest.approx(-0.025)
    assert np.allclose(centred_fix - centred_fix[0], kept_fix)
