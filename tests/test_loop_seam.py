"""Looped motions stay seamless on the bodies: the clean-up's swing toe lift decides smoothly.

The rendered Exp-1 clips hold the number of gait cycles that fills 4 s (walk 4, jog 5:
``cycles_for_clip``). Retargeted onto their bodies, two of those 4-cycle walks jumped at the
seam (seam ratio 1.89 for F_Hi2, 2.23 for F_Lo2; 1.02 / 0.70 before retargeting): in the last
frame before heel strike ``footfix.lift_toes`` turned the toes up by its full 15° for 0.06 mm
of heel clearance — the heel, already the foot's lowest point, dips as the toes come up and
rises again, and the old rule took the best turn of the whole range. The same flip pitched the
women's walking feet 30–36° in one frame inside the clips.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from stimuli.motion import quat
from stimuli.motion.footfix import cap_landing_turn, lift_toes, offsets_of


def _lift(offsets, ankle_y, floor):
    foot = lift_toes(np.array([[0.0, ankle_y, 0.0]]), np.array([[1.0, 0, 0, 0]]), np.array([offsets]),
                     np.array([floor]), np.array([True]))
    turn = np.degrees(2 * np.arccos(np.clip(abs(foot[0, 0]), 0.0, 1.0)))
    low = ankle_y + offsets_of(foot, np.array([offsets]))[0, :, 1].min()
    return turn, low


def test_toe_lift_does_not_turn_a_lowest_heel_for_nothing():
    """Heel (1 cm behind, 8 cm below the ankle) lowest: turning the toes up lowers it until it is
    under the ankle (7°), and at 15° it is 0.1 mm higher than unturned. No turn."""
    heel_lowest = [[0.0, -0.08, -0.01], [0.0, -0.03, 0.15]]
    turn, low = _lift(heel_lowest, 0.095, 0.02)
    assert turn < 1e-6 and low == pytest.approx(0.015)


def test_toe_lift_still_turns_for_a_clear_gain():
    """A toe tip just behind the point under the ankle (toes pointing down at toe off) dips a
    fraction of a millimetre before rising: the full turn that lifts it 3.6 mm is still taken."""
    toes_down = [[0.0, -0.02, -0.08], [0.0, -0.12, -0.002]]
    turn, low = _lift(toes_down, 0.14, 0.03)
    assert turn == pytest.approx(15.0, abs=0.01) and low > 0.023


def test_toe_lift_takes_the_least_turn_that_clears():
    toes_down = [[0.0, -0.02, -0.05], [0.0, -0.12, 0.12]]
    turn, low = _lift(toes_down, 0.12, 0.02)
    assert 0.0 < turn < 15.0 and 0.0195 < low < 0.0215


def _largest_pitch_step(motion, joints) -> float:
    """Largest one-frame change (degrees, around the loop) of the feet's pitch."""
    grot, _ = motion.global_transforms()
    out = 0.0
    for name in joints:
        fwd = quat.rotate(grot[:, motion.joint_names.index(name)], np.array([0.0, 0.0, 1.0]))
        pitch = np.degrees(np.arctan2(-fwd[:, 1], np.hypot(fwd[:, 0], fwd[:, 2])))
        out = max(out, float(np.abs(np.diff(np.r_[pitch, pitch[:1]])).max()))
    return out


@pytest.fixture(scope="module")
def rendered_loops():
    """Every Exp-1 actor's walk and jog as the renderer makes them (cycles filling the 4-s clip),
    before and after retargeting onto the actor's body."""
    from stimuli.bodies import body_for_actor
    from stimuli.motion.loop import cycles_for_clip
    from stimuli.motion.retarget import retarget
    from stimuli.motion.style import actor_gait
    from stimuli.protocol import load_protocol
    proto = load_protocol(Path(__file__).resolve().parents[1] / "protocols" / "exp1_shape_motion.yaml")
    out = {}
    for actor in [a for a in proto.actors if not a.practice_only]:
        body = body_for_actor(actor)
        for gait, spec in proto.gaits.items():
            cycles = cycles_for_clip(proto.clip.duration_s, spec.cadence_spm)
            motion = actor_gait(actor, gait, spec.cadence_spm, spec.speed_mps, proto.seed, float(proto.clip.fps),
                                cycles)
            out[actor.id, gait, cycles] = (motion, retarget(motion, body))
    return out


@pytest.mark.slow
def test_rendered_loops_are_seamless_on_their_bodies(rendered_loops):
    """All 8 actors × walk (4 cycles) / jog (5 cycles): the seam on the body is as smooth as the
    clip (ratio 0.74–1.09; it was up to 2.23), and the feet pitch no faster than the source's."""
    from stimuli.motion.loop import seam_error

    assert len(rendered_loops) == 16 and {c for _, _, c in rendered_loops} == {4, 5}
    seams = {key: round(seam_error(on_body)["ratio"], 2) for key, (_, on_body) in rendered_loops.items()}
    assert max(seams.values()) < 1.2, {k: v for k, v in seams.items() if v >= 1.2}
    steps = {key: (_largest_pitch_step(source, ("l_ankle", "r_ankle")),
                   _largest_pitch_step(on_body, ("foot.L", "foot.R")))
             for key, (source, on_body) in rendered_loops.items()}
    assert all(on_body < source + 5.0 for source, on_body in steps.values()), steps


def test_toe_lift_fades_out_after_toe_off_instead_of_ending_in_one_frame():
    """A foot leaving the floor toes-down needs its toes lifted for two frames: the lift then fades
    at the given rate through the first half of the swing (the cleaned CMU 35_17 run and 07_12
    walk turned a foot 31° and 39° in one 30-fps frame at toe off, where the captures turn 21°
    and 25°), and the second half keeps its own (none here)."""
    n = 10
    swing = np.ones(n, bool)
    swing[[0, 9]] = False                                        # stance, swing 1-8, stance
    toe_down = np.array([[0.0, -0.02, -0.05], [0.0, -0.12, 0.12]])
    offsets = np.repeat(toe_down[None], n, axis=0)
    ankle = np.tile([0.0, 0.12, 0.0], (n, 1))                    # the toe tip on the floor
    floor = np.zeros(n)
    floor[[1, 2]] = 0.02                                         # 2 cm of clearance wanted, then none
    feet = np.tile([1.0, 0, 0, 0], (n, 1))

    def turns(**kw):
        out = lift_toes(ankle, feet, offsets, floor, swing, **kw)
        return np.degrees(quat.angle(out))

    abrupt, faded = turns(), turns(max_rate=np.radians(3.0))
    assert abrupt[2] > 8 and abrupt[3] == 0                      # ended within one frame
    assert faded[2] == pytest.approx(abrupt[2])
    assert faded[3] == pytest.approx(abrupt[2] - 3) and faded[4] == pytest.approx(abrupt[2] - 6)
    assert np.all(faded[5:] == 0) and faded[0] == 0              # second half and stance untouched


def test_toe_lift_of_a_heel_landing_comes_down_to_none_at_the_rate_before_it_lands():
    """A foot already toes-up 40° before heel strike, its heel under the swing clearance: turning
    the toes up further raises that heel, and the lift was its full amount up to the frame before
    landing, where the clean-up lays the foot flat (CMU 07_02: 41° in one frame, the capture 13°).
    Capped, it is at most the rate times the frames left to the landing."""
    n = 10
    swing = np.ones(n, bool)
    swing[[0, 9]] = False
    foot = np.tile(quat.from_axis_angle(np.array([-np.radians(40.0), 0.0, 0.0])), (n, 1))   # toes up
    local = np.array([[0.0, -0.08, -0.05], [0.0, -0.03, 0.15]])                           # heel, toe tip
    offsets = quat.rotate(foot[:, None], np.repeat(local[None], n, axis=0))
    assert offsets[0, 1, 1] > offsets[0, 0, 1]                   # the toe tip above the heel
    ankle = np.tile([0.0, -offsets[0, 0, 1] + 0.002, 0.0], (n, 1))   # the heel 2 mm over the floor
    floor = np.zeros(n)
    floor[[7, 8]] = 0.008                                        # 8 mm of clearance wanted late in swing
    rate = np.radians(3.0)

    lifted = lift_toes(ankle, foot, offsets, floor, swing, max_rate=rate)
    capped = cap_landing_turn(lifted, foot, swing, rate)

    def turns(feet):
        return np.degrees(quat.angle(quat.mul(feet, quat.inv(foot))))

    assert turns(lifted)[8] > 6                                  # a big turn in the last frame of swing
    assert turns(capped)[8] <= 3 + 1e-9 and turns(capped)[7] <= 6 + 1e-9 and turns(capped)[8] > 0


def test_a_carried_toe_lift_keeps_the_axis_it_had_where_it_was_needed():
    """After toe off the foot turns 30° about the vertical between two frames: the lift carried into
    the second frame turns about the axis it had in the first (recomputed from the new heading, the
    hold-out Poser walk's foot turned 34.6° in one frame where the capture turns 17°)."""
    n = 10
    swing = np.ones(n, bool)
    swing[[0, 9]] = False                                       # the first half of the swing: 1-4
    toe_down = np.array([[0.0, -0.02, -0.05], [0.0, -0.12, 0.12]])
    yaw = np.radians([0.0, 0.0, 0.0] + [30.0] * 7)
    foot = quat.from_axis_angle(np.stack([0 * yaw, yaw, 0 * yaw], -1))
    offsets = quat.rotate(foot[:, None], np.repeat(toe_down[None], n, axis=0))
    ankle = np.tile([0.0, 0.12, 0.0], (n, 1))
    floor = np.zeros(n)
    floor[[1, 2]] = 0.02
    out = lift_toes(ankle, foot, offsets, floor, swing, max_rate=np.radians(3.0))
    turns = quat.mul(out, quat.inv(foot))                       # the lift, in the world
    axis = turns[:, 1:] / np.maximum(np.linalg.norm(turns[:, 1:], axis=1, keepdims=True), 1e-12)
    assert np.degrees(quat.angle(turns[3:4]))[0] > 1          # carried into the turned frame …
    assert np.allclose(axis[3], axis[2], atol=1e-9)             # … about the first frame's axis


def test_the_landing_cap_holds_for_all_passes_together():
    """The clean-up lifts again on each of its passes where the clearance is still short: three
    passes lifted CMU 07_02's toes-up foot 18° in the frames before heel strike, each within its own
    cap. Against the foot before any lift, the turn comes in and goes out at the rate."""
    n = 8
    swing = np.array([False, True, True, True, True, True, True, False])
    unlifted = np.tile(quat.from_axis_angle(np.array([-np.radians(30.0), 0.0, 0.0])), (n, 1))   # toes up
    lift = np.radians([0, 0, 0, 0, 18, 18, 18, 0])               # three passes' worth, late in swing
    feet = quat.mul(quat.from_axis_angle(np.stack([-lift, 0 * lift, 0 * lift], -1)), unlifted)
    out = cap_landing_turn(feet, unlifted, swing, np.radians(5.0))
    turn = np.degrees(quat.angle(quat.mul(out, quat.inv(unlifted))))
    assert turn.round(6).tolist() == [0, 0, 0, 0, 5, 10, 5, 0]   # in at 5° a frame, out by the landing
