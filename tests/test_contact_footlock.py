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
