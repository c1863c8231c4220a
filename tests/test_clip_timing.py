"""How a gait's cadence is fitted to a clip (stimuli.render.timing): the prediction matches what the
generator and the renderer's loop fitting do, and validate warns when the clip changes a gait."""

from __future__ import annotations

import pytest
import yaml

from stimuli.render.timing import gait_fit, keeping_durations, whole_cycles

# The walkthrough's pilot: walk 108 and jog 150 steps/min in a 2 s clip at 15 fps.
PILOT_GAITS = {"walk": {"cadence_spm": 108, "speed_mps": 1.1}, "jog": {"cadence_spm": 150, "speed_mps": 2.4}}


def pilot(tmp_path, protocol_path, **clip) -> str:
    data = yaml.safe_load(protocol_path("exp1_shape_motion").read_text())
    data["gaits"] = PILOT_GAITS
    data["clip"].update({"duration_s": 2, "fps": 15, "width": 320, "height": 180} | clip)
    path = tmp_path / "pilot.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_whole_cycles_is_the_motion_packages_rule():
    from stimuli.motion.loop import cycles_for_clip

    for tenths in range(1, 600, 7):
        for cadence in range(41, 260, 3):
            assert whole_cycles(tenths / 10, cadence) == cycles_for_clip(tenths / 10, cadence)


@pytest.mark.parametrize("gait, cadence, speed", [("walk", 108, 1.1), ("jog", 150, 2.4)])
def test_predicted_cadence_is_what_the_clip_plays(gait, cadence, speed):
    """The generator's loop stretched over the clip's frames by fit_loop plays the predicted cadence."""
    from stimuli.motion.style import actor_gait
    from stimuli.protocol import Actor
    from stimuli.render.sources import fit_loop

    actor = Actor(id="F_Avg", label="Avg", sex="F", height_m=1.65, bmi=23.4)
    motion = actor_gait(actor, gait, cadence, speed, 77, 15.0, whole_cycles(2.0, cadence))
    _, _, scale = fit_loop(motion.rotations, motion.root_translation, motion.fps, 30, 15)
    played = motion.metadata["cadence_spm"] * scale
    fit = gait_fit(gait, cadence, speed, 2.0, 15)
    assert played == pytest.approx(fit.effective_cadence_spm, rel=1e-9) == pytest.approx(120.0)
    # fit_loop plays the generator's belt speed `ratio` times faster; belt_matched_speed divides it back out
    assert scale == pytest.approx(fit.ratio, rel=0.02) and fit.effective_speed_mps == speed


def test_keeping_durations_are_whole_frames_within_tolerance():
    shorter, longer = keeping_durations([108, 150], 2.0, 15)
    assert shorter is None and longer == pytest.approx(83 / 15)   # 5.53 s: walk 5 cycles, jog 7
    for d in (longer, *keeping_durations([150], 2.0, 15)):
        assert round(d * 15) == pytest.approx(d * 15)
        assert gait_fit("jog", 150, 2.4, d, 15).within_tolerance


def test_validate_warns_per_gait_whose_cadence_the_clip_changes(tmp_path, protocol_path, run_cli):
    code, stdout, _ = run_cli("validate", pilot(tmp_path, protocol_path))
    assert code == 0
    out = " ".join(stdout.split())
    assert "clip 2 s (looped): walk 2 cycle(s) at 120.0 steps/min (protocol 108), jog 2 cycle(s) at 120.0" in out
    assert ("warning: gaits.jog: 150 steps/min does not fill the 2 s clip with whole gait cycles, so the clip shows "
            "2 cycle(s) at 120.0 steps/min (-20.0 %); the belt keeps 2.4 m/s, so steps are 1.20 m instead of 0.96; "
            "clip.duration_s 1.6 s or 2.4 s keeps 150 steps/min") in out
    assert "warning: gaits.walk: 108 steps/min" in out and "(+11.1 %)" in out
    assert "warning: clip.duration_s: 5.53 s keeps every gait within 2%" in out


def test_no_warning_when_the_clip_keeps_the_cadence(tmp_path, protocol_path, run_cli):
    code, stdout, _ = run_cli("validate", pilot(tmp_path, protocol_path, duration_s=5.53))
    assert code == 0 and "warning:" not in stdout


def test_a_clip_that_does_not_loop_keeps_the_cadence(tmp_path, protocol_path, run_cli):
    """clip.loop: false used to change nothing; the clip now plays the protocol's cadence and belt speed,
    cut at its end."""
    from stimuli.motion.style import actor_gait
    from stimuli.protocol import Actor
    from stimuli.render.sources import fit_loop

    code, stdout, _ = run_cli("validate", pilot(tmp_path, protocol_path, loop=False, cycles=1))
    out = " ".join(stdout.split())
    assert code == 0 and "warning:" not in out
    assert ("clip 2 s (not looped: the protocol's cadence to whole frames, cut at the end): walk 1.82 cycle(s) at "
            "109.1 steps/min (protocol 108), jog 2.50 cycle(s) at 150.0") in out
    actor = Actor(id="F_Avg", label="Avg", sex="F", height_m=1.65, bmi=23.4)
    motion = actor_gait(actor, "jog", 150, 2.4, 77, 15.0, whole_cycles(2.0, 150))
    rot, _, scale = fit_loop(motion.rotations, motion.root_translation, motion.fps, 30, 15, loop=False)
    assert scale == 1.0 and len(rot) == 30 and motion.metadata["cadence_spm"] == pytest.approx(150, rel=0.01)
    # what the manifest records is what the clip plays: the loop rounded to whole frames (24 fps: 151.6)
    played = actor_gait(actor, "jog", 150, 2.4, 77, 24.0, whole_cycles(2.0, 150)).metadata["cadence_spm"]
    fit = gait_fit("jog", 150, 2.4, 2.0, 24, loop=False)
    assert fit.effective_cadence_spm == pytest.approx(played, rel=1e-9) and fit.effective_speed_mps == 2.4
    code, _, err = run_cli("validate", pilot(tmp_path, protocol_path, loop=False, cycles=3))
    assert code == 2 and "shows 1.82 cycles of walk (108 steps/min), fewer than 3" in " ".join(err.split())
