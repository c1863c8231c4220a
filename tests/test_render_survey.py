"""A complete render folder is also a survey source: design files and every survey export."""

from __future__ import annotations

import yaml


def short(tmp_path, protocol_path, name):
    data = yaml.safe_load(protocol_path(name).read_text())
    data["clip"].update(duration_s=1.1, cycles=1)  # one whole walk cycle at 112 steps/min: the shortest valid clip
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_complete_render_writes_the_survey(tmp_path, protocol_path, run_cli):
    path = short(tmp_path, protocol_path, "thesis_validation")
    out = tmp_path / "render"
    code, stdout, _ = run_cli("render", path, "--out", out, "--resolution", "160x90", "--fps", "10", "--workers", "1",
                              "--poses", "procedural", "--no-progress", "--video-base-url", "https://lab.example/clips/")
    assert code == 0
    for name in ("design.json", "trials.csv", "conditions.csv", "survey/survey.qsf", "survey/survey_qualtrics.txt",
                 "survey/jspsych/index.html"):
        assert (out / name).is_file(), name
    assert "https://lab.example/clips/" in (out / "survey" / "survey.qsf").read_text()
    assert "survey: qsf" in stdout


def test_partial_render_exports_no_survey(tmp_path, protocol_path, run_cli, monkeypatch):
    """The CLI read the protocol and built the design again after the render (and a third time for
    --motions): render_protocol's report carries the design now."""
    import stimuli.protocol

    path = short(tmp_path, protocol_path, "exp1_shape_motion")
    out = tmp_path / "render"
    loads, real = [], stimuli.protocol.load_protocol
    monkeypatch.setattr(stimuli.protocol, "load_protocol", lambda p: loads.append(p) or real(p))
    code, stdout, _ = run_cli("render", path, "--out", out, "--resolution", "160x90", "--fps", "10", "--workers", "1",
                              "--poses", "procedural", "--no-progress", "--limit", "1")
    assert code == 0 and "survey: not exported" in stdout and not (out / "survey").exists()
    assert loads == [path]
