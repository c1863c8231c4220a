"""A self-hosted jsPsych experiment: a static folder any web server (or a laptop) can serve.

Layout of the exported folder::

    index.html        loads lib/, config.js and experiment.js
    config.js         the design: every participant's trial list, clip paths, HTML-escaped texts
    experiment.js     the runtime (jsPsych 8 timeline; see its header for the URL parameters)
    lib/              jsPsych and its plugins, copied from the project's ``node_modules`` (npm ci)
    clips/            the clips, copied from the source folder when they exist there

The runtime replays ``trials.csv`` exactly: the list follows from the participant number (or a
between-group URL parameter), so blocks, practice, familiarisation, repetitions, trial order and
left/right placement are the design's. The data format is documented in ``docs/readme_survey.md``.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

from jinja2 import Environment, FileSystemLoader, select_autoescape

from stimuli.errors import StimuliError
from stimuli.survey.source import SurveySource, clip_url
from stimuli.survey.text import (BLOCK_INTRO, CONSENT_AGREE, CONTINUE, END_TEXT, FAMILIARIZATION_INTRO,
                                 PRACTICE_INTRO, answer_labels, attention_html, consent_html, escape,
                                 instructions_html, question_html)

RUNTIME = Path(__file__).with_name("runtime")
# (file in node_modules, name in lib/), in the order index.html loads them.
LIBRARIES = [
    ("jspsych/dist/index.browser.min.js", "jspsych.js"),
    ("@jspsych/plugin-preload/dist/index.browser.min.js", "plugin-preload.js"),
    ("@jspsych/plugin-html-button-response/dist/index.browser.min.js", "plugin-html-button-response.js"),
    ("@jspsych/plugin-video-button-response/dist/index.browser.min.js", "plugin-video-button-response.js"),
    ("jspsych/css/jspsych.css", "jspsych.css"),
]
TEXTS = {"rank_step": "Choice {k}: which clip is the best of those left?", "finish": "Finish",
         # the hint above each clip says how this page replays it (a click on the clip; it has no controls)
         "watch": "You can answer once the clip has played to the end; click the clip to watch it again.",
         "saved": "Thank you! Your answers are saved. You may close this page.",
         "loading": "Loading the clips…", "load_error": "The clips could not be loaded. Please tell the experimenter.",
         # shapemotion serve (config.server): saving at the end, and what the participant is told if it fails
         "saving": "Saving your answers…",
         "save_error": "Some answers could not be saved. Please reload this page to finish the study.",
         "start_error": "The study could not be started. Please reload this page, or tell the experimenter."}


def node_modules() -> Path:
    """Where jsPsych is installed: ``$SHAPEMOTION_NODE_MODULES`` or the project's ``node_modules``."""
    configured = os.environ.get("SHAPEMOTION_NODE_MODULES")
    return Path(configured) if configured else Path(__file__).resolve().parents[2] / "node_modules"


def config(source: SurveySource, post_url: str = "", video_base_url: str | None = None) -> dict:
    """Everything experiment.js needs, with all protocol text already HTML-escaped.

    Clips are relative paths inside the folder, or ``video_base_url`` + path when they are served
    elsewhere (that server must allow cross-origin requests: the clips are preloaded).
    """
    p = source.protocol
    labels = answer_labels(p)
    texts = {"consent": consent_html(p), "instructions": instructions_html(p), "question": question_html(p),
             "agree": escape(CONSENT_AGREE), "continue": escape(CONTINUE),
             "practice_intro": escape(PRACTICE_INTRO), "fam_intro": escape(FAMILIARIZATION_INTRO),
             "block_intro": escape(BLOCK_INTRO), "end": escape(END_TEXT)}
    texts |= {k: escape(v) for k, v in TEXTS.items()}
    used = {t["stimulus_id"] for t in source.trials}
    return _attention(p, labels) | {
        "protocol": p.name,
        "between": source.between,
        "response": {"type": p.response.type, "labels": labels, "labels_html": [escape(x) for x in labels]},
        "clip": _shown_size(p.clip.width, p.clip.height),
        "text": texts,
        "clips": {s.stimulus_id: clip_url(video_base_url, s.file) for s in source.stimuli if s.stimulus_id in used},
        "lists": _lists(source),
        "post_url": post_url,
    }


def _attention(p, labels: list[str]) -> dict:
    """``attention``: when and what the checks ask (the answer spelled as its button), or nothing."""
    checks = p.attention_checks
    if checks is None:
        return {}
    key = " ".join(checks.answer.split()).casefold()
    answer = next(label for label in labels if " ".join(label.split()).casefold() == key)
    return {"attention": {"every": checks.every, "answer": answer, "prompt": attention_html(p)}}


def _shown_size(width: int, height: int, widest: int = 1280) -> dict:
    """The clip's size on the page before fitting to the window: at most ``widest`` wide, aspect kept.

    >>> _shown_size(1920, 540)
    {'width': 1280, 'height': 360}
    """
    shown = min(width, widest)
    return {"width": shown, "height": round(height * shown / width)}


def _lists(source: SurveySource) -> list[dict]:
    """One entry per design participant: between groups and the trials in order."""
    by_participant: dict[int, list[dict]] = {}
    for row in source.trials:
        by_participant.setdefault(int(row["participant"]), []).append(row)
    out = []
    for number, rows in sorted(by_participant.items()):
        rows.sort(key=lambda r: int(r["trial"]))
        groups = {name: rows[0][name] for name in source.between if name in rows[0]}
        trials = [{"id": r["stimulus_id"], "kind": r["kind"], "block": int(r["block"]),
                   "block_label": r["block_label"], "trial": int(r["trial"]), "repetition": int(r["repetition"]),
                   "positions": list(source.stimulus(r["stimulus_id"]).arrangement)} for r in rows]
        out.append({"list": number, "groups": groups, "trials": trials})
    return out


def config_js(data: dict) -> str:
    """``window.SHAPEMOTION_CONFIG = …;`` with ``<``, ``>``, ``&`` as JSON escapes (never closes a tag)."""
    text = json.dumps(data, ensure_ascii=True, separators=(",", ":"))
    text = text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")
    return f"window.SHAPEMOTION_CONFIG = {text};\n"


def index_html(source: SurveySource) -> str:
    env = Environment(loader=FileSystemLoader(RUNTIME), autoescape=select_autoescape(["html", "j2"]),
                      keep_trailing_newline=True)
    scripts = [f"lib/{name}" for _, name in LIBRARIES if name.endswith(".js")]
    p = source.protocol
    return env.get_template("index.html.j2").render(title=p.title or p.name, scripts=scripts, version="0.1.0")


def write_jspsych(source: SurveySource, out_dir: str | Path, post_url: str = "",
                  video_base_url: str | None = None) -> list[str]:
    """Write the experiment folder (all or nothing: built in a temporary folder, then moved into place).

    Returns the stimulus ids whose clips were not found in the source folder (the folder still works
    once they are copied into ``clips/``). With ``video_base_url`` the clips are not copied.
    """
    out_dir = Path(out_dir)
    modules = node_modules()
    missing_libs = [src for src, _ in LIBRARIES if not (modules / src).is_file()]
    if missing_libs:
        raise StimuliError(f"{modules}: jsPsych is not installed ({missing_libs[0]} missing); run 'make setup' "
                           f"(npm ci) in the project, or set SHAPEMOTION_NODE_MODULES")
    if out_dir.exists() and (not out_dir.is_dir() or any(out_dir.iterdir())):
        raise StimuliError(f"{out_dir}: exists and is not an empty folder; choose a new --out folder")
    data = config(source, post_url, video_base_url)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=out_dir.parent))
    try:
        (tmp / "lib").mkdir()
        for src, name in LIBRARIES:
            shutil.copyfile(modules / src, tmp / "lib" / name)
        shutil.copyfile(RUNTIME / "experiment.js", tmp / "experiment.js")
        (tmp / "config.js").write_text(config_js(data), encoding="utf-8")
        (tmp / "index.html").write_text(index_html(source), encoding="utf-8")
        missing = [] if video_base_url else _copy_clips(source, tmp, data["clips"])
        tmp.chmod(0o755)  # mkdtemp makes it private; a web server must read it
        if out_dir.exists():
            out_dir.rmdir()
        tmp.rename(out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return missing


def _copy_clips(source: SurveySource, target: Path, clips: dict[str, str]) -> list[str]:
    missing = []
    for sid in clips:
        file = source.stimulus(sid).file
        src = source.folder / file
        if src.is_file():
            (target / file).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(src, target / file)
        else:
            missing.append(sid)
    return missing
