"""Browser round trip: protocol → design → jsPsych folder → headless Chromium → CSV → import → ANOVA.

Uses Debian's Chromium (``/usr/bin/chromium``) through playwright — never a downloaded browser — and
a local HTTP server on 127.0.0.1 that also records POSTed data. The clips are tiny real H.264 files
made with imageio-ffmpeg (the renderer is not needed to test the survey).
"""

from __future__ import annotations

import functools
import http.server
import io
import json
import threading
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from conftest import buttons_enabled

from stimuli.design import build_design, write_design
from stimuli.protocol import load_protocol, parse_protocol
from stimuli.survey import export_survey

pytestmark = pytest.mark.slow
ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = Path("/usr/bin/chromium")
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--no-first-run", "--autoplay-policy=no-user-gesture-required"]
DONE = "window.SHAPEMOTION_STATUS && window.SHAPEMOTION_STATUS.done"
XSS = '<img src=x onerror="window.__xss=1">'

# A small Likert study a scripted participant can click through in seconds: SEX between, BODY within.
TINY = f"""
name: tiny_roundtrip
title: Tiny round trip
seed: 11
participants: 4
actors:
  - {{id: F_Hi1, label: Hi1, sex: F, height_m: 1.60, bmi: 28.1}}
  - {{id: F_Lo1, label: Lo1, sex: F, height_m: 1.60, bmi: 24.8}}
  - {{id: M_Hi1, label: Hi1, sex: M, height_m: 1.79, bmi: 32.1}}
  - {{id: M_Lo1, label: Lo1, sex: M, height_m: 1.81, bmi: 22.7}}
factors:
  - {{name: SEX, role: between, levels: [F, M], maps_to: sex}}
  - {{name: BODY, role: within, levels: [Hi1, Lo1], maps_to: body}}
display: {{layout: treadmill}}
clip: {{duration_s: 0.5, fps: 10, width: 64, height: 64}}
repetitions: 2
response:
  type: likert
  question: How heavy does the character look?
  labels: [Light, Medium, Heavy]
  instructions: 'Watch each clip. {XSS}'
analysis: {{dependent_measure: mean_rating}}
"""


# -- fixtures -------------------------------------------------------------------------------------

def make_clips(folder: Path, seconds: float = 1.0, fps: int = 10) -> None:
    """One tiny H.264 clip per stimulus of the design, at ``clips/<stimulus_id>.mp4``."""
    import imageio_ffmpeg

    for sid in pd.read_csv(folder / "conditions.csv")["stimulus_id"]:
        path = folder / "clips" / f"{sid}.mp4"
        path.parent.mkdir(parents=True, exist_ok=True)
        writer = imageio_ffmpeg.write_frames(str(path), (64, 48), fps=fps, codec="libx264", pix_fmt_out="yuv420p",
                                             macro_block_size=16, output_params=["-movflags", "+faststart"],
                                             ffmpeg_log_level="error")
        writer.send(None)
        for i in range(int(seconds * fps)):
            writer.send(np.full((48, 64, 3), 40 + 20 * i, np.uint8).tobytes())
        writer.close()


class Server:
    """Serves a folder on 127.0.0.1 and keeps the bodies POSTed to ``/collect``."""

    def __init__(self, folder: Path):
        posted = self.posted = []

        class Handler(http.server.SimpleHTTPRequestHandler):
            def log_message(self, *args):  # keep test output quiet
                pass

            def do_POST(self):
                posted.append(self.rfile.read(int(self.headers["Content-Length"])).decode("utf-8"))
                self.send_response(200)
                self.end_headers()

        self.httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(Handler, directory=folder))
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)
        self.thread.start()
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}"

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
        self.thread.join()


@pytest.fixture(scope="module")
def browser():
    if not CHROMIUM.exists():
        pytest.skip("Debian chromium is not installed (make setup installs it)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
        yield b
        b.close()


def exported(tmp_path: Path, protocol, participants=None) -> tuple[Path, Path]:
    design = tmp_path / "design"
    write_design(build_design(protocol, participants), design)
    make_clips(design)
    export_survey(design, "jspsych", tmp_path / "site")
    return design, tmp_path / "site"


def run_page(page, url: str) -> pd.DataFrame:
    page.goto(url)
    page.wait_for_function(DONE, timeout=60_000)
    return pd.read_csv(io.StringIO(page.evaluate("window.SHAPEMOTION_CSV")), dtype=str, keep_default_na=False)


def import_and_anova(design: Path, frames: list[pd.DataFrame], path: Path):
    from analysis.anova import anova
    from analysis.io_design import load_design
    from analysis.measures import anova_input
    from analysis.responses import import_responses

    pd.concat(frames, ignore_index=True).to_csv(path, index=False)
    info = load_design(design)
    result = import_responses(path, info)
    assert result.reconciles, result.summary()
    # every column real jsPsych writes is known: a "not imported" note here would be noise on every file
    assert not result.summary()["columns_not_imported"], result.summary()
    data = anova_input(result.data[~result.data["practice"]], info)
    return result, anova(data.data, data.dv, "participant", within=data.within, between=data.between)


# -- simulation mode on the paper's Experiment 2 ----------------------------------------------------

def test_simulated_participants_of_exp2_end_in_an_anova_table(tmp_path, browser):
    design, site = exported(tmp_path, load_protocol(ROOT / "protocols" / "exp2_com_vs_average.yaml"))
    server = Server(site)
    try:
        page = browser.new_page()
        frames, posted = [], []
        for n in range(1, 17):
            post = f"&post={server.url}/collect" if n == 1 else ""
            frames.append(run_page(page, f"{server.url}/index.html?participant={n}&simulate=data-only&save=0{post}"))
            posted.append(page.evaluate("window.SHAPEMOTION_STATUS.posted"))
        assert posted == [200] + [None] * 15
        page.close()
    finally:
        server.close()
    assert len(server.posted) == 1
    assert pd.read_csv(io.StringIO(server.posted[0]), dtype=str, keep_default_na=False).equals(frames[0])
    trials = pd.read_csv(design / "trials.csv", dtype=str)
    for n, frame in enumerate(frames, start=1):   # each run replays its list of trials.csv exactly
        shown = frame[frame["clip_id"] != ""]
        expected = trials[trials["participant"] == str(n)]
        assert shown["clip_id"].tolist() == expected["stimulus_id"].tolist()
        assert shown["trial"].tolist() == expected["trial"].tolist()
        assert frame["end"].iloc[-1] == "1"
    result, table = import_and_anova(design, frames, tmp_path / "responses.csv")
    assert result.summary()["participants"] == 16 and result.summary()["answers"] == 16 * 64
    method = table.effect("METHOD")
    assert (method["df1"], method["df2"]) == (1, 15) and 0 <= method["p"] <= 1
    assert {"METHOD", "SEX:METHOD", "GAIT:METHOD"} <= set(table.effects.index)


# -- a scripted participant who watches every clip and clicks ---------------------------------------

RATINGS = {1: {"Hi1": 3, "Lo1": 1}, 2: {"Hi1": 3, "Lo1": 2}, 3: {"Hi1": 2, "Lo1": 1}, 4: {"Hi1": 3, "Lo1": 1}}


def click_through(page, url: str, participant: int, checks: dict) -> None:
    """Consent and instructions, then per clip: buttons disabled until the clip has ended, then rate."""
    buttons = "#jspsych-video-button-response-btngroup button"
    page.goto(url)
    page.get_by_role("button", name="I agree").click()
    page.wait_for_selector("text=Watch each clip.")
    checks["xss_text"] = XSS in page.inner_text("body")   # shown as text, not run as markup
    page.get_by_role("button", name="Continue").click()
    while True:
        page.wait_for_selector("#jspsych-video-button-response-stimulus, #jspsych-html-button-response-stimulus")
        if page.query_selector("#jspsych-html-button-response-stimulus"):  # the closing screen
            page.get_by_role("button", name="Finish").click()
            break
        video = page.query_selector("#jspsych-video-button-response-stimulus")
        checks.setdefault("disabled_while_playing", []).append(
            page.evaluate(f"() => [...document.querySelectorAll('{buttons}')].every(b => b.disabled)"))
        page.wait_for_function(buttons_enabled(buttons), timeout=10_000)
        checks.setdefault("ended_when_enabled", []).append(video.evaluate("v => v.ended"))
        body = "Hi1" if "Hi1" in page.evaluate("() => window.SHAPEMOTION_STATUS.clip") else "Lo1"
        page.get_by_role("button", name=["Light", "Medium", "Heavy"][RATINGS[participant][body] - 1]).click()
    page.wait_for_function(DONE, timeout=30_000)


def test_scripted_participants_round_trip_to_the_anova(tmp_path, browser):
    design, site = exported(tmp_path, parse_protocol(TINY))
    server = Server(site)
    checks: dict = {}
    try:
        context = browser.new_context()
        page = context.new_page()
        for n in RATINGS:
            click_through(page, f"{server.url}/index.html?participant={n}&save=0&post={server.url}/collect", n, checks)
        assert page.evaluate("window.__xss") is None
        context.close()
    finally:
        server.close()
    assert checks["xss_text"] and len(server.posted) == 4
    assert all(checks["disabled_while_playing"]) and all(checks["ended_when_enabled"])
    assert len(checks["ended_when_enabled"]) == 4 * 4
    frames = [pd.read_csv(io.StringIO(body), dtype=str, keep_default_na=False) for body in server.posted]
    result, table = import_and_anova(design, frames, tmp_path / "responses.csv")
    # every answer arrived with the rating the participant clicked
    data = result.data
    for row in data.itertuples():
        assert int(row.rating) == RATINGS[int(row.participant)][row.BODY]
    # the BODY F of the split-plot, computed by hand from the clicked ratings
    groups = data.groupby("participant")["SEX"].first()
    diff = pd.Series({p: r["Hi1"] - r["Lo1"] for p, r in RATINGS.items()})
    diff.index = diff.index.astype(str)
    ss_body = len(diff) * diff.mean() ** 2 / 2
    ss_error = sum(((d - d.mean()) ** 2).sum() for _, d in diff.groupby(groups)) / 2
    expected_f = ss_body / (ss_error / (len(diff) - 2))
    assert table.effect("BODY")["F"] == pytest.approx(expected_f)
    assert table.effect("BODY")["p"] == pytest.approx(stats.f.sf(expected_f, 1, len(diff) - 2))
    assert table.effect("BODY")["F"] > 10      # heavier bodies were rated heavier by every participant


def test_visual_simulation_plays_the_clips(tmp_path, browser):
    _, site = exported(tmp_path, parse_protocol(TINY))
    server = Server(site)
    try:
        context = browser.new_context(accept_downloads=True)
        page = context.new_page()
        with page.expect_download(timeout=60_000) as download:   # the participant's local copy
            frame = run_page(page, f"{server.url}/index.html?participant=2&simulate=visual")
        saved = Path(download.value.path()).read_bytes().decode("utf-8")
        assert download.value.suggested_filename == "shapemotion_tiny_roundtrip_2.csv"
        assert saved == page.evaluate("window.SHAPEMOTION_CSV")
        context.close()
    finally:
        server.close()
    tests = frame[frame["kind"] == "test"]
    assert len(tests) == 4 and set(tests["response_label"]) <= {"Light", "Medium", "Heavy"}
    assert (tests["rating"].astype(int) == tests["response"].astype(int) + 1).all()


def test_ranking_is_recorded_as_an_order_of_labels(tmp_path, browser):
    design, site = exported(tmp_path, load_protocol(ROOT / "protocols" / "thesis_validation.yaml"), 4)
    server = Server(site)
    try:
        page = browser.new_page()
        frames = [run_page(page, f"{server.url}/index.html?participant={n}&simulate=data-only&save=0")
                  for n in range(1, 5)]
        page.close()
    finally:
        server.close()
    for frame in frames:
        steps = frame[frame["clip_id"] != ""]
        assert steps["rank_step"].tolist() == ["1", "2", "3"]
        (answer,) = steps.loc[steps["stimulus_id"] != "", "response"]
        order = json.loads(answer)
        assert sorted(order) == ["A", "B", "C", "D"]
        assert steps["response_label"].tolist() == order[:3]
    from analysis.io_design import load_design
    from analysis.responses import import_responses

    pd.concat(frames, ignore_index=True).to_csv(tmp_path / "r.csv", index=False)
    result = import_responses(tmp_path / "r.csv", load_design(design))
    assert result.reconciles and len(result.data) == 4
    assert all(sorted(r.split(">")) == sorted(["lean_mocap", "keyframed", "modifier", "obese_mocap"])
               for r in result.data["ranking"])


def test_group_and_list_come_from_the_url(tmp_path, browser):
    design, site = exported(tmp_path, parse_protocol(TINY))
    trials = pd.read_csv(design / "trials.csv", dtype=str)
    group_of = trials.groupby("participant")["SEX"].first()
    server = Server(site)
    try:
        page = browser.new_page()

        def run(query: str) -> pd.DataFrame:
            return run_page(page, f"{server.url}/index.html?simulate=data-only&save=0&{query}")

        by_number = [run(f"participant={n}") for n in range(1, 9)]
        males = [run(f"SEX=M&participant={n}") for n in (1, 2, 3)]
        fixed = run("list=3&participant=anna")
        anonymous = run("")
        page.close()
    finally:
        server.close()
    lists = [f["list"].iloc[0] for f in by_number]
    assert lists == ["1", "2", "3", "4", "1", "2", "3", "4"]          # participant N → list (N-1) mod 4 + 1
    assert sorted(f["SEX"].iloc[0] for f in by_number[:4]) == ["F", "F", "M", "M"]
    assert all(f["SEX"].iloc[0] == group_of[f["list"].iloc[0]] for f in by_number)
    assert [f["SEX"].iloc[0] for f in males] == ["M"] * 3
    assert males[0]["list"].iloc[0] != males[1]["list"].iloc[0]
    assert males[0]["list"].iloc[0] == males[2]["list"].iloc[0]         # 2 M lists: participant 3 wraps to 1
    assert (fixed["list"].iloc[0], fixed["participant"].iloc[0]) == ("3", "anna")
    assert anonymous["participant"].iloc[0].startswith("p") and anonymous["list"].iloc[0] in {"1", "2", "3", "4"}


def test_six_walkers_in_a_row_record_the_chosen_strength(tmp_path, browser):
    """Point-light 6-AFC: labels A–F, arrangements rotated over participants, votes per strength."""
    design, site = exported(tmp_path, load_protocol(ROOT / "protocols" / "thesis_pointlight.yaml"), 6)
    server = Server(site)
    try:
        page = browser.new_page()
        frames = [run_page(page, f"{server.url}/index.html?participant={n}&simulate=data-only&save=0")
                  for n in range(1, 7)]
        page.close()
    finally:
        server.close()
    from analysis.io_design import load_design
    from analysis.responses import import_responses

    for frame in frames:
        tests = frame[frame["kind"] == "test"]
        assert len(tests) == 10
        for row in tests.itertuples():
            positions = row.positions.split("|")
            assert row.response_label == "ABCDEF"[int(row.response)]
            assert row.chosen == positions[int(row.response)]
    pd.concat(frames, ignore_index=True).to_csv(tmp_path / "r.csv", index=False)
    result = import_responses(tmp_path / "r.csv", load_design(design))
    merged = result.data.merge(pd.concat(frames)[["participant", "stimulus_id", "chosen"]].astype(str),
                               on=["participant", "stimulus_id"], suffixes=("", "_browser"))
    assert result.reconciles and len(merged) == 60
    assert (merged["chosen"].astype(str) == merged["chosen_browser"]).all()
