"""The jsPsych trial page fits a laptop: question above the clip, answers right below it, no scrolling.

In Debian's Chromium (never a downloaded browser) at 1366×768 (and 1366×650) and 1920×1080, on a trial of each response
type the runtime supports (Likert, 2AFC, k-AFC, ranking): the question, the whole video element and every
answer button lie inside the viewport, the page does not scroll, and the boxes are ordered question →
video → buttons. Screenshots go to ``$SHAPEMOTION_LAYOUT_SHOTS`` when it is set (to look at them).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import buttons_enabled

from stimuli.protocol import load_protocol, parse_protocol
from tests.test_survey_browser import browser  # noqa: F401  (the fixture: Debian's Chromium)
from tests.test_survey_browser import TINY, Server, exported

ROOT = Path(__file__).resolve().parents[1]
SIZES = [(1366, 768), (1366, 650), (1920, 1080)]   # 1366×650: the page of a laptop browser with its bars
VIDEO = "#jspsych-video-button-response-stimulus"
BUTTONS = "#jspsych-video-button-response-btngroup button"
# the Likert round trip at the protocols' real clip size
LIKERT_720P = TINY.replace("width: 64, height: 64", "width: 1280, height: 720")

BOXES = """() => {
  const box = e => { const r = e.getBoundingClientRect(); return {top: r.top, bottom: r.bottom, left: r.left, right: r.right}; };
  return {question: box(document.querySelector('.shapemotion-question')),
          video: box(document.querySelector('#jspsych-video-button-response-stimulus')),
          buttons: [...document.querySelectorAll('#jspsych-video-button-response-btngroup button')].map(box),
          width: window.innerWidth, height: window.innerHeight,
          scroll_height: document.scrollingElement.scrollHeight};
}"""


def make_hd_clips(folder: Path, size=(1280, 720), frames: int = 5) -> None:
    """Replace the design's clips by short clips of the protocol's real size (the layout depends on it)."""
    import imageio_ffmpeg

    for sid in pd.read_csv(folder / "conditions.csv")["stimulus_id"]:
        path = folder / "clips" / f"{sid}.mp4"
        path.parent.mkdir(parents=True, exist_ok=True)
        writer = imageio_ffmpeg.write_frames(str(path), size, fps=10, codec="libx264", pix_fmt_out="yuv420p",
                                             ffmpeg_log_level="error")
        writer.send(None)
        for i in range(frames):
            writer.send(np.full((size[1], size[0], 3), 60 + 30 * i, np.uint8).tobytes())
        writer.close()


def first_question_trial(page, url: str) -> None:
    """Click through consent, instructions and intro screens (and familiarisation clips) to a rated clip."""
    page.goto(url)
    for _ in range(40):
        page.wait_for_selector(f"{VIDEO}, #jspsych-html-button-response-stimulus")
        if page.query_selector(VIDEO) and page.query_selector(".shapemotion-question"):
            page.wait_for_function(f"() => document.querySelector('{VIDEO}').readyState >= 1", timeout=20_000)
            page.wait_for_timeout(200)   # let the resize-driven layout settle
            return
        if page.query_selector(VIDEO):  # a familiarisation clip: its Continue is enabled once it has played
            page.wait_for_function(buttons_enabled(BUTTONS), timeout=20_000)
            page.click(BUTTONS)
        else:
            page.click("#jspsych-html-button-response-btngroup button")
        page.wait_for_timeout(50)
    raise AssertionError(f"{url}: no trial with a question after 40 screens")


def assert_fits(boxes: dict, where: str) -> None:
    height, width = boxes["height"], boxes["width"]
    everything = [boxes["question"], boxes["video"], *boxes["buttons"]]
    for box in everything:
        assert box["top"] >= 0 and box["bottom"] <= height, (where, box, height)
        assert box["left"] >= 0 and box["right"] <= width, (where, box, width)
    assert boxes["scroll_height"] <= height, (where, boxes["scroll_height"], height)
    assert boxes["question"]["bottom"] <= boxes["video"]["top"], where
    assert all(b["top"] >= boxes["video"]["bottom"] for b in boxes["buttons"]), where
    # the answers sit right below the clip, not at the foot of the window
    assert min(b["top"] for b in boxes["buttons"]) - boxes["video"]["bottom"] < 80, where


CASES = {  # response type: (protocol, design participants, clips of the real size)
    "likert": (lambda: parse_protocol(LIKERT_720P), None, True),
    "2afc": (lambda: load_protocol(ROOT / "protocols" / "exp2_com_vs_average.yaml"), None, False),
    "6afc": (lambda: load_protocol(ROOT / "protocols" / "thesis_pointlight.yaml"), 6, False),
    "ranking": (lambda: load_protocol(ROOT / "protocols" / "thesis_validation.yaml"), 4, False),
}


@pytest.mark.parametrize("kind", CASES)
def test_trial_page_fits_the_window_with_the_question_on_top(tmp_path, browser, kind):
    protocol, participants, hd = CASES[kind]
    design, site = exported(tmp_path, protocol(), participants)
    if hd:
        make_hd_clips(design)
        for clip in (design / "clips").iterdir():
            (site / "clips" / clip.name).write_bytes(clip.read_bytes())
    shots = os.environ.get("SHAPEMOTION_LAYOUT_SHOTS")
    server = Server(site)
    try:
        for width, height in SIZES:
            context = browser.new_context(viewport={"width": width, "height": height})
            page = context.new_page()
            first_question_trial(page, f"{server.url}/index.html?participant=1&save=0")
            boxes = page.evaluate(BOXES)
            if shots:
                page.screenshot(path=str(Path(shots) / f"{kind}_{width}x{height}.png"))
            assert_fits(boxes, f"{kind} at {width}x{height}")
            if kind == "likert":   # the clip is as large as the window allows: at least 60 % of its height
                assert boxes["video"]["bottom"] - boxes["video"]["top"] >= min(720, 0.6 * height), boxes
            if width == 1920:      # a window made smaller during the trial: the clip shrinks with it
                page.set_viewport_size({"width": 1366, "height": 650})
                page.wait_for_timeout(200)
                assert_fits(page.evaluate(BOXES), f"{kind} resized from 1920x1080 to 1366x650")
            context.close()
    finally:
        server.close()
