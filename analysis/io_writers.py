"""Write simulated answers in the real export formats, so that the importer is exercised end to end.

- ``long``: one row per answer (participant, between factors, block, trial, stimulus_id, repetition,
  practice, response, rt); Likert as 1…k, k-AFC as the chosen level, rankings as ``a>b>c``.
- ``qualtrics``: the current 3-header-row CSV (export tags; question text; ImportId JSON), metadata
  columns StartDate … UserLanguage, embedded data ``participant`` and the between factors, one
  column per question (tag = stimulus id, ``_r<rep>`` when shown more than once; rank-order questions
  ``_1``…``_k``), block ``*_DO`` display-order columns and ``FL_*_DO``; values as choice text (default)
  or numbers. ``legacy=True`` writes the old 2-row form.
- ``jspsych``: ``jsPsych.data.get().csv()`` / ``.json()`` as the self-hosted experiment writes them
  (0-based button responses, rt in ms, every value quoted in CSV), with a consent row per participant.
"""

from __future__ import annotations

import csv
import io
import json
from collections import Counter
from datetime import datetime, timedelta

import numpy as np
import pandas as pd

from analysis.io_design import DesignInfo, arrangement_of
from analysis.simulate import SIMULATED_COLUMN

META = [("StartDate", "Start Date", {"ImportId": "startDate", "timeZone": "Europe/Dublin"}),
        ("EndDate", "End Date", {"ImportId": "endDate", "timeZone": "Europe/Dublin"}),
        ("Status", "Response Type", {"ImportId": "status"}),
        ("IPAddress", "IP Address", {"ImportId": "ipAddress"}),
        ("Progress", "Progress", {"ImportId": "progress"}),
        ("Duration (in seconds)", "Duration (in seconds)", {"ImportId": "duration"}),
        ("Finished", "Finished", {"ImportId": "finished"}),
        ("RecordedDate", "Recorded Date", {"ImportId": "recordedDate", "timeZone": "Europe/Dublin"}),
        ("ResponseId", "Response ID", {"ImportId": "_recordId"}),
        ("RecipientLastName", "Recipient Last Name", {"ImportId": "recipientLastName"}),
        ("RecipientFirstName", "Recipient First Name", {"ImportId": "recipientFirstName"}),
        ("RecipientEmail", "Recipient Email", {"ImportId": "recipientEmail"}),
        ("ExternalReference", "External Data Reference", {"ImportId": "externalDataReference"}),
        ("LocationLatitude", "Location Latitude", {"ImportId": "locationLatitude"}),
        ("LocationLongitude", "Location Longitude", {"ImportId": "locationLongitude"}),
        ("DistributionChannel", "Distribution Channel", {"ImportId": "distributionChannel"}),
        ("UserLanguage", "User Language", {"ImportId": "userLanguage"})]
LEGACY_META = ["ResponseID", "ResponseSet", "Name", "ExternalDataReference", "EmailAddress", "IPAddress",
               "Status", "StartDate", "EndDate", "Finished"]
START = datetime(2024, 3, 1, 9, 0, 0)


def _csv(rows: list[list], quote_all: bool = False) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n", quoting=csv.QUOTE_ALL if quote_all else csv.QUOTE_MINIMAL)
    writer.writerows(rows)
    return buffer.getvalue()


def _occurrences(sim: pd.DataFrame) -> pd.Series:
    """Per participant and stimulus, the 1-based showing (repetitions and repeated practice clips)."""
    counter: Counter = Counter()
    out = []
    for p, s in zip(sim["participant"], sim["stimulus_id"]):
        counter[(p, s)] += 1
        out.append(counter[(p, s)])
    return pd.Series(out, index=sim.index)


# -- long ----------------------------------------------------------------------------------------------

def long_text(sim: pd.DataFrame, design: DesignInfo) -> str:
    """Plain long CSV: one row per answer."""
    marked = [SIMULATED_COLUMN] if SIMULATED_COLUMN in sim else []   # says "simulated" to the report
    rows = [["participant", *design.between, "block", "trial", "stimulus_id", "repetition", "practice", "response",
             "rt", *marked]]
    for rec in sim.to_dict("records"):
        rows.append([rec["participant"], *(rec[b] for b in design.between), rec["block"], rec["trial"],
                     rec["stimulus_id"], rec["repetition"], int(rec["practice"]), _long_response(rec, design),
                     rec["rt"], *(rec[c] for c in marked)])
    return _csv(rows)


def _long_response(rec: dict, design: DesignInfo) -> str:
    if design.response_type == "likert":
        return str(rec["rating"])
    arrangement = arrangement_of(rec)
    if design.response_type == "afc":
        return arrangement[int(rec["position"]) - 1]
    return ">".join(arrangement[int(p) - 1] for p in str(rec["order"]).split("|"))


# -- Qualtrics -----------------------------------------------------------------------------------------

def _tags(sim: pd.DataFrame) -> pd.Series:
    occurrence = _occurrences(sim)
    repeated = occurrence.groupby(sim["stimulus_id"]).transform("max") > 1
    return pd.Series(np.where(repeated, sim["stimulus_id"] + "_r" + occurrence.astype(str), sim["stimulus_id"]),
                     index=sim.index)


def qualtrics_text(sim: pd.DataFrame, design: DesignInfo, values: str = "text", legacy: bool = False,
                   seed: int = 0) -> str:
    """A Qualtrics CSV export of the simulated answers (``values`` "text" or "numeric")."""
    sim = sim.copy()
    sim["tag"] = _tags(sim)
    order = {s: i for i, s in enumerate(design.conditions["stimulus_id"])}
    sid_of = dict(zip(sim["tag"], sim["stimulus_id"]))
    tags = sorted(sid_of, key=lambda t: (order[sid_of[t]], t))
    k = len(arrangement_of(design.conditions.iloc[0].to_dict())) if design.response_type == "ranking" else 0
    question_cols = [f"{t}_{i}" for t in tags for i in range(1, k + 1)] if k else tags
    qid = {t: f"QID{i + 10}" for i, t in enumerate(tags)}
    blocks = list(dict.fromkeys(sim.sort_values(["block"])["block_label"]))
    block_name = {b: "Block_" + "".join(c if c.isalnum() else "_" for c in b) for b in blocks}
    marked = [SIMULATED_COLUMN] if SIMULATED_COLUMN in sim else []   # embedded data that says "simulated"
    embedded = ["participant", "shapemotion_protocol", *design.between, *marked]
    # Qualtrics writes a block's display order only when it randomises its questions (blocks.trials: random)
    fixed = (design.protocol.get("blocks") or {}).get("trials") == "fixed"
    do_cols = ([] if fixed else [f"{block_name[b]}_DO" for b in blocks]) + ["FL_5_DO"]
    question = str(design.protocol.get("response", {}).get("question", "Your answer"))
    rng = np.random.default_rng(seed)
    body = []
    for n, (participant, rows) in enumerate(sim.groupby("participant", sort=True)):
        answers = dict(zip(rows["tag"], rows.to_dict("records")))
        cells = []
        for t in tags:
            cells += _qualtrics_values(answers.get(t), design, values, k)
        start = START + timedelta(minutes=37 * n)
        duration = int(rows["rt"].sum() + 60 * len(blocks))
        meta = _meta_values(start, duration, rng, values)
        by_block = rows.sort_values("trial").groupby("block_label", sort=False)["tag"].apply("|".join)
        shown = [] if fixed else [by_block.get(b, "") for b in blocks]
        flow = "|".join(block_name[b] for b in rows.sort_values("trial")["block_label"].drop_duplicates())
        group = [str(rows.iloc[0][b]) for b in design.between]
        protocol = str(design.protocol.get("name", ""))
        body.append((meta, cells, [str(participant), protocol, *group, *("1" for _ in marked)], shown + [flow]))
    if legacy:
        return _legacy(body, question_cols, embedded, do_cols, question)
    header = [m[0] for m in META] + question_cols + embedded + do_cols
    texts = [m[1] for m in META] + [f"{question} - {c}" for c in question_cols] + embedded + \
        [f"{c[:-3]} - Display Order" for c in do_cols]
    import_ids = [m[2] for m in META] + [{"ImportId": qid[c.rsplit("_", 1)[0]] + f"_{c.rsplit('_', 1)[1]}"}
                                         if k else {"ImportId": qid[c]} for c in question_cols] + \
        [{"ImportId": e} for e in embedded] + [{"ImportId": c} for c in do_cols]
    rows = [header, texts, [json.dumps(i, separators=(",", ":")) for i in import_ids]]
    rows += [meta + cells + emb + shown for meta, cells, emb, shown in body]
    return _csv(rows)


def _legacy(body, question_cols, embedded, do_cols, question) -> str:
    """The old 2-row export: V1…V10 metadata (names in row 2), export tags, question text."""
    header = [f"V{i + 1}" for i in range(len(LEGACY_META))] + question_cols + embedded + do_cols
    texts = LEGACY_META + [f"{question} - {c}" for c in question_cols] + embedded + do_cols
    rows = [header, texts]
    for meta, cells, emb, shown in body:
        current = dict(zip([m[0] for m in META], meta))
        legacy = [current["ResponseId"], "Default Response Set", "Anonymous", "", "", "", "0",
                  current["StartDate"], current["EndDate"], "1"]
        rows.append(legacy + cells + emb + shown)
    return _csv(rows)


def _meta_values(start: datetime, duration: int, rng: np.random.Generator, values: str) -> list[str]:
    end = start + timedelta(seconds=duration)
    rid = "R_" + "".join(rng.choice(list("ABCDEFGHJKLMNPQRSTUVWXYZabcdefghijkmnopqrstuvwxyz0123456789"), 15))
    fmt = "%Y-%m-%d %H:%M:%S"
    status, finished = ("0", "1") if values == "numeric" else ("IP Address", "True")
    return [start.strftime(fmt), end.strftime(fmt), status, "", "100", str(duration), finished, end.strftime(fmt),
            rid, "", "", "", "", "", "", "anonymous", "EN"]


def _qualtrics_values(rec: dict | None, design: DesignInfo, values: str, k: int) -> list[str]:
    if rec is None:
        return [""] * max(k, 1)
    if design.response_type == "likert":
        rating = int(rec["rating"])
        return [str(rating) if values == "numeric" else design.labels[rating - 1]]
    labels = _position_labels(design, len(arrangement_of(rec)))
    if design.response_type == "afc":
        position = int(rec["position"])
        return [str(position) if values == "numeric" else labels[position - 1]]
    order = [int(p) for p in str(rec["order"]).split("|")]
    return [str(order.index(pos) + 1) for pos in range(1, k + 1)]   # rank of each position


def _position_labels(design: DesignInfo, k: int) -> list[str]:
    labels = design.position_labels or [chr(ord("A") + i) for i in range(k)]
    return [str(x).title() if str(x).lower() in ("left", "right") else str(x) for x in labels]


# -- jsPsych -------------------------------------------------------------------------------------------

def jspsych_records(sim: pd.DataFrame, design: DesignInfo) -> list[dict]:
    """The trial objects ``jsPsych.data.get()`` holds (docs/readme_survey.md): consent, one video trial
    per answer, and the closing screen with ``end`` = 1."""
    out = []
    protocol = str(design.protocol.get("name", ""))
    for participant, rows in sim.groupby("participant", sort=True):
        common = {"participant": str(participant), "list": int(participant),
                  **{b: str(rows.iloc[0][b]) for b in design.between}, "protocol": protocol,
                  **({SIMULATED_COLUMN: 1} if SIMULATED_COLUMN in sim else {})}
        elapsed, index = 5000, 0
        out.append({"rt": 5000, "stimulus": "<p>Consent</p>", "response": 0, "trial_type": "html-button-response",
                    "trial_index": 0, "time_elapsed": elapsed, "internal_node_id": "0.0-0.0", **common})
        for rec in rows.sort_values("trial").to_dict("records"):
            index += 1
            rt = int(round(rec["rt"] * 1000))
            elapsed += rt + 4000
            out.append({"rt": rt, "stimulus": [f"clips/{rec['stimulus_id']}.mp4"],
                        "response": _jspsych_response(rec, design), "trial_type": "video-button-response",
                        "trial_index": index, "time_elapsed": elapsed, "internal_node_id": f"0.0-{index}.0",
                        **common, "stimulus_id": rec["stimulus_id"], "clip_id": rec["stimulus_id"],
                        "kind": "practice" if rec["practice"] else "test", "practice": int(bool(rec["practice"])),
                        "block": int(rec["block"]), "block_label": rec["block_label"], "trial": int(rec["trial"]),
                        "repetition": int(rec["repetition"]), **_placement(rec),
                        "response_label": _response_label(rec, design), **_score_columns(rec, design)})
        out.append({"rt": 1500, "stimulus": "<p>Thank you!</p>", "response": 0, "trial_type": "html-button-response",
                    "trial_index": index + 1, "time_elapsed": elapsed + 1500,
                    "internal_node_id": f"0.0-{index + 1}.0", **common, "end": 1})
    return out


def _placement(rec: dict) -> dict:
    arrangement = arrangement_of(rec)
    if len(arrangement) == 2:
        return {"left": arrangement[0], "right": arrangement[1]}
    return {"positions": "|".join(arrangement)} if arrangement else {}


def _response_label(rec: dict, design: DesignInfo) -> str:
    if design.response_type == "likert":
        return design.labels[int(rec["rating"]) - 1]
    labels = _position_labels(design, len(arrangement_of(rec)))
    if design.response_type == "afc":
        return labels[int(rec["position"]) - 1]
    return ""


def _score_columns(rec: dict, design: DesignInfo) -> dict:
    if design.response_type == "likert":
        return {"rating": int(rec["rating"])}
    if design.response_type == "afc":
        return {"chosen": arrangement_of(rec)[int(rec["position"]) - 1]}
    return {}


def _jspsych_response(rec: dict, design: DesignInfo):
    if design.response_type == "likert":
        return int(rec["rating"]) - 1
    if design.response_type == "afc":
        return int(rec["position"]) - 1
    labels = _position_labels(design, len(arrangement_of(rec)))
    return [labels[int(p) - 1] for p in str(rec["order"]).split("|")]


def jspsych_text(sim: pd.DataFrame, design: DesignInfo, as_json: bool) -> str:
    records = jspsych_records(sim, design)
    if as_json:
        return json.dumps(records, indent=1) + "\n"
    columns = list(dict.fromkeys(k for r in records for k in r))
    rows = [columns] + [[_cell(r.get(c)) for c in columns] for r in records]
    return _csv(rows, quote_all=True)


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, (list, dict)):
        return json.dumps(value, separators=(",", ":"))
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def export_text(sim: pd.DataFrame, design: DesignInfo, fmt: str, path_suffix: str = ".csv", seed: int = 0) -> str:
    """Text of ``sim`` in ``fmt``: long | qualtrics | qualtrics-numeric | qualtrics-legacy | jspsych."""
    if fmt == "long":
        return long_text(sim, design)
    if fmt in ("qualtrics", "qualtrics-text"):
        return qualtrics_text(sim, design, "text", seed=seed)
    if fmt == "qualtrics-numeric":
        return qualtrics_text(sim, design, "numeric", seed=seed)
    if fmt == "qualtrics-legacy":
        return qualtrics_text(sim, design, "numeric", legacy=True, seed=seed)
    if fmt == "jspsych":
        return jspsych_text(sim, design, as_json=path_suffix.lower() == ".json")
    raise ValueError(fmt)


FORMATS = ["long", "qualtrics", "qualtrics-numeric", "qualtrics-legacy", "jspsych"]
