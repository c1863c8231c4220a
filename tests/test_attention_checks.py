"""Attention checks: protocol block → jsPsych page (headless Chromium) → data flag → import report and exclusion.

The block is optional: without it the design files are byte for byte what they were. The checks live in
every export (and ``shapemotion serve``, tests/test_serve_checks.py); the Qualtrics and PsychoPy ones are
tested in tests/test_attention_exports.py.
"""

from __future__ import annotations

import io
import json

import pandas as pd
import pytest
from conftest import buttons_enabled

from stimuli.design import build_design, design_json, write_design
from stimuli.errors import StimuliError
from stimuli.protocol import parse_protocol
from stimuli.survey import export_all, export_survey
from stimuli.survey.jspsych import config
from stimuli.survey.source import load_source
from tests.test_survey_browser import browser  # noqa: F401  (the fixture: Debian's Chromium)
from tests.test_survey_browser import DONE, TINY, Server, exported, make_clips

CHECKS = "attention_checks: {every: 2, answer: ' medium', exclude_if_failed: 1}\n"


def tiny(extra: str = "", participants: int = 4):
    return parse_protocol(TINY.replace("participants: 4", f"participants: {participants}") + extra)


def test_without_the_block_the_design_files_are_unchanged(tmp_path):
    plain, checked = tiny(), tiny(CHECKS)
    assert plain.attention_checks is None and "attention_checks" not in plain.to_json_dict()
    a, b = tmp_path / "a", tmp_path / "b"
    write_design(build_design(plain), a)
    write_design(build_design(checked), b)
    for name in ("conditions.csv", "trials.csv"):   # the design's trials are the same either way
        assert (a / name).read_bytes() == (b / name).read_bytes()
    with_checks = json.loads((b / "design.json").read_text())
    assert with_checks["protocol"].pop("attention_checks") == {
        "every": 2, "answer": " medium", "exclude_if_failed": 1,
        "prompt": "To show that you are reading this, please select '{answer}'."}
    assert json.dumps(with_checks, indent=2) + "\n" == (a / "design.json").read_text()
    assert design_json(build_design(plain)) == json.loads((a / "design.json").read_text())


@pytest.mark.parametrize("block, says", [
    ("attention_checks: {every: 2, answer: Heavyish}", "attention_checks.answer (line 23): 'Heavyish' is not one of "
                                                       "the answer buttons ['Light', 'Medium', 'Heavy']"),
    ("attention_checks: {every: 0, answer: Light}", "attention_checks.every"),
    ("attention_checks: {every: 2, answer: Light, exclude_if_failed: 0}", "attention_checks.exclude_if_failed"),
    ("attention_checks: {every: 2, answer: Light, after: 3}", "attention_checks.after"),
])
def test_a_wrong_block_is_refused_naming_the_field(block, says):
    with pytest.raises(StimuliError) as error:
        tiny(block + "\n")
    assert says in str(error.value)


def test_every_export_carries_them(tmp_path):
    design = tmp_path / "design"
    write_design(build_design(tiny(CHECKS)), design)
    make_clips(design)
    for fmt in ("qsf", "qualtrics-txt", "psychopy"):
        export_survey(design, fmt, tmp_path / fmt, video_base_url="https://example.org/clips")
    assert "attention_check_1" in (tmp_path / "qsf").read_text()
    assert "attention_check_1" in (tmp_path / "qualtrics-txt").read_text()
    assert (tmp_path / "psychopy" / "conditions" / "attention_check.csv").exists()
    export_all(design, tmp_path / "all")
    assert (tmp_path / "all" / "jspsych" / "index.html").exists() and (tmp_path / "all" / "psychopy").exists()
    # the page gets the answer spelled as its button, and the request escaped
    cfg = config(load_source(design))
    assert cfg["attention"] == {"every": 2, "answer": "Medium",
                                "prompt": "<p>To show that you are reading this, please select &#x27; medium&#x27;.</p>"}
    assert "attention" not in config(load_source(_plain_design(tmp_path)))


def _plain_design(tmp_path):
    design = tmp_path / "plain"
    write_design(build_design(tiny()), design)
    return design


# -- in Chromium: participants 1 and 3 answer the check, 2 and 4 do not ------------------------------

def answer_everything(page, url: str, attentive: bool) -> pd.DataFrame:
    """Clicks through: 'Heavy' on every clip; on a check 'Medium' when attentive, else 'Heavy'."""
    page.goto(url)
    video_buttons = "#jspsych-video-button-response-btngroup button"
    while not page.evaluate(DONE):
        page.wait_for_selector("#jspsych-video-button-response-stimulus, #jspsych-html-button-response-stimulus, "
                               "#jspsych-content p")
        if page.evaluate(DONE):
            break
        if page.query_selector("#jspsych-video-button-response-stimulus"):
            page.wait_for_function(buttons_enabled(video_buttons), timeout=10_000)
            page.get_by_role("button", name="Heavy").click()
        elif "please select" in page.inner_text("#jspsych-html-button-response-stimulus"):
            page.get_by_role("button", name="Medium" if attentive else "Heavy").click()
        else:
            page.click("#jspsych-html-button-response-btngroup button")
        page.wait_for_timeout(30)
    return pd.read_csv(io.StringIO(page.evaluate("window.SHAPEMOTION_CSV")), dtype=str, keep_default_na=False)


def test_checks_are_shown_recorded_reported_and_excluded(tmp_path, browser):
    design, site = exported(tmp_path, tiny(CHECKS))
    server = Server(site)
    try:
        page = browser.new_page()
        frames = [answer_everything(page, f"{server.url}/index.html?participant={n}&save=0", n % 2 == 1)
                  for n in range(1, 5)]
        page.close()
    finally:
        server.close()
    for n, frame in enumerate(frames, start=1):
        checks = frame[frame["attention_check"] == "1"]
        # 4 test trials, a check after every 2nd, none after the last
        assert len(checks) == 1 and frame.index.get_loc(checks.index[0]) == frame.index[frame["kind"] == "test"][1] + 1
        assert checks["attention_answer"].tolist() == ["Medium"]
        assert checks["attention_passed"].tolist() == (["1"] if n % 2 else ["0"])
    from analysis.io_design import load_design
    from analysis.responses import import_responses

    pd.concat(frames, ignore_index=True).to_csv(tmp_path / "r.csv", index=False)
    result = import_responses(tmp_path / "r.csv", load_design(design))
    assert result.reconciles and not result.summary()["columns_not_imported"]
    assert result.summary()["attention_checks"] == [{"participant": str(n), "checks": 1, "failed": int(n % 2 == 0)}
                                                    for n in range(1, 5)]
    assert sorted(result.data["participant"].unique()) == ["1", "3"]
    failed = result.excluded_rows[result.excluded_rows["reason"] == "failed attention checks"]
    assert sorted(failed["participant"].unique()) == ["2", "4"] and len(failed) == 2 * 4
    assert failed["detail"].str.contains("failed 1 of 1 attention checks").all()
    # the check rows themselves are no answers: listed as such, as jsPsych's other screens are
    assert result.summary()["excluded_by_reason"]["not a stimulus trial"] > 0


def jspsych_rows(design, failing: set[str], rating=lambda t: "1") -> pd.DataFrame:
    """A jsPsych-shaped file: every design trial answered, then one check per participant (``failing`` fail it)."""
    trials = pd.read_csv(design / "trials.csv", dtype=str)
    rows = []
    for pid, group in trials.groupby("participant"):
        for t in group.itertuples():
            rows.append({"participant": pid, "SEX": t.SEX, "stimulus_id": t.stimulus_id, "response": rating(t),
                         "rt": "900", "repetition": t.repetition, "trial_type": "video-button-response",
                         "kind": t.kind})
        rows.append({"participant": pid, "trial_type": "html-button-response", "attention_check": "1",
                     "attention_answer": "Medium", "response_label": "Light" if pid in failing else "medium ",
                     "attention_passed": "0", "response": "0"})
    return pd.DataFrame(rows)


def test_report_only_when_no_rule(tmp_path):
    """Without exclude_if_failed the failed checks are reported, and nobody is excluded for them."""
    from analysis.io_design import load_design
    from analysis.responses import import_responses

    design = tmp_path / "design"
    write_design(build_design(tiny("attention_checks: {every: 2, answer: Medium}\n")), design)
    jspsych_rows(design, {"2"}).to_csv(tmp_path / "r.csv", index=False)
    result = import_responses(tmp_path / "r.csv", load_design(design))
    assert result.reconciles and result.data["participant"].nunique() == 4
    # judged from the labels, not from the page's attention_passed (which this file gets wrong on purpose)
    assert [c["failed"] for c in result.summary()["attention_checks"]] == [0, 1, 0, 0]
    assert "failed attention checks" not in result.summary()["excluded_by_reason"]


def test_analyze_reports_and_excludes(tmp_path):
    """``analyze``: summary.json lists the checks per participant; exclusions.csv gives the reason."""
    from analysis.report import analyze

    design = tmp_path / "design"
    write_design(build_design(tiny(CHECKS, participants=8)), design)
    heavier = lambda t: "2" if "Hi1" in t.stimulus_id else str(int(t.repetition) - 1)   # noqa: E731
    jspsych_rows(design, {"2", "5"}, heavier).to_csv(tmp_path / "r.csv", index=False)
    summary = analyze(design, tmp_path / "r.csv", tmp_path / "report", models=False)
    assert [c["failed"] for c in summary["import"]["attention_checks"]] == [0, 1, 0, 0, 1, 0, 0, 0]
    assert summary["import"]["excluded_by_reason"]["failed attention checks"] == 2 * 4
    assert summary["import"]["participants"] == 6
    exclusions = pd.read_csv(tmp_path / "report" / "exclusions.csv", dtype=str)
    failed = exclusions[exclusions["reason"] == "failed attention checks"]
    assert set(failed["participant"]) == {"2", "5"}
