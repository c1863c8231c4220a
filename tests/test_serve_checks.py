"""Attention checks in ``shapemotion serve``: the checks are items of each served list (where the static
page puts them), stored, validated and resumed by position like the design's trials, and exported as
the static runtime writes them, so ``analyze`` reports and excludes alike.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import httpx
import pandas as pd
import pytest

from stimuli.serve.study import load_study
from test_serve import ADMIN, PROTOCOL, answer, free_port, make_design, snapshot, start, start_server
from test_survey_browser import ARGS, CHROMIUM, make_clips

pytestmark = pytest.mark.filterwarnings("ignore:Using `httpx` with `starlette.testclient`")
CHECKS = "attention_checks: {every: 2, answer: ' medium', exclude_if_failed: 1}\n"
MEDIUM, HEAVY = 1, 2      # button indexes of the 3-point scale (Light, Medium, Heavy)


@pytest.fixture
def served(tmp_path):
    from starlette.testclient import TestClient

    from stimuli.serve.app import create_app
    from stimuli.serve.db import Database

    design = make_design(tmp_path / "design", PROTOCOL + CHECKS)
    study = load_study(design)
    db = Database(design / "shapemotion-serve.db", study.fingerprint)
    client = TestClient(create_app(study, db, ADMIN, expire_s=600))
    client.study, client.db, client.design = study, db, design
    yield client
    db.close()


def test_each_list_has_a_check_after_every_second_test_trial(served):
    trials = pd.read_csv(served.design / "trials.csv", dtype=str)
    for number, entry in served.study.lists.items():
        kinds = [t["kind"] for t in entry["trials"]]
        assert kinds == ["test", "test", "attention_check", "test", "test"]      # none after the last
        assert [t["index"] for t in entry["trials"]] == list(range(5))
        design = trials.loc[trials["participant"] == str(number), "stimulus_id"].tolist()
        assert [t["id"] for t in entry["trials"] if "id" in t] == design            # the design's order kept
    assert served.study.config["attention"]["answer"] == "Medium"
    # a protocol without checks serves the lists it served before (its databases stay valid)
    plain = load_study(make_design(served.design.parent / "plain"))
    assert all("attention_check" not in [t["kind"] for t in e["trials"]] for e in plain.lists.values())


def test_a_check_answer_is_stored_once_validated_and_resumed(served):
    s = start(served, participant="p1")
    answer(served, s, 0, HEAVY)
    answer(served, s, 1, HEAVY)
    # a reload on the check's screen resumes at the check
    assert start(served, participant="p1")["trials"][0] == {"kind": "attention_check", "block": 1, "index": 2}
    before = snapshot(served.db)
    assert answer(served, s, 2, 3).status_code == 422           # not a button of the check
    assert answer(served, s, 3, HEAVY).status_code == 409       # the check comes first
    assert snapshot(served.db) == before
    assert answer(served, s, 2, HEAVY).json() == {"stored": True, "next": 3}
    assert answer(served, s, 2, HEAVY).json() == {"stored": False, "next": 3}     # a retry
    assert answer(served, s, 2, MEDIUM).status_code == 409                       # a changed answer
    back = start(served, participant="p1")                                        # a reload
    assert back["next"] == 3 and [t["kind"] for t in back["trials"]] == ["test", "test"]
    row = served.db.answer(s["session"], 2)
    assert row | {"session": "", "participant": ""} == {
        "rt": 800, "trial_type": "html-button-response", "trial_index": 2, "participant": "", "session": "",
        "list": 1, "SEX": "M", "protocol": "serve_tiny", "attention_check": 1, "attention_answer": "Medium",
        "response": HEAVY, "response_label": "Heavy", "attention_passed": 0}


def complete(client, state: dict, check: int) -> None:
    for trial in state["trials"]:
        response = check if trial["kind"] == "attention_check" else (HEAVY if "Hi1" in trial["id"] else 0)
        assert answer(client, state, trial["index"], response).status_code == 200
    client.post(f"/api/sessions/{state['session']}/finish", json={},
                headers={"X-Session-Token": state["token"]}).raise_for_status()


def test_analyze_on_the_export_reports_and_excludes_a_failed_check(served, tmp_path, run_cli):
    for n in range(1, 7):
        complete(served, start(served, participant=f"p{n}"), HEAVY if n == 2 else MEDIUM)
    code, out, err = run_cli("serve", "export", served.design, "--out", tmp_path / "r.csv")
    assert code == 0, err
    rows = pd.read_csv(tmp_path / "r.csv", dtype=str, keep_default_na=False)
    assert (rows["attention_check"] == "1").sum() == 6
    code, out, err = run_cli("analyze", served.design, "--responses", tmp_path / "r.csv", "--out",
                             tmp_path / "report", "--no-models")
    assert code == 0, err
    summary = json.loads((tmp_path / "report" / "summary.json").read_text())["import"]
    assert summary["attention_checks"] == [{"participant": f"p{n}", "checks": 1, "failed": int(n == 2)}
                                           for n in range(1, 7)]
    assert summary["participants"] == 5 and summary["excluded_by_reason"]["failed attention checks"] == 4
    assert not summary["columns_not_imported"]


# -- in Chromium: one participant passes the check, one fails it and reloads the page right after -----

def click_through(page, url: str, attentive: bool, reload_after_check: bool) -> None:
    """'Heavy' on every clip; on the check 'Medium' when attentive, else 'Heavy'; reload once if asked."""
    page.goto(url)
    reloaded = False
    while not page.evaluate("window.SHAPEMOTION_STATUS && window.SHAPEMOTION_STATUS.done"):
        page.wait_for_selector("#jspsych-video-button-response-stimulus, #jspsych-html-button-response-stimulus,"
                               " #jspsych-content p")
        if page.query_selector("#jspsych-video-button-response-stimulus"):
            page.wait_for_function("() => { const b = document.querySelector('#jspsych-video-button-response-"
                                   "btngroup button'); return b !== null && !b.disabled; }", timeout=20_000)
            page.get_by_role("button", name="Heavy").click()
        elif page.query_selector("#jspsych-html-button-response-stimulus") and "please select" in \
                page.inner_text("#jspsych-html-button-response-stimulus"):
            saved = page.evaluate("window.SHAPEMOTION_STATUS.saved")
            page.get_by_role("button", name="Medium" if attentive else "Heavy").click()
            if reload_after_check and not reloaded:
                page.wait_for_function(f"() => window.SHAPEMOTION_STATUS.saved > {saved}", timeout=20_000)
                page.reload()
                reloaded = True
        elif page.query_selector("#jspsych-html-button-response-btngroup button"):
            page.click("#jspsych-html-button-response-btngroup button")
        page.wait_for_timeout(30)


def test_served_page_shows_stores_and_resumes_the_checks(tmp_path, run_cli):
    if not CHROMIUM.exists():
        pytest.skip("Debian chromium is not installed (make setup installs it)")
    from playwright.sync_api import sync_playwright

    design = make_design(tmp_path / "design", PROTOCOL + CHECKS)
    make_clips(design, seconds=0.5)
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    proc = start_server(design, port)
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
            statuses, frames = [], []
            for n, attentive in ((1, True), (2, False)):
                context = browser.new_context()
                page = context.new_page()
                click_through(page, f"{url}/?participant=web{n}&redirect=0", attentive, reload_after_check=n == 2)
                statuses.append(page.evaluate("window.SHAPEMOTION_STATUS"))
                frames.append(pd.read_csv(io.StringIO(page.evaluate("window.SHAPEMOTION_DATA()")), dtype=str,
                                          keep_default_na=False))
                context.close()
            browser.close()
        for n in range(3, 7):        # four more participants through the API, all attentive (for the ANOVA)
            state = httpx.post(f"{url}/api/sessions", json={"params": {"participant": f"api{n}"}}).json()
            for trial in state["trials"]:
                response = MEDIUM if trial["kind"] == "attention_check" else (HEAVY if "Hi1" in trial["id"] else 0)
                httpx.post(f"{url}/api/sessions/{state['session']}/trials", headers={"X-Session-Token": state["token"]},
                           json={"index": trial["index"], "response": response, "rt": 900}).raise_for_status()
            httpx.post(f"{url}/api/sessions/{state['session']}/finish", headers={"X-Session-Token": state["token"]},
                       json={}).raise_for_status()
        limits = httpx.get(f"{url}/admin/limits", headers={"Authorization": f"Bearer {ADMIN}"}).json()
    finally:
        proc.kill()
        proc.wait(10)
    assert all(s["errors"] == [] and s["limited"] == 0 for s in statuses)
    assert sum(limits["refused"].values()) == 0                # a normal run never meets the rate limit
    # the page showed the check where the static page does: right after the second test trial
    first = frames[0][frames[0]["trial_type"].isin(["video-button-response"]) | (frames[0]["attention_check"] == "1")]
    assert first["attention_check"].tolist() == ["", "", "1", "", ""]
    code, out, err = run_cli("serve", "export", design, "--out", tmp_path / "r.csv")
    assert code == 0, err
    rows = pd.read_csv(tmp_path / "r.csv", dtype=str, keep_default_na=False)
    answers = rows[rows["end"] != "1"]
    assert not answers.duplicated(["participant", "trial_index"]).any()          # each answer once
    checks = answers[answers["attention_check"] == "1"].set_index("participant")
    assert checks.loc[["web1", "web2"], "response_label"].tolist() == ["Medium", "Heavy"]   # kept over the reload
    assert checks.loc[["web1", "web2"], "attention_passed"].tolist() == ["1", "0"]
    assert answers.groupby("participant").size().tolist() == [5] * 6
    code, out, err = run_cli("analyze", design, "--responses", tmp_path / "r.csv", "--out", tmp_path / "report",
                             "--no-models")
    assert code == 0, err
    summary = json.loads((tmp_path / "report" / "summary.json").read_text())["import"]
    assert {c["participant"]: c["failed"] for c in summary["attention_checks"]} == {
        "web1": 0, "web2": 1, "api3": 0, "api4": 0, "api5": 0, "api6": 0}
    exclusions = pd.read_csv(tmp_path / "report" / "exclusions.csv", dtype=str)
    failed = exclusions[exclusions["reason"] == "failed attention checks"]
    assert set(failed["participant"]) == {"web2"} and len(failed) == 4


def test_the_static_page_and_the_server_place_the_checks_alike(tmp_path):
    """Exp. 2 (nested blocks, familiarisation, practice, 2AFC) with a check every 5th test trial: the static
    page (jsPsych's data-only simulation) shows each check between the same clips as the served list."""
    if not CHROMIUM.exists():
        pytest.skip("Debian chromium is not installed (make setup installs it)")
    from playwright.sync_api import sync_playwright

    from stimuli.design import build_design, write_design
    from stimuli.protocol import parse_protocol
    from stimuli.serve.study import with_checks
    from stimuli.survey import export_survey
    from stimuli.survey.jspsych import config
    from stimuli.survey.source import load_source
    from stimuli.survey.text import answer_labels
    from test_survey_browser import DONE, Server

    text = (Path(__file__).resolve().parents[1] / "protocols" / "exp2_com_vs_average.yaml").read_text()
    first = answer_labels(parse_protocol(text))[0]
    design = tmp_path / "design"
    write_design(build_design(parse_protocol(text + f"attention_checks: {{every: 5, answer: '{first}'}}\n"), 3), design)
    export_survey(design, "jspsych", tmp_path / "site", video_base_url="https://media.example.org/exp2")
    cfg = config(load_source(design))
    server = Server(tmp_path / "site")
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
            page = browser.new_page()
            shown = {}
            for n in (1, 2, 3):
                page.goto(f"{server.url}/index.html?participant={n}&simulate=data-only&save=0")
                page.wait_for_function(DONE, timeout=60_000)
                data = pd.read_csv(io.StringIO(page.evaluate("window.SHAPEMOTION_CSV")), dtype=str,
                                   keep_default_na=False)
                data = data[(data["clip_id"] != "") | (data["attention_check"] == "1")]
                shown[n] = [c or "check" for c in data["clip_id"]]
            browser.close()
    finally:
        server.close()
    for entry in cfg["lists"]:
        served = [t.get("id", "check") for t in with_checks(entry["trials"], cfg["attention"])]
        assert shown[entry["list"]] == served
        assert served.count("check") == (sum(t["kind"] == "test" for t in entry["trials"]) - 1) // 5 > 0


def test_a_ranking_study_with_checks_is_served_and_scored(tmp_path):
    """Ranking answers with every label; its check with one label's button, as on the static page."""
    from starlette.testclient import TestClient

    from analysis.io_design import load_design
    from analysis.responses import import_responses
    from stimuli.serve.app import create_app
    from stimuli.serve.db import Database
    from test_report import RANKING_PROTOCOL

    design = make_design(tmp_path / "design", RANKING_PROTOCOL + "attention_checks: {every: 1, answer: B}\n")
    study = load_study(design)
    db = Database(design / "shapemotion-serve.db", study.fingerprint)
    client = TestClient(create_app(study, db, ADMIN))
    try:
        for n in range(8):
            s = start(client, participant=f"r{n}")
            assert [t["kind"] for t in s["trials"]] == ["test", "attention_check", "test"]
            for t in s["trials"]:
                given = (2 if n == 0 else 1) if t["kind"] == "attention_check" else ["C", "A", "B"]
                assert answer(client, s, t["index"], given).status_code == 200
            assert answer(client, s, 1, ["A", "B", "C"]).status_code == 422       # a check is answered by index
            client.post(f"/api/sessions/{s['session']}/finish", json={},
                        headers={"X-Session-Token": s["token"]}).raise_for_status()
        export = client.get("/admin/export.csv", headers={"Authorization": f"Bearer {ADMIN}"})
        (tmp_path / "r.csv").write_text(export.text)
    finally:
        db.close()
    result = import_responses(tmp_path / "r.csv", load_design(design))
    assert result.reconciles and not result.summary()["columns_not_imported"]
    assert [c["failed"] for c in result.summary()["attention_checks"]] == [1] + [0] * 7
    assert result.data["participant"].nunique() == 8          # no exclude_if_failed: reported only
