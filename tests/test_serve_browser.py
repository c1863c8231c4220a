"""``shapemotion serve`` with real participants: 24 headless Chromium pages (Debian's, through playwright,
several browser contexts of one browser, 20 at once) click through a study served by uvicorn on 127.0.0.1.

Some participants abandon after their first answer, some reload the page mid-way, and the server is
killed with SIGKILL and restarted while the second wave is answering. Then: every answered trial is in
the database once; the finished sessions' list counts differ by at most one; and the ANOVA of the
server's export equals the ANOVA of the same answers as the jsPsych runtime recorded them in the page
(the data the static export saves).
"""

from __future__ import annotations

import asyncio
import io
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pandas as pd
import pytest
from conftest import buttons_enabled

from test_serve import ADMIN, PROTOCOL, free_port, start_server
from test_survey_browser import ARGS, CHROMIUM, import_and_anova, make_clips

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]
BUTTONS = "#jspsych-video-button-response-btngroup button"
WAVE_ONE, WAVE_TWO = 20, 4
ABANDON = {3, 8, 13, 18}          # leave after their first answer
RELOAD = {2, 7, 12, 17}           # reload the page after their second answer (wave one)
KILL_AFTER = 2                    # wave two: the server is killed once each has answered this many


def rating(n: int, body: str) -> int:
    """Participant n's rating (1–3) of a body: heavier bodies rated heavier, with some spread."""
    return (3 if n % 3 else 2) if body == "Hi1" else (1 if n % 2 else 2)


async def participant(browser, url: str, n: int, log: dict, answered_event: asyncio.Event | None = None):
    """One participant: consent, instructions, each clip watched to its end, then rated."""
    context = await browser.new_context()
    page = await context.new_page()
    record = log[n] = {"answers": 0, "frames": [], "finished": False}
    await page.goto(f"{url}/?PROLIFIC_PID=pid{n:02d}&STUDY_ID=st1&SESSION_ID=se{n}")
    try:
        while True:
            await page.wait_for_selector("#jspsych-video-button-response-stimulus, "
                                         "#jspsych-html-button-response-stimulus", timeout=60_000)
            if await page.query_selector("#jspsych-html-button-response-stimulus"):
                button = page.locator("#jspsych-html-button-response-btngroup button")
                name = await button.inner_text()
                if name == "Finish":       # everything answered: keep what the page recorded, then finish
                    record["frames"].append(await page.evaluate("window.SHAPEMOTION_DATA()"))
                    await button.click()
                    await page.wait_for_url("**/complete?cc=C0DE42", timeout=60_000)
                    record["finished"] = True
                    return
                await button.click()
                continue
            await page.wait_for_function(buttons_enabled(BUTTONS), timeout=60_000)
            clip = await page.evaluate("window.SHAPEMOTION_STATUS.clip")
            label = ["Light", "Medium", "Heavy"][rating(n, "Hi1" if "Hi1" in clip else "Lo1") - 1]
            await page.locator(BUTTONS, has_text=label).click()
            record["answers"] += 1
            done = record["answers"]
            if n in ABANDON or (n in RELOAD and done == 2) or (answered_event and done == KILL_AFTER):
                await page.wait_for_function(f"() => window.SHAPEMOTION_STATUS.saved >= {done}", timeout=60_000)
            if n in ABANDON:
                record["left"] = time.monotonic()
                return
            if n in RELOAD and done == 2:
                record["frames"].append(await page.evaluate("window.SHAPEMOTION_DATA()"))
                await page.reload()
            if answered_event and done == KILL_AFTER:
                answered_event.n = getattr(answered_event, "n", 0) + 1
                if answered_event.n == WAVE_TWO:
                    answered_event.set()
    finally:
        await context.close()


async def study(url: str, design: Path, port: int, log: dict, server: dict) -> None:
    """Wave one (20 at once), the abandoned sessions' expiry, then wave two with the server killed."""
    from playwright.async_api import async_playwright

    async with async_playwright() as p:
        browser = await p.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
        try:
            started = time.monotonic()
            await asyncio.gather(*(participant(browser, url, n, log) for n in range(1, WAVE_ONE + 1)))
            server["wave_one_s"] = time.monotonic() - started
            # the abandoned sessions expire (--expire-min 0.2 = 12 s) and free their lists for wave two
            last_left = max(log[n]["left"] for n in ABANDON)
            await asyncio.sleep(max(0.0, last_left + 13 - time.monotonic()))
            answered = asyncio.Event()

            async def kill_and_restart():
                await answered.wait()
                os.kill(server["proc"].pid, signal.SIGKILL)
                server["proc"].wait(10)
                await asyncio.sleep(1.0)          # the pages' requests fail meanwhile and are retried
                server["proc"] = await asyncio.to_thread(start_server, design, port, "--expire-min", "0.2")
                server["restarted"] = True

            await asyncio.gather(kill_and_restart(), *(participant(browser, url, n, log, answered)
                                                       for n in range(WAVE_ONE + 1, WAVE_ONE + WAVE_TWO + 1)))
        finally:
            await browser.close()


def test_participants_in_chromium_are_saved_balanced_and_analysed_alike(tmp_path):
    if not CHROMIUM.exists():
        pytest.skip("Debian chromium is not installed (make setup installs it)")
    from stimuli.design import build_design, write_design
    from stimuli.protocol import parse_protocol

    port = free_port()
    url = f"http://127.0.0.1:{port}"
    text = PROTOCOL.replace("participants: 4", "participants: 8").replace(
        "completion_code: C0DE42}", f"completion_code: C0DE42, completion_url: '{url}/complete?cc={{code}}'}}")
    design = tmp_path / "design"
    write_design(build_design(parse_protocol(text)), design)
    make_clips(design, seconds=0.5)
    log: dict = {}
    server = {"proc": start_server(design, port, "--expire-min", "0.2")}
    try:
        asyncio.run(study(url, design, port, log, server))
        export = httpx.get(f"{url}/admin/export.csv", headers={"Authorization": f"Bearer {ADMIN}"})
        progress = httpx.get(f"{url}/admin/progress", headers={"Authorization": f"Bearer {ADMIN}"}).json()
    finally:
        server["proc"].kill()
        server["proc"].wait(10)
    assert server.get("restarted")
    rows = pd.read_csv(io.StringIO(export.text), dtype=str, keep_default_na=False)
    assert (rows["end"] == "1").sum() == WAVE_ONE + WAVE_TWO - len(ABANDON)   # each finished session's closing row
    rows = rows[rows["end"] != "1"]

    # every answered trial is in the database once
    assert not rows.duplicated(["participant", "trial_index"]).any()
    stored = rows.groupby("participant").size()
    for n, record in log.items():
        assert stored.get(f"pid{n:02d}", 0) == record["answers"], (n, record)
        assert record["finished"] == (n not in ABANDON)
    assert sum(r["answers"] for r in log.values()) == len(rows)

    # balanced: the finished sessions per list differ by at most one
    finished = [p["finished"] for p in progress]
    assert sum(finished) == WAVE_ONE + WAVE_TWO - len(ABANDON)
    assert max(finished) - min(finished) <= 1, progress

    # the stored ratings are the clicked ones
    for row in rows.itertuples():
        n = int(row.participant[3:])
        assert int(row.rating) == rating(n, "Hi1" if row.stimulus_id.endswith("Hi1") else "Lo1")

    # analyze on the export = analyze on the same answers as the page's jsPsych data
    finished_ids = {f"pid{n:02d}" for n, r in log.items() if r["finished"]}
    (tmp_path / "export.csv").write_text(export.text)
    served = pd.read_csv(tmp_path / "export.csv", dtype=str, keep_default_na=False)   # abandoned ones included
    page_frames = [pd.read_csv(io.StringIO(f), dtype=str, keep_default_na=False) for r in log.values()
                   if r["finished"] for f in r["frames"]]
    page_rows = pd.concat(page_frames, ignore_index=True)
    # a reloaded page recorded two runs (jsPsych's counters restart): joined into the one uninterrupted
    # run the static export would have saved, or the importer keeps only the finished second part
    page_rows = page_rows[page_rows["clip_id"] != ""].copy()
    page_rows["trial_index"] = page_rows.groupby("participant").cumcount().astype(str)
    page_rows["time_elapsed"] = page_rows["trial_index"]
    result_a, table_a = import_and_anova(design, [served], tmp_path / "a.csv")
    result_b, table_b = import_and_anova(design, [page_rows], tmp_path / "b.csv")
    assert result_a.summary()["participants"] == result_b.summary()["participants"] == len(finished_ids)
    assert result_a.summary()["answers"] == result_b.summary()["answers"] == 4 * len(finished_ids)
    pd.testing.assert_frame_equal(table_a.effects, table_b.effects)
    assert table_a.effect("BODY")["F"] > 10


def test_a_clip_that_cannot_play_is_recorded_and_does_not_trap_the_participant(tmp_path):
    """Clips whose bytes load but do not decode: each trial records play_failed (with the browser in the
    sessions table) and enables the answers, so the participant finishes."""
    if not CHROMIUM.exists():
        pytest.skip("Debian chromium is not installed (make setup installs it)")
    from playwright.sync_api import sync_playwright

    from test_serve import make_design

    design = make_design(tmp_path / "design")       # placeholder bytes, not video
    port = free_port()
    proc = start_server(design, port)
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
            page = browser.new_page()
            page.goto(f"http://127.0.0.1:{port}/?participant=broken&redirect=0")
            page.get_by_role("button", name="I agree").click()
            page.get_by_role("button", name="Continue").click()
            for trial in range(4):      # trial i is on screen once its clip's failure is recorded
                page.wait_for_function(f"() => window.SHAPEMOTION_STATUS.failed.length > {trial}", timeout=30_000)
                page.wait_for_function(buttons_enabled(BUTTONS), timeout=30_000)
                page.locator(BUTTONS, has_text="Medium").click()
            page.get_by_role("button", name="Finish").click()
            page.wait_for_function("() => window.SHAPEMOTION_STATUS.done", timeout=30_000)
            status = page.evaluate("window.SHAPEMOTION_STATUS")
            data = pd.read_csv(io.StringIO(page.evaluate("window.SHAPEMOTION_DATA()")), dtype=str,
                               keep_default_na=False)
            browser.close()
        exported = subprocess_export(design, tmp_path / "r.csv")
    finally:
        proc.kill()
        proc.wait(10)
    assert len(status["failed"]) == 4 and all(f.startswith("play_failed:") for f in status["failed"])
    assert (data.loc[data["clip_id"] != "", "failed_video"] != "").all()
    answers, sessions = exported
    assert (answers["end"] == "1").sum() == 1 and (answers["response"] == "1").sum() == 4
    (row,) = sessions.itertuples()
    assert row.status == "finished" and "Chrome" in row.browser and row.failed_clips.count("play_failed:") == 4


def subprocess_export(design: Path, out: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """``shapemotion serve export`` of the running server's database (WAL: readable while it serves)."""
    subprocess.run([sys.executable, "-m", "stimuli.cli", "serve", "export", str(design), "--out", str(out)],
                   check=True, capture_output=True)
    return tuple(pd.read_csv(path, dtype=str, keep_default_na=False)
                 for path in (out, out.with_name(f"{out.stem}_sessions.csv")))


def test_the_static_folder_posts_each_answer_to_post_trial(tmp_path):
    """Without a server of its own: ``?post_trial=URL`` POSTs each answer (JSON, with the browser) as it is given."""
    if not CHROMIUM.exists():
        pytest.skip("Debian chromium is not installed (make setup installs it)")
    import json

    from playwright.sync_api import sync_playwright

    from stimuli.design import build_design, write_design
    from stimuli.protocol import parse_protocol
    from stimuli.survey import export_survey
    from test_survey_browser import TINY, Server

    design = tmp_path / "design"
    write_design(build_design(parse_protocol(TINY)), design)
    make_clips(design, seconds=0.5)
    export_survey(design, "jspsych", tmp_path / "site")
    server = Server(tmp_path / "site")
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
            page = browser.new_page()
            page.goto(f"{server.url}/index.html?participant=3&save=0&simulate=data-only"
                      f"&post_trial={server.url}/trial")
            page.wait_for_function("() => window.SHAPEMOTION_STATUS.done && window.SHAPEMOTION_STATUS.saved === 4",
                                   timeout=30_000)
            csv = pd.read_csv(io.StringIO(page.evaluate("window.SHAPEMOTION_CSV")), dtype=str, keep_default_na=False)
            browser.close()
    finally:
        server.close()
    posted = sorted((json.loads(body) for body in server.posted), key=lambda p: int(p["trial"]))  # sent in parallel
    answered = csv[csv["stimulus_id"] != ""]
    assert [p["stimulus_id"] for p in posted] == answered["stimulus_id"].tolist()
    assert [str(p["response"]) for p in posted] == answered["response"].tolist()
    assert all("Chrome" in p["user_agent"] and p["participant"] == "3" for p in posted)
