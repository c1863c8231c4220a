"""The ``shapemotion motion`` commands: files written, user errors → exit code 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from stimuli.cli import main
from stimuli.commands.checks import parse_body
from stimuli.errors import StimuliError
from stimuli.motion import Motion
from stimuli.motion.markers import MARKERS

ROOT = Path(__file__).resolve().parents[1]
WALK = ROOT / "stimuli" / "data" / "cmu_35_01_walk.bvh"


def test_generate_import_average_modify_metrics_export(tmp_path, capsys):
    w = tmp_path / "w.npz"
    assert main(["motion", "generate", "--gait", "jog", "--protocol", str(ROOT / "protocols" / "exp1_shape_motion.yaml"),
                 "--actor", "M_Hi2", "--out", str(w), "--bvh", str(tmp_path / "w.bvh")]) == 0
    m = Motion.load(w)
    assert m.metadata["gait"] == "jog" and m.metadata["actor_id"] == "M_Hi2"
    assert abs(m.metadata["cadence_spm"] - 138) <= 1 and m.metadata["speed_mps"] == 2.2
    assert main(["motion", "import", str(WALK), "--loop", "--cycles", "2", "--fps", "30",
                 "--out", str(tmp_path / "c.npz")]) == 0
    c = Motion.load(tmp_path / "c.npz")
    assert c.fps == 30 and c.metadata["looped"] and c.metadata["treadmill"]
    w2 = tmp_path / "w2.npz"
    assert main(["motion", "generate", "--height", "1.7", "--bmi", "31", "--seed", "3", "--out", str(w2)]) == 0
    assert main(["motion", "generate", "--height", "1.8", "--bmi", "21", "--seed", "4", "--out", str(tmp_path / "w3.npz")]) == 0
    assert main(["motion", "average", str(w2), str(tmp_path / "w3.npz"), "--out", str(tmp_path / "a.npz")]) == 0
    assert Motion.load(tmp_path / "a.npz").metadata["n_motions"] == 2
    assert main(["motion", "modify", str(w2), "--height", "1.83", "--body-fat", "34.1",
                 "--out", str(tmp_path / "mod.npz")]) == 0
    assert Motion.load(tmp_path / "mod.npz").metadata["modifier"]["swing_ratio"] == pytest.approx(1.286497, abs=1e-6)
    assert main(["motion", "metrics", str(w), "--json", str(tmp_path / "m.json")]) == 0
    metrics = json.loads((tmp_path / "m.json").read_text())
    assert metrics["flight_pct"] > 0 and metrics["skate_pct"] <= 5
    assert main(["motion", "export-bvh", str(tmp_path / "c.npz"), "--out", str(tmp_path / "c.bvh")]) == 0
    from stimuli.motion.bvh import read_bvh
    back = read_bvh(tmp_path / "c.bvh")
    assert np.allclose(back.positions(), c.positions(), atol=2e-4)
    assert main(["motion", "markers", str(w), "--out", str(tmp_path / "mk.csv")]) == 0
    import pandas as pd
    mk = pd.read_csv(tmp_path / "mk.csv")
    assert len(mk) == m.n_frames * 15 and set(mk["marker"]) == set(MARKERS)
    assert main(["motion", "strip", str(w), str(tmp_path / "c.npz"), "--out", str(tmp_path / "s.png")]) == 0
    assert (tmp_path / "s.png").stat().st_size > 10_000


def test_metrics_of_a_raw_capture_judge_contact_from_its_own_floor(tmp_path, capsys):
    """The CMU walk stands 1–2 cm above its toes' push-off dip: judged from y = 0 it read as 9 % stance
    and 82 % flight; judged from the level its feet stand at, it walks, and the CLI says why."""
    assert main(["motion", "import", str(WALK), "--loop", "--cycles", "2", "--out", str(tmp_path / "c.npz")]) == 0
    capsys.readouterr()
    assert main(["motion", "metrics", str(tmp_path / "c.npz")]) == 0
    out, err = capsys.readouterr()
    q = json.loads(out)
    assert q["stance_pct"] > 45 and q["flight_pct"] < 15 and q["double_support_pct"] > 5, q
    # the level depends on the cycles the loop takes (the best-closing two: 1.7 cm; the first one, repeated: 1.6)
    assert 1.0 < q["stance_height_cm"] < 2.5 and f"stand {q['stance_height_cm']:.1f} cm above y = 0" in err


def test_metrics_of_a_floating_clip_report_its_float_and_a_stub_is_refused(tmp_path, capsys):
    """Raised 10 cm, a walk had no 'planted' frame within 5 cm of y = 0 and read Float 0; a 1-frame motion
    got 100 % stance and its metadata's cycles and speed."""
    from stimuli.motion.generate import GaitParams, generate

    walk = generate(GaitParams(gait="walk", cadence_spm=112, speed_mps=1.2), height_m=1.6, fps=30, cycles=2)
    raised = walk.root_translation.copy()
    raised[:, 1] += 0.10
    walk.replace(root_translation=raised).save(tmp_path / "up.npz")
    capsys.readouterr()
    assert main(["motion", "metrics", str(tmp_path / "up.npz")]) == 0
    out, err = capsys.readouterr()
    assert 9.5 < json.loads(out)["float_cm"] < 10.5 and "or the clip floats" in err
    walk.slice(0, 1).save(tmp_path / "one.npz")
    assert main(["motion", "metrics", str(tmp_path / "one.npz")]) == 2
    assert "1 frame(s) hold no gait cycle" in " ".join(capsys.readouterr().err.split())


def test_average_checks_and_explains_the_body_it_records(tmp_path, capsys):
    """A height of 160 (centimetres) made an average 'of 80.8 m'; a word made numpy raise; mixed sexes or a
    missing BMI left the average without a body, silently."""
    from stimuli.motion.generate import GaitParams, generate

    walk = generate(GaitParams(gait="walk", cadence_spm=112, speed_mps=1.2), height_m=1.6, fps=30, cycles=2)
    for name, meta in (("f", {"sex": "F", "bmi": 22.0}), ("m", {"sex": "M", "bmi": None}),
                       ("cm", {"height_m": 160}), ("word", {"height_m": "tall"})):
        bad = walk.replace()
        bad.metadata.update(meta)
        bad.save(tmp_path / f"{name}.npz")
    for name, message in (("cm", "motion 2: metadata height_m is 160; expected a number within 1.2–2.3 m"),
                          ("word", "motion 2: metadata height_m is 'tall'")):
        assert main(["motion", "average", str(tmp_path / "f.npz"), str(tmp_path / f"{name}.npz"),
                     "--out", str(tmp_path / "a.npz")]) == 2
        assert message in " ".join(capsys.readouterr().err.split()) and not (tmp_path / "a.npz").exists()
    assert main(["motion", "average", str(tmp_path / "f.npz"), str(tmp_path / "m.npz"), "--out", str(tmp_path / "a.npz")]) == 0
    err = " ".join(capsys.readouterr().err.split())
    assert "sexes differ (F, M): the average records no sex" in err and "motion(s) 2 record no bmi" in err
    assert "sex" not in Motion.load(tmp_path / "a.npz").metadata


@pytest.mark.parametrize("args,msg", [
    (["motion", "import", "{bad}", "--out", "{out}"], "not a readable BVH"),
    (["motion", "import", "{short}", "--loop", "--out", "{out}"], "fewer than one whole gait cycle"),
    (["motion", "metrics", "{missing}"], "not found"),
    (["motion", "generate", "--cadence", "10", "--out", "{out}"], "--cadence: 10 is outside the human range 40–260"),
    (["motion", "generate", "--speed", "9", "--out", "{out}"], "--speed: 9 is outside the human range 0.2–6 m/s"),
])
def test_user_errors_exit_2(tmp_path, capsys, args, msg):
    (tmp_path / "bad.bvh").write_text("nonsense")
    lines = WALK.read_text().splitlines()
    head = lines[:lines.index("MOTION")]
    frames = lines[lines.index("MOTION") + 3:][:40]
    (tmp_path / "short.bvh").write_text("\n".join(head + ["MOTION", "Frames: 40", "Frame Time: .0083333"] + frames) + "\n")
    subs = {"{bad}": str(tmp_path / "bad.bvh"), "{short}": str(tmp_path / "short.bvh"),
            "{missing}": str(tmp_path / "none.npz"), "{out}": str(tmp_path / "o.npz")}
    assert main([subs.get(a, a) for a in args]) == 2
    assert msg in capsys.readouterr().err.replace("\n  ", " ")


def test_parse_body():
    """One parser for every --body (preview's own accepted age=3 and ignored it)."""
    assert parse_body("sex=m,height=1.8,bmi=25") == {"sex": "M", "height_m": 1.8, "bmi": 25.0}
    assert parse_body("SEX=F, Height=1.6, BMI=28.1") == {"sex": "F", "height_m": 1.6, "bmi": 28.1}
    with pytest.raises(StimuliError, match="missing bmi"):
        parse_body("sex=M,height=1.8")
    with pytest.raises(StimuliError, match="unknown key"):
        parse_body("sex=M,height=1.8,bmi=25,age=3")
    with pytest.raises(StimuliError, match="sex must be F or M"):
        parse_body("sex=X,height=1.8,bmi=25")


def test_preview_and_motion_read_body_the_same_way(run_cli, tmp_path):
    for command in (["preview", "--stepping", "--out", tmp_path / "p.mp4"],
                    ["motion", "retarget", WALK, "--out", tmp_path / "r.npz"]):
        code, _, err = run_cli(*command, "--body", "sex=M,height=1.8,bmi=25,age=3")
        assert code == 2 and "unknown key 'age'" in err, command


def test_generate_checks_cadence_and_speed_once_with_the_protocols_bounds():
    """--cadence 10 passed the CLI's > 0 and failed in the generator naming cadence_spm (20–260), while a
    protocol's gaits allow 40–260: one set of bounds now, the protocol's."""
    from stimuli.motion.generate import CADENCE_RANGE_SPM, SPEED_RANGE_MPS, GaitParams
    from stimuli.protocol import GaitSpec

    for field, bounds in (("cadence_spm", CADENCE_RANGE_SPM), ("speed_mps", SPEED_RANGE_MPS)):
        limits = {k: getattr(m, k) for m in GaitSpec.model_fields[field].metadata for k in ("gt", "lt", "ge", "le")
                  if getattr(m, k, None) is not None}
        assert limits == dict(zip(("ge", "le"), bounds)), (field, limits)   # ends included, as the CLI's
    GaitSpec(cadence_spm=CADENCE_RANGE_SPM[0], speed_mps=SPEED_RANGE_MPS[1])
    GaitParams(cadence_spm=CADENCE_RANGE_SPM[0], speed_mps=SPEED_RANGE_MPS[1]).resolved()
    with pytest.raises(StimuliError, match="cadence_spm must be within 40–260"):
        GaitParams(cadence_spm=30).resolved()
