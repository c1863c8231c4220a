"""What the study server knows about the study: the design's lists, the files it may serve, and how an
answer is checked and turned into a row of the export.

Everything here comes from the design or render folder (``design.json``, ``trials.csv``, the clips);
nothing a participant sends is trusted beyond the answer itself: the export row's stimulus, block,
trial and placement are the design's, looked up from the list position the answer is for.

>>> from stimuli.serve.study import check_answer
>>> check_answer("likert", ["Light", "Heavy"], [], 1)
1
>>> check_answer("likert", ["Light", "Heavy"], [], 2)
Traceback (most recent call last):
...
ValueError: response: expected a whole number from 0 to 1 (the index of the button), got 2
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

from stimuli.errors import StimuliError
from stimuli.survey import jspsych
from stimuli.survey.checks import after_every_test
from stimuli.survey.source import SurveySource, load_source

PROLIFIC_COMPLETION = "https://app.prolific.com/submissions/complete?cc={code}"


@dataclass
class Study:
    """A design ready to serve: its lists by number, the page's config and the files by URL path."""

    source: SurveySource
    lists: dict[int, dict]                 # list number -> {"list", "groups", "trials"}
    config: dict                           # config.js without the lists (each page asks for its own)
    files: dict[str, Path] = field(repr=False)   # URL path (no leading /) -> file on disk
    fingerprint: str = ""

    @property
    def protocol(self):
        return self.source.protocol

    @property
    def response_type(self) -> str:
        return self.protocol.response.type

    def completion_url(self) -> str | None:
        """Where a finished participant is sent (the protocol's ``recruitment``), or None."""
        r = self.protocol.recruitment
        if r is None:
            return None
        url = r.completion_url or (PROLIFIC_COMPLETION if r.platform == "prolific" else "")
        return url.replace("{code}", r.completion_code) if url else None

    def participant_param(self) -> str:
        """The URL parameter that carries the platform's participant id."""
        r = self.protocol.recruitment
        if r is not None and r.participant_param:
            return r.participant_param
        return "PROLIFIC_PID" if r is None or r.platform == "prolific" else "participant"


def load_study(folder: str | Path) -> Study:
    """Read a design or render folder for serving; a missing clip or jsPsych install is a StimuliError.

    The clips must be in the folder: the server is the only place they are served from.
    """
    source = load_source(folder)
    data = jspsych.config(source)
    lists = {}
    for entry in data.pop("lists"):
        entry["trials"] = with_checks(entry["trials"], data.get("attention"))
        for index, trial in enumerate(entry["trials"]):
            trial["index"] = index
        lists[entry["list"]] = entry
    data["server"] = True
    modules = jspsych.node_modules()
    files = {}
    for src, name in jspsych.LIBRARIES:
        if not (modules / src).is_file():
            raise StimuliError(f"{modules}: jsPsych is not installed ({src} missing); run 'make setup' (npm ci) "
                               f"in the project, or set SHAPEMOTION_NODE_MODULES")
        files[f"lib/{name}"] = modules / src
    files["experiment.js"] = jspsych.RUNTIME / "experiment.js"
    for sid, url in data["clips"].items():
        path = source.folder / source.stimulus(sid).file
        if not path.is_file():
            raise StimuliError(f"{path}: clip of stimulus {sid!r} not found; 'shapemotion serve' serves the clips "
                               f"from the folder (render them, or copy them to {source.stimulus(sid).file})")
        files[url] = path
    digest = hashlib.sha256(json.dumps([source.protocol.name, lists], sort_keys=True).encode()).hexdigest()[:16]
    return Study(source, lists, data, files, digest)


def with_checks(trials: list[dict], attention: dict | None) -> list[dict]:
    """The list with an attention check after every ``every``-th test trial, none after the last.

    The place is the static page's (experiment.js, buildTimeline); served, the checks are items of the
    list, so they are stored, resumed and validated by position like the design's trials.

    >>> trials = [{"kind": "practice", "block": 1}] + [{"kind": "test", "block": 1}] * 5
    >>> [t["kind"] for t in with_checks(trials, {"every": 2})]
    ['practice', 'test', 'test', 'attention_check', 'test', 'test', 'attention_check', 'test']
    """
    if not attention:
        return trials
    return after_every_test(trials, attention["every"], lambda t: {"kind": "attention_check", "block": t["block"]})


def check_answer(response_type: str, labels: list[str], positions: list[str], response, kind: str = "test"):
    """The answer if it fits the trial, else ValueError saying what was expected.

    Familiarisation clips have one button (0); Likert and forced choice answer with a button index;
    a ranking answers with every label once, best first; an attention check shows the answer labels as
    buttons (whatever the response type) and answers with a label's index.
    """
    if kind == "familiarization":
        n = 1
    elif kind == "attention_check":
        n = len(labels)
    elif response_type == "ranking":
        if (not isinstance(response, list) or sorted(map(str, response)) != sorted(labels)
                or not all(isinstance(x, str) for x in response)):
            raise ValueError(f"response: expected each of the labels {labels} once, best first")
        return response
    else:
        n = len(labels) if response_type == "likert" else len(positions)
    if isinstance(response, bool) or not isinstance(response, int) or not 0 <= response < n:
        raise ValueError(f"response: expected a whole number from 0 to {n - 1} (the index of the button), "
                         f"got {json.dumps(response)[:40]}")
    return response


def check_rt(rt) -> float | None:
    """A response time in ms (0 to one day), or None when the browser sent none."""
    if rt is None:
        return None
    if isinstance(rt, bool) or not isinstance(rt, (int, float)) or not 0 <= rt <= 86_400_000:
        raise ValueError(f"rt: expected milliseconds from 0 to 86400000, got {json.dumps(rt)[:40]}")
    return float(rt)


def export_row(study: Study, session: dict, trial: dict, response, rt: float | None) -> dict:
    """One row of the export, as the static jsPsych runtime writes a trial (the columns ``analyze`` reads).

    ``session`` holds ``id``, ``participant`` and ``list``; ``trial`` is the design's trial at this position.
    """
    if trial["kind"] == "attention_check":
        return check_row(study, session, trial, response, rt)
    entry = study.lists[session["list"]]
    labels = study.config["response"]["labels"]
    answered = trial["kind"] != "familiarization"
    row = {"rt": "" if rt is None else round(rt), "trial_type": "video-button-response",
           "trial_index": trial["index"], "participant": session["participant"], "session": session["id"],
           "list": session["list"], **entry["groups"], "protocol": study.protocol.name,
           "stimulus_id": trial["id"] if answered else "", "clip_id": trial["id"], "kind": trial["kind"],
           "practice": 0 if trial["kind"] == "test" else 1, "block": trial["block"],
           "block_label": trial["block_label"], "trial": trial["trial"], "repetition": trial["repetition"]}
    positions = trial["positions"]
    if len(positions) == 2:
        row |= {"left": positions[0], "right": positions[1]}
    elif len(positions) > 2:
        row["positions"] = "|".join(positions)
    if not answered:
        row["response"] = response
    elif study.response_type == "ranking":
        row |= {"response": json.dumps(response), "response_label": response[0]}
    elif study.response_type == "likert":
        row |= {"response": response, "response_label": labels[response], "rating": response + 1}
    else:
        row |= {"response": response, "response_label": labels[response], "chosen": positions[response]}
    return row


def check_row(study: Study, session: dict, trial: dict, response: int, rt: float | None) -> dict:
    """An attention check's row, as the static runtime writes it (attentionCheck in experiment.js): the
    requested and the given label, which ``analyze`` judges again (analysis/responses/attention.py)."""
    entry = study.lists[session["list"]]
    asked, given = study.config["attention"]["answer"], study.config["response"]["labels"][response]
    return {"rt": "" if rt is None else round(rt), "trial_type": "html-button-response",
            "trial_index": trial["index"], "participant": session["participant"], "session": session["id"],
            "list": session["list"], **entry["groups"], "protocol": study.protocol.name,
            "attention_check": 1, "attention_answer": asked, "response": response, "response_label": given,
            "attention_passed": int(given == asked)}
