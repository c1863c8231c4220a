"""Rate limiting in ``shapemotion serve``: a burst over the limit gets 429 with Retry-After, stores nothing
and is counted for the admin; a participant who answers as people do never meets it; the page waits
the Retry-After and sends again (headless Chromium).
"""

from __future__ import annotations

import pytest

from stimuli.serve.app import create_app
from stimuli.serve.db import Database
from stimuli.serve.limits import RateLimiter, parse_rate
from stimuli.serve.study import load_study
from test_serve import ADMIN, Clock, answer, free_port, make_design, snapshot, start, start_server

pytestmark = pytest.mark.filterwarnings("ignore:Using `httpx` with `starlette.testclient`")
ADMIN_HEADERS = {"Authorization": f"Bearer {ADMIN}"}


def served_with(tmp_path, **limits):
    from starlette.testclient import TestClient

    design = make_design(tmp_path / "design")
    study = load_study(design)
    db = Database(design / "shapemotion-serve.db", study.fingerprint)
    clock = Clock()
    client = TestClient(create_app(study, db, ADMIN, expire_s=600, clock=clock, **limits))
    client.db, client.clock = db, clock
    return client


def test_a_burst_over_the_limit_gets_429_and_stores_nothing(tmp_path):
    client = served_with(tmp_path, rate=1.0, burst=3)
    s = start(client, participant="fast")                        # 1 start of the address's 3
    tok = {"X-Session-Token": s["token"]}
    assert [answer(client, s, i).status_code for i in range(3)] == [200, 200, 200]   # the session's 3
    before = snapshot(client.db)
    refused = [answer(client, s, 3), answer(client, s, 2),
               client.post(f"/api/sessions/{s['session']}/events", headers=tok, json={"kind": "load_failed",
                                                                                       "clip": "clips/x.mp4"}),
               client.post(f"/api/sessions/{s['session']}/finish", headers=tok, json={}),
               client.get(f"/api/sessions/{s['session']}", headers=tok)]
    assert [r.status_code for r in refused] == [429] * 5
    assert all(r.headers["retry-after"] == "1" and "too many requests" in r.json()["error"] for r in refused)
    assert snapshot(client.db) == before                         # nothing stored, not even 'seen'
    # the admin sees them: on the session's list, and by route
    progress = client.get("/admin/progress", headers=ADMIN_HEADERS).json()
    assert {p["list"]: p["rate_limited"] for p in progress}[s["list"]] == 5
    assert sum(p["rate_limited"] for p in progress) == 5
    limits = client.get("/admin/limits", headers=ADMIN_HEADERS).json()
    assert limits == {"rate_per_s": 1.0, "burst": 3,
                      "refused": {"start": 0, "resume": 1, "trials": 2, "events": 1, "finish": 1}}
    # after Retry-After the same request goes through
    client.clock.now += 1
    assert answer(client, s, 3).json() == {"stored": True, "next": 4}
    client.db.close()


def test_each_session_has_its_own_bucket_and_starts_are_limited_per_address(tmp_path):
    client = served_with(tmp_path, rate=0.5, burst=2)
    a, b = start(client, participant="a"), start(client, participant="b")
    third = client.post("/api/sessions", json={"params": {"participant": "c"}})
    assert third.status_code == 429 and third.headers["retry-after"] == "2"
    assert client.db.session_of("c") is None
    for s in (a, b):                                              # a's burst does not spend b's
        assert [answer(client, s, i).status_code for i in range(3)] == [200, 200, 429]
    client.clock.now += 2
    assert start(client, participant="c")["list"] == 3
    client.db.close()


def test_a_participant_answering_as_people_do_never_meets_the_default_limit(tmp_path):
    """Answers a second apart, each sent twice (a retry), a reload that resumes, a block's worth of failed
    clips reported at once: all under the defaults (5/s, burst 100)."""
    client = served_with(tmp_path)
    for n in range(30):          # a lab behind one address starting together
        s = start(client, participant=f"p{n}")
    for index in range(4):
        client.clock.now += 1.0
        assert answer(client, s, index).status_code == answer(client, s, index).status_code == 200
        if index == 1:
            for k in range(40):
                client.post(f"/api/sessions/{s['session']}/events", headers={"X-Session-Token": s["token"]},
                            json={"kind": "load_failed", "clip": f"clips/{k}.mp4"}).raise_for_status()
            back = client.post("/api/sessions", json={"params": {}, "resume": {"session": s["session"],
                                                                                  "token": s["token"]}})
            assert back.json()["next"] == 2
    assert client.post(f"/api/sessions/{s['session']}/finish", headers={"X-Session-Token": s["token"]},
                       json={}).status_code == 200
    limits = client.get("/admin/limits", headers=ADMIN_HEADERS).json()
    assert sum(limits["refused"].values()) == 0
    client.db.close()


def test_without_a_limit_nothing_is_refused(tmp_path):
    client = served_with(tmp_path, rate=0)
    s = start(client, participant="bench")
    assert all(answer(client, s, i % 4).status_code == 200 for i in range(150))
    assert client.get("/admin/limits", headers=ADMIN_HEADERS).json()["rate_per_s"] is None
    client.db.close()


def test_the_per_session_event_cap_is_final_not_a_rate_limit(tmp_path):
    """Past 200 clip events a session's further events are refused for good: a 429 without Retry-After,
    which the page records instead of sending again (it resends only a 429 that names a wait)."""
    client = served_with(tmp_path, rate=0)
    s = start(client, participant="broken")

    def post():
        return client.post(f"/api/sessions/{s['session']}/events", headers={"X-Session-Token": s["token"]},
                           json={"kind": "play_failed", "clip": "clips/x.mp4"})

    assert all(post().status_code == 200 for _ in range(200))
    last = post()
    assert last.status_code == 429 and "retry-after" not in last.headers
    client.db.close()


def test_the_bucket_refills_at_its_rate():
    limiter = RateLimiter(rate=2.0, burst=4)
    assert [limiter.take("k", 0.0) for _ in range(5)] == [0.0, 0.0, 0.0, 0.0, 0.5]
    assert limiter.take("k", 0.25) == pytest.approx(0.25)       # half a token back: 0.25 s to go
    assert limiter.take("k", 0.5) == 0.0
    assert [limiter.take("k", 100.0) for _ in range(5)].count(0.0) == 4     # never more than the burst


def test_bad_rate_options_are_refused_naming_them(tmp_path, run_cli):
    assert parse_rate("2.5 / s") == 2.5 and parse_rate("30/min") == 0.5
    design = make_design(tmp_path / "d")
    for option, value in (("--rate", "fast"), ("--rate", "5/h"), ("--burst", "0")):
        code, out, err = run_cli("serve", design, option, value, "--admin-token", ADMIN)
        assert code == 2 and option in err, (option, err)


def test_the_page_waits_the_retry_after_and_sends_again(tmp_path):
    """A study served with a tiny limit (1 request/s, burst 1): the page meets 429s, waits, and every answer
    is stored once, with no error recorded."""
    from test_survey_browser import ARGS, CHROMIUM, make_clips

    if not CHROMIUM.exists():
        pytest.skip("Debian chromium is not installed (make setup installs it)")
    import httpx
    from playwright.sync_api import sync_playwright

    from conftest import buttons_enabled
    from test_serve_browser import BUTTONS

    design = make_design(tmp_path / "design")
    make_clips(design, seconds=0.5)
    port = free_port()
    proc = start_server(design, port, "--rate", "1/s", "--burst", "1")
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
            page = browser.new_page()
            page.goto(f"http://127.0.0.1:{port}/?participant=quick&redirect=0")
            page.get_by_role("button", name="I agree").click()
            page.get_by_role("button", name="Continue").click()
            for trial in range(4):      # answered as soon as the buttons allow: faster than 1/s with events
                page.wait_for_function(f"() => window.SHAPEMOTION_STATUS.position === {trial}", timeout=30_000)
                page.wait_for_function(buttons_enabled(BUTTONS), timeout=30_000)
                page.locator(BUTTONS, has_text="Heavy").click()
            page.get_by_role("button", name="Finish").click()
            page.wait_for_function("() => window.SHAPEMOTION_STATUS.done", timeout=60_000)
            status = page.evaluate("window.SHAPEMOTION_STATUS")
            browser.close()
        limits = httpx.get(f"http://127.0.0.1:{port}/admin/limits", headers=ADMIN_HEADERS).json()
        progress = httpx.get(f"http://127.0.0.1:{port}/admin/progress", headers=ADMIN_HEADERS).json()
    finally:
        proc.kill()
        proc.wait(10)
    assert status["errors"] == [] and status["saved"] == 4
    assert status["limited"] > 0 and sum(limits["refused"].values()) == status["limited"]
    assert [(p["finished"], p["answers"]) for p in progress if p["finished"]] == [(1, 4)]
