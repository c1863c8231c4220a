"""``shapemotion serve``: assignment, per-trial saving, resume, Prolific hand-off, export, and every
request the server must refuse (4xx, nothing stored) — through Starlette's TestClient, plus one real
uvicorn process killed with SIGKILL mid-study.

The clips are placeholder bytes: the API never decodes them (tests/test_serve_browser.py plays real ones).
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from stimuli.design import build_design, write_design
from stimuli.protocol import parse_protocol
from stimuli.serve.app import create_app
from stimuli.serve.db import Database
from stimuli.serve.study import load_study
from test_survey_browser import TINY

# Starlette asks for httpx2 in its TestClient; httpx (what the project installs) still works
pytestmark = pytest.mark.filterwarnings("ignore:Using `httpx` with `starlette.testclient`")
ROOT = Path(__file__).resolve().parents[1]
ADMIN = "admin-token-for-tests"

# The browser round trip's study (SEX between, 2 lists each; BODY within; 3-point Likert; 4 trials a
# list; an XSS attempt in the instructions), handed back to Prolific with a completion code.
PROTOCOL = TINY.replace("name: tiny_roundtrip", "name: serve_tiny") + \
    "recruitment: {platform: prolific, completion_code: C0DE42}\n"


class Clock:
    """A clock the tests move by hand (session expiry)."""

    def __init__(self):
        self.now = 1_000_000.0

    def __call__(self) -> float:
        return self.now


def make_design(folder: Path, text: str = PROTOCOL, participants: int | None = None) -> Path:
    write_design(build_design(parse_protocol(text), participants), folder)
    for sid in pd.read_csv(folder / "conditions.csv")["stimulus_id"]:
        (folder / "clips").mkdir(exist_ok=True)
        (folder / "clips" / f"{sid}.mp4").write_bytes(b"not decoded by these tests")
    return folder


@pytest.fixture
def served(tmp_path):
    from starlette.testclient import TestClient

    design = make_design(tmp_path / "design")
    study = load_study(design)
    db = Database(design / "shapemotion-serve.db", study.fingerprint)
    clock = Clock()
    client = TestClient(create_app(study, db, ADMIN, expire_s=600, clock=clock))
    client.study, client.db, client.clock, client.design = study, db, clock, design
    yield client
    db.close()


def start(client, **params) -> dict:
    r = client.post("/api/sessions", json={"params": params})
    assert r.status_code == 200, r.text
    return r.json()


def answer(client, state: dict, index: int, response=1, rt=800, token=None):
    return client.post(f"/api/sessions/{state['session']}/trials", json={"index": index, "response": response, "rt": rt},
                       headers={"X-Session-Token": token or state["token"]})


def complete(client, state: dict, response=1) -> dict:
    for trial in state["trials"]:
        assert answer(client, state, trial["index"], response).json()["stored"] is True
    r = client.post(f"/api/sessions/{state['session']}/finish", json={}, headers={"X-Session-Token": state["token"]})
    assert r.status_code == 200, r.text
    return r.json()


def snapshot(db: Database) -> list[str]:
    return list(db.conn.iterdump())


# -- assignment ---------------------------------------------------------------------------------------

def test_first_participants_get_the_design_lists_in_order_then_the_least_filled(served):
    states = [start(served, PROLIFIC_PID=f"pid{n}") for n in range(1, 5)]
    assert [s["list"] for s in states] == [1, 2, 3, 4]
    trials = pd.read_csv(served.design / "trials.csv", dtype=str)
    for s in states:   # each session follows its design list exactly
        expected = trials[trials["participant"] == str(s["list"])]
        assert [t["id"] for t in s["trials"]] == expected["stimulus_id"].tolist()
        assert s["groups"]["SEX"] == expected["SEX"].iloc[0]
    for s in states[:3]:
        complete(served, s)
    # list 4 is still in progress: it holds its slot, so the next participant starts list 1 again
    assert start(served, PROLIFIC_PID="pid5")["list"] == 1
    # list 4's participant leaves; after the expiry its slot is free (and pid5's too, unfinished):
    # list 4 is then the emptiest, and after it the four lists tie again
    served.clock.now += 601
    assert [start(served, PROLIFIC_PID=f"pid{n}")["list"] for n in (6, 7)] == [4, 1]
    progress = served.get("/admin/progress", headers={"Authorization": f"Bearer {ADMIN}"}).json()
    assert [(p["list"], p["finished"], p["in_progress"], p["expired"]) for p in progress] == [
        (1, 1, 1, 1), (2, 1, 0, 0), (3, 1, 0, 0), (4, 0, 1, 1)]


def test_a_between_group_in_the_url_picks_among_that_groups_lists(served):
    lists = served.study.lists
    males = [start(served, SEX="M", participant=f"m{n}")["list"] for n in range(3)]
    assert all(lists[n]["groups"]["SEX"] == "M" for n in males)
    assert sorted(males[:2]) == sorted(n for n in lists if lists[n]["groups"]["SEX"] == "M")


# -- saving, retry, resume, hand-off ------------------------------------------------------------------

def test_answers_are_stored_once_and_a_reload_resumes_at_the_next_trial(served):
    s = start(served, PROLIFIC_PID="5f0c1e2d3b4a", STUDY_ID="study1", SESSION_ID="sess1")
    assert answer(served, s, 0, 2).json() == {"stored": True, "next": 1}
    assert answer(served, s, 0, 2).json() == {"stored": False, "next": 1}      # a retried request
    assert answer(served, s, 1, 0).json()["stored"] is True
    again = start(served, PROLIFIC_PID="5f0c1e2d3b4a")       # the same Prolific participant comes back
    assert (again["session"], again["next"], again["token"]) == (s["session"], 2, s["token"])
    assert [t["index"] for t in again["trials"]] == [2, 3]
    by_token = served.post("/api/sessions", json={"params": {}, "resume": {"session": s["session"],
                                                                           "token": s["token"]}}).json()
    assert by_token["session"] == s["session"] and by_token["next"] == 2      # a reload (token in storage)
    done = complete(served, again)
    assert done == {"finished": True, "redirect": "https://app.prolific.com/submissions/complete?cc=C0DE42"}
    assert served.db.answered(s["session"]) == [0, 1, 2, 3]
    session = served.db.session(s["session"])
    assert '"STUDY_ID": "study1"' in session["params"] and session["user_agent"] == "testclient"


def test_the_export_is_read_by_analyze_as_a_jspsych_file(served, tmp_path):
    from analysis.io_design import load_design
    from analysis.responses import import_responses

    ratings = {1: {"Hi1": 3, "Lo1": 1}, 2: {"Hi1": 3, "Lo1": 2}, 3: {"Hi1": 2, "Lo1": 1}, 4: {"Hi1": 3, "Lo1": 2}}
    for n in range(1, 5):
        s = start(served, participant=f"p{n}")
        for t in s["trials"]:
            body = "Hi1" if t["id"].endswith("Hi1") else "Lo1"
            assert answer(served, s, t["index"], ratings[n][body] - 1).status_code == 200
        served.post(f"/api/sessions/{s['session']}/finish", json={}, headers={"X-Session-Token": s["token"]})
    dropout = start(served, participant="dropout")           # one answer, never finished
    answer(served, dropout, 0)
    csv = served.get("/admin/export.csv", headers={"Authorization": f"Bearer {ADMIN}"})
    assert csv.status_code == 200
    (tmp_path / "responses.csv").write_text(csv.text)
    result = import_responses(tmp_path / "responses.csv", load_design(served.design))
    assert result.reconciles, result.summary()
    assert result.summary()["participants"] == 4 and result.summary()["answers"] == 16
    assert not result.summary()["columns_not_imported"]
    # the finished sessions end with jsPsych's closing row; the dropout's answer is excluded as unfinished
    reasons = result.exclusions.loc[result.exclusions["participant"] == "dropout", "reason"]
    assert reasons.tolist() == ["unfinished"]
    for row in result.data.itertuples():
        assert int(row.rating) == ratings[int(row.participant[1:])][row.BODY]


def test_an_expired_session_that_comes_back_keeps_its_answers(served):
    s = start(served, participant="slow")
    answer(served, s, 0)
    served.clock.now += 10_000
    back = start(served, participant="slow")
    assert back["session"] == s["session"] and back["next"] == 1


# -- refused requests ---------------------------------------------------------------------------------

def test_each_bad_request_gets_a_4xx_and_changes_nothing(served):
    a = start(served, participant="alice")
    b = start(served, participant="bob")
    answer(served, a, 0)
    before = snapshot(served.db)
    sid = a["session"]
    tok = {"X-Session-Token": a["token"]}
    admin = {"Authorization": f"Bearer {ADMIN}"}
    bad = {
        "another participant's session": answer(served, b, 1, token=a["token"]),
        "no token": served.post(f"/api/sessions/{sid}/trials", json={"index": 1, "response": 1}),
        "unknown session": served.post("/api/sessions/0123456789abcdef/trials", json={"index": 1, "response": 1},
                                       headers=tok),
        "answer outside the scale": answer(served, a, 1, 3),
        "negative answer": answer(served, a, 1, -1),
        "answer not a number": answer(served, a, 1, "Heavy"),
        "true as an answer": answer(served, a, 1, True),
        "rt not a time": answer(served, a, 1, 1, rt="slow"),
        "trial not next": answer(served, a, 2),
        "trial outside the list": answer(served, a, 99),
        "answer changed": answer(served, a, 0, 2),
        "finish too early": served.post(f"/api/sessions/{sid}/finish", json={}, headers=tok),
        "oversized body": served.post(f"/api/sessions/{sid}/trials", headers=tok,
                                      content=b'{"index": 1, "response": 1, "x": "' + b"a" * 20_000 + b'"}'),
        "not JSON": served.post(f"/api/sessions/{sid}/trials", headers=tok, content=b"index=1"),
        "JSON not an object": served.post(f"/api/sessions/{sid}/trials", headers=tok, json=[1, 2]),
        "bad event": served.post(f"/api/sessions/{sid}/events", headers=tok, json={"kind": "hack", "clip": "x"}),
        "bad participant id": served.post("/api/sessions", json={"params": {"participant": "<script>"}}),
        "participant id with a newline": served.post("/api/sessions", json={"params": {"PROLIFIC_PID": "abc\n"}}),
        "database": served.get("/shapemotion-serve.db"),
        "../ path": served.get("/clips/../shapemotion-serve.db"),
        "encoded ../ path": served.get("/clips/%2e%2e/shapemotion-serve.db"),
        "design file": served.get("/design.json"),
        "outside the folder": served.get("/..%2f..%2fetc/passwd"),
        "admin without token": served.get("/admin/export.csv"),
        "admin wrong token": served.get("/admin/progress", headers={"Authorization": "Bearer guess"}),
        "admin token as a participant": served.get("/admin/export.csv", headers=tok),
    }
    codes = {name: r.status_code for name, r in bad.items()}
    assert all(400 <= c < 500 for c in codes.values()), codes
    assert codes["another participant's session"] == 403 and codes["oversized body"] == 413
    assert codes["answer outside the scale"] == 422 and codes["trial not next"] == 409
    assert codes["admin without token"] == 401 and codes["database"] == 404
    assert "error" in bad["answer outside the scale"].json()
    assert snapshot(served.db) == before
    # and the server still works for both
    assert answer(served, a, 1).status_code == 200 and answer(served, b, 0).status_code == 200


def test_the_page_escapes_protocol_text_and_sends_security_headers(served):
    page = served.get("/")
    assert page.status_code == 200 and "<title>Tiny round trip</title>" in page.text
    config = served.get("/config.js").text
    assert "<" not in config and "\\u0026lt;img src=x onerror" in config and '"server":true' in config
    assert "lists" not in config        # a participant gets only their own list, from the API
    assert "default-src 'self'" in page.headers["content-security-policy"]
    assert page.headers["x-content-type-options"] == "nosniff"
    clip = served.study.config["clips"]
    assert served.get("/" + next(iter(clip.values()))).status_code == 200
    assert served.get("/lib/jspsych.js").headers["content-type"].startswith("text/javascript")


# -- the command line and the database file -------------------------------------------------------------

def test_serve_export_from_the_folder_or_the_database_file(served, tmp_path, run_cli):
    s = start(served, participant="p1")
    answer(served, s, 0)
    served.post(f"/api/sessions/{s['session']}/events", headers={"X-Session-Token": s["token"]},
                json={"kind": "load_failed", "clip": "clips/x.mp4"})
    code, out, err = run_cli("serve", "export", served.design, "--out", tmp_path / "a.csv")
    assert code == 0, err
    code, out, err = run_cli("serve", "export", served.design / "shapemotion-serve.db", "--out", tmp_path / "b.csv")
    assert code == 0, err
    assert (tmp_path / "a.csv").read_text() == (tmp_path / "b.csv").read_text()
    rows = pd.read_csv(tmp_path / "a.csv", dtype=str)
    assert rows["participant"].tolist() == ["p1"] and rows["response"].tolist() == ["1"]
    sessions = pd.read_csv(tmp_path / "a_sessions.csv", dtype=str, keep_default_na=False)
    assert sessions["failed_clips"].tolist() == ["load_failed:clips/x.mp4"]
    assert sessions["browser"].tolist() == ["testclient"] and sessions["status"].tolist() == ["not finished"]


def test_serve_refuses_bad_input_naming_it(tmp_path, run_cli):
    def run(*args):   # the message is one paragraph, wrapped
        code, out, err = run_cli(*args)
        return code, out, " ".join(err.split())

    (tmp_path / "junk.db").write_text("not sqlite")
    code, out, err = run("serve", "export", tmp_path / "junk.db", "--out", tmp_path / "x.csv")
    assert code == 2 and "junk.db: not an SQLite database" in err and not (tmp_path / "x.csv").exists()
    code, out, err = run("serve", "export", tmp_path / "missing.db", "--out", tmp_path / "x.csv")
    assert code == 2 and "no such database" in err
    code, out, err = run("serve", tmp_path / "nowhere")
    assert code == 2 and "nowhere" in err
    design = make_design(tmp_path / "d")
    code, out, err = run("serve", design, "--admin-token", "short")
    assert code == 2 and "--admin-token" in err
    other = make_design(tmp_path / "other", PROTOCOL.replace("participants: 4", "participants: 8"))
    Database(other / "x.db", load_study(other).fingerprint).close()
    code, out, err = run("serve", design, "--db", other / "x.db", "--port", "1")
    assert code == 2 and "another design" in err
    (design / "clips" / sorted(os.listdir(design / "clips"))[0]).unlink()
    code, out, err = run("serve", design)
    assert code == 2 and "not found" in err and "clips/" in err


def test_a_protocol_without_recruitment_keeps_its_design_json():
    from stimuli.design import design_json

    plain = parse_protocol(PROTOCOL.replace("recruitment: {platform: prolific, completion_code: C0DE42}\n", ""))
    assert "recruitment" not in design_json(build_design(plain))["protocol"]
    with_it = design_json(build_design(parse_protocol(PROTOCOL)))["protocol"]["recruitment"]
    assert with_it == {"platform": "prolific", "completion_code": "C0DE42", "completion_url": "",
                       "participant_param": ""}
    with pytest.raises(Exception, match="completion_code"):
        parse_protocol(PROTOCOL.replace("C0DE42", "'a b<'"))


# -- a real server killed mid-study ---------------------------------------------------------------------

def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_server(design: Path, port: int, *options: str) -> subprocess.Popen:
    """``shapemotion serve`` in a process of its own, once it answers (the caller kills it); its log is
    ``serve.log`` beside the design folder (a pipe nobody reads would block a chatty server)."""
    log = (design.parent / "serve.log").open("ab")
    proc = subprocess.Popen([sys.executable, "-m", "stimuli.cli", "serve", str(design), "--port", str(port),
                             "--admin-token", ADMIN, *options], stdout=log, stderr=log)
    log.close()
    import httpx

    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        try:
            httpx.get(f"http://127.0.0.1:{port}/config.js", timeout=1)
            return proc
        except httpx.TransportError:
            if proc.poll() is not None:
                raise AssertionError((design.parent / "serve.log").read_text())
            time.sleep(0.2)
    proc.kill()
    raise AssertionError("the server did not start in 30 s")


def test_sigkill_mid_study_loses_nothing_and_participants_resume(tmp_path):
    import httpx

    design = make_design(tmp_path / "design")
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    proc = start_server(design, port)
    try:
        states = [httpx.post(f"{url}/api/sessions", json={"params": {"participant": f"p{n}"}}).json()
                  for n in range(4)]
        for n, s in enumerate(states):          # participant n has answered n trials
            for index in range(n):
                r = httpx.post(f"{url}/api/sessions/{s['session']}/trials", json={"index": index, "response": 2},
                               headers={"X-Session-Token": s["token"]})
                assert r.status_code == 200
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        proc = start_server(design, port)
        for n, s in enumerate(states):
            back = httpx.post(f"{url}/api/sessions", json={"params": {}, "resume": {"session": s["session"],
                                                                                      "token": s["token"]}}).json()
            assert (back["session"], back["next"], back["list"]) == (s["session"], n, s["list"])
        progress = httpx.get(f"{url}/admin/progress", headers={"Authorization": f"Bearer {ADMIN}"}).json()
        assert sum(p["answers"] for p in progress) == 0 + 1 + 2 + 3
    finally:
        proc.kill()
        proc.wait(10)
