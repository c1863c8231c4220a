"""Qualtrics Survey Format (``.qsf``): the JSON file Qualtrics exports and imports (Create project →
Survey → From a file).

The file holds ``SurveyEntry`` (the survey's identity) and ``SurveyElements``: ``BL`` (blocks and
their question-randomisation options), ``FL`` (survey flow), ``SO`` (options), ``SCO``, ``PROJ``,
``STAT``, ``QC`` (question count), ``RS`` (response set) and one ``SQ`` per question. The procedure:

consent → instructions → *BlockRandomizer* (one of the between groups, ``EvenPresentation``, which
sets the group's embedded data) → [*BlockRandomizer* over arrangement rotations] → the blocks
(a *BlockRandomizer* over them when the order is random or counterbalanced), each a *Group* of
familiarisation page(s), practice intro + practice questions, and the test questions (one per page,
in random order — or, with ``blocks.trials: fixed``, in the design's fixed order with question
randomisation off; every stimulus ``repetitions`` times) → end.

With ``blocks.nested`` the blocks are nested: the randomizer (or, with ``order: fixed``, the declared
sequence) holds one *Group* per main block (e.g. ``SEX=F``), each holding the main block's
familiarisation page(s) and then a *BlockRandomizer* (``EvenPresentation``; a plain sequence when
fixed) over *Groups* of its sub-blocks (practice + test, as above), so a main block's sub-blocks are
always shown together and the familiarisation once before them.

With ``attention_checks``, a test block holds check questions (export tags ``attention_check_1``, …) in
fixed slots (:mod:`stimuli.survey.checks`): question randomisation is then Qualtrics's *Advanced*
form, whose ``FixedOrder`` lists one entry per slot, ``{~Randomized~}`` where a randomly drawn test
question goes and the check's ``QID`` where it stays.

IDs are derived from the protocol name, so the same design gives a byte-identical file.
"""

from __future__ import annotations

import hashlib
import json
import math
import string

from stimuli.survey.checks import CHECK_TAG, block_slots, interleave
from stimuli.survey.plan import BlockPlan, GroupPlan, MainBlockPlan, RotationPlan, build_plan, export_tag
from stimuli.survey.qsf_questions import descriptive, video_question
from stimuli.survey.source import SurveySource, clip_url
from stimuli.survey.text import (FAMILIARIZATION_INTRO, PRACTICE_INTRO, consent_html, escape, instructions_html,
                                 attention_html, question_html, video_html)

ALPHABET = string.digits + string.ascii_letters
NEVER = "0000-00-00 00:00:00"
ROTATION_FIELD = "arrangement_rotation"
PROTOCOL_FIELD = "shapemotion_protocol"
RANDOMIZED_SLOT = "{~Randomized~}"   # a FixedOrder slot that Qualtrics fills with a randomly drawn question


def qualtrics_id(prefix: str, *parts: str) -> str:
    """A Qualtrics-style id (``SV_``/``BL_``/``RS_`` + 15 base-62 characters) derived from ``parts``.

    >>> qualtrics_id("BL_", "demo", "block 1")[:3], len(qualtrics_id("BL_", "x"))
    ('BL_', 18)
    """
    number = int.from_bytes(hashlib.sha256("\x1f".join(parts).encode()).digest()[:12], "big")
    chars = []
    for _ in range(15):
        number, digit = divmod(number, 62)
        chars.append(ALPHABET[digit])
    return prefix + "".join(chars)


class QsfBuilder:
    """Collects questions, blocks and flow elements with consecutive ``QID``/``FL`` numbers."""

    def __init__(self, source: SurveySource, video_base_url: str | None):
        self.source = source
        self.protocol = source.protocol
        self.base_url = video_base_url
        self.name = self.protocol.name
        self.survey_id = qualtrics_id("SV_", self.name)
        self.questions: list[dict] = []
        self.blocks: list[dict] = []
        self.flow_count = 1
        self.checks = 0
        self.slots: dict[int, list[int]] = {}   # id(BlockPlan) → after which test questions a check comes

    # -- ids ----------------------------------------------------------------------------------
    def flow_id(self) -> str:
        self.flow_count += 1
        return f"FL_{self.flow_count}"

    def next_qid(self) -> str:
        return f"QID{len(self.questions) + 1}"

    # -- questions and blocks -----------------------------------------------------------------
    def clip(self, stimulus) -> str:
        p = self.protocol
        return video_html(clip_url(self.base_url, stimulus.file), p.clip.width, p.clip.height)

    def add_text(self, tag: str, html_text: str, has_video: bool = False) -> str:
        qid = self.next_qid()
        self.questions.append(descriptive(self.survey_id, qid, tag, html_text, has_video))
        return qid

    def add_video_question(self, tag: str, stimulus) -> str:
        qid = self.next_qid()
        html_text = question_html(self.protocol) + self.clip(stimulus)
        self.questions.append(video_question(self.survey_id, qid, tag, html_text, self.protocol))
        return qid

    def add_check(self) -> str:
        """An attention check question: the protocol's request, the answer buttons, forced response."""
        qid = self.next_qid()
        self.checks += 1
        self.questions.append(video_question(self.survey_id, qid, CHECK_TAG.format(k=self.checks),
                                             attention_html(self.protocol), self.protocol, check=True))
        return qid

    def add_block(self, description: str, qids: list[str], randomize: str = "false", subset: int = 0,
                  kind: str = "Standard", fixed: frozenset[str] = frozenset()) -> str:
        """A block; ``randomize``: ``false`` (page per question, fixed order), ``RandomWithXPerPage``
        (all questions, random order, one per page), ``RandomWithOnlyX`` (a random ``subset``) or
        ``Advanced`` (a page per question; the ``fixed`` questions stay in their slots, the others are
        drawn at random into the remaining slots)."""
        block_id = qualtrics_id("BL_", self.name, description)
        elements = []
        for qid in qids:
            if elements and randomize in ("false", "Advanced"):
                elements.append({"Type": "Page Break"})
            elements.append({"Type": "Question", "QuestionID": qid})
        options = {"BlockLocking": "false", "RandomizeQuestions": randomize, "BlockVisibility": "Expanded"}
        if randomize == "Advanced":   # the shape of Qualtrics's own exports of "Advanced Randomization"
            options["Randomization"] = {"Advanced": {
                "FixedOrder": [q if q in fixed else RANDOMIZED_SLOT for q in qids],
                "RandomizeAll": [q for q in qids if q not in fixed], "RandomSubSet": [], "Undisplayed": [],
                "TotalRandSubset": 0, "QuestionsPerPage": 0}, "EvenPresentation": False}
        elif randomize == "RandomWithXPerPage":
            options["Randomization"] = {"Advanced": {"QuestionsPerPage": 1}, "EvenPresentation": False}
        elif randomize == "RandomWithOnlyX":
            options["Randomization"] = {"Advanced": {"TotalRandSubset": subset, "QuestionsPerPage": 1},
                                        "EvenPresentation": True}
        block = {"Type": kind, "Description": description[:100], "ID": block_id, "BlockElements": elements,
                 "Options": options}
        if kind == "Standard":
            block = {"Type": kind, "SubType": ""} | {k: v for k, v in block.items() if k != "Type"}
        self.blocks.append(block)
        return block_id

    # -- flow ---------------------------------------------------------------------------------
    def block_ref(self, block_id: str, kind: str = "Standard") -> dict:
        return {"ID": block_id, "Type": kind, "FlowID": self.flow_id(), "Autofill": []}

    def randomizer(self, flow: list[dict], subset: int) -> dict:
        return {"Type": "BlockRandomizer", "FlowID": self.flow_id(), "SubSet": subset, "EvenPresentation": True,
                "Flow": flow}

    def group(self, description: str, flow: list[dict]) -> dict:
        return {"Type": "Group", "FlowID": self.flow_id(), "Description": description[:100], "Flow": flow}

    def embedded(self, values: dict[str, str]) -> dict:
        return {"Type": "EmbeddedData", "FlowID": self.flow_id(), "EmbeddedData": [
            {"Description": k, "Type": "Custom", "Field": k, "VariableType": "String", "DataVisibility": [],
             "AnalyzeText": False, "Value": v} for k, v in values.items()]}


def build_qsf(source: SurveySource, video_base_url: str | None = None) -> dict:
    """The whole QSF document of ``source``'s procedure, as a JSON-ready dict."""
    b = QsfBuilder(source, video_base_url)
    p = source.protocol
    consent = b.add_block("Consent", [b.add_text("consent", consent_html(p))], kind="Default")
    instructions = b.add_block("Instructions", [b.add_text("instructions", instructions_html(p))])
    fields = {PROTOCOL_FIELD: p.name} | {name: "" for name in source.between}
    plans = build_plan(source)
    for rotation in (r for g in plans for r in g.rotations):
        b.slots |= block_slots(rotation.blocks, p.attention_checks)
    if any(r.index is not None for g in plans for r in g.rotations):
        fields[ROTATION_FIELD] = ""
    flow = [b.embedded(fields), b.block_ref(consent, "Block"), b.block_ref(instructions)]
    flow += _assignment_flow(b, plans)
    flow.append({"Type": "EndSurvey", "FlowID": b.flow_id()})
    return _document(b, flow)


def _assignment_flow(b: QsfBuilder, plans: list[GroupPlan]) -> list[dict]:
    """Between groups, balanced by Qualtrics (one of them per respondent, evenly presented)."""
    branches = []
    for plan in plans:
        inner = ([b.embedded(plan.groups)] if plan.groups else []) + _rotation_flow(b, plan)
        branches.append(b.group(f"Group {plan.label}", inner) if len(plans) > 1 else inner)
    return [b.randomizer(branches, 1)] if len(plans) > 1 else branches[0]


def _rotation_flow(b: QsfBuilder, plan: GroupPlan) -> list[dict]:
    if len(plan.rotations) == 1:
        return _blocks_flow(b, plan, plan.rotations[0], "")
    branches = []
    for rotation in plan.rotations:
        tag = f" rotation {rotation.index}"
        inner = [b.embedded({ROTATION_FIELD: str(rotation.index)})] + _blocks_flow(b, plan, rotation, tag)
        branches.append(b.group(f"{plan.label}{tag}", inner))
    return [b.randomizer(branches, 1)]


def _blocks_flow(b: QsfBuilder, plan: GroupPlan, rotation: RotationPlan, tag: str) -> list[dict]:
    """The rotation's blocks, or with nesting its main blocks, each a Group; randomised unless fixed."""
    if rotation.main_blocks:
        units = [b.group(f"{plan.label} | {main.label}{tag}", _main_block_flow(b, plan, main, tag))
                 for main in rotation.main_blocks]
    else:
        units = [b.group(f"{plan.label} | {block.label}{tag}", _block_flow(b, plan, block, tag))
                 for block in rotation.blocks]
    return _in_block_order(b, units)


def _in_block_order(b: QsfBuilder, units: list[dict]) -> list[dict]:
    """Groups presented all, in random order (evenly) — or as listed when ``blocks.order`` is fixed."""
    if len(units) > 1 and b.protocol.blocks.order != "fixed":
        return [b.randomizer(units, len(units))]
    return units


def _main_block_flow(b: QsfBuilder, plan: GroupPlan, main: MainBlockPlan, tag: str) -> list[dict]:
    """A main block: its familiarisation page(s) once, then its sub-blocks (each a Group) in block order."""
    flow = []
    if main.familiarization:
        flow.append(_familiarization_ref(b, f"{plan.label} | {main.label}{tag}", main.familiarization))
    subs = [b.group(f"{plan.label} | {block.label}{tag}", _block_flow(b, plan, block, tag)) for block in main.blocks]
    return flow + _in_block_order(b, subs)


def _familiarization_ref(b: QsfBuilder, name: str, clips: list) -> dict:
    """The familiarisation block (an intro, then one clip per page) and its place in the flow."""
    qids = [b.add_text("fam_intro", f"<p>{escape(FAMILIARIZATION_INTRO)}</p>")]
    qids += [b.add_text(s.stimulus_id, b.clip(s), has_video=True) for s in clips]
    return b.block_ref(b.add_block(f"{name} familiarization", qids))


def _block_flow(b: QsfBuilder, plan: GroupPlan, block: BlockPlan, tag: str) -> list[dict]:
    """Familiarisation page(s), practice, then the test questions of one block."""
    name = f"{plan.label} | {block.label}{tag}"
    repetitions = b.protocol.repetitions
    flow = []
    if block.familiarization:
        flow.append(_familiarization_ref(b, name, block.familiarization))
    if block.practice_count:
        copies = math.ceil(block.practice_count / len(block.practice))
        intro = b.add_block(f"{name} practice intro", [b.add_text("practice_intro", f"<p>{escape(PRACTICE_INTRO)}</p>")])
        qids = [b.add_video_question(export_tag(s.stimulus_id, c, copies), s)
                for c in range(1, copies + 1) for s in block.practice]
        subset = block.practice_count < len(qids)
        practice = b.add_block(f"{name} practice", qids, "RandomWithOnlyX" if subset else "RandomWithXPerPage",
                               block.practice_count)
        flow += [b.block_ref(intro), b.block_ref(practice)]
    qids = [b.add_video_question(export_tag(s.stimulus_id, rep, repetitions), s) for s, rep in block.tests]
    checks: list[str] = []

    def check() -> str:
        checks.append(b.add_check())
        return checks[-1]

    qids = interleave(qids, b.slots.get(id(block), []), check)
    if b.protocol.blocks.trials == "fixed":
        order = "false"   # as listed, a page each
    else:
        order = "Advanced" if checks else "RandomWithXPerPage"
    flow.append(b.block_ref(b.add_block(f"{name} test", qids, order, fixed=frozenset(checks))))
    return flow


def _document(b: QsfBuilder, flow: list[dict]) -> dict:
    sid, p = b.survey_id, b.protocol
    response_set = qualtrics_id("RS_", b.name)
    trash = {"Type": "Trash", "Description": "Trash / Unused Questions", "ID": qualtrics_id("BL_", b.name, "trash"),
             "BlockElements": []}

    def element(kind: str, primary: str, payload, secondary=None, tertiary=None) -> dict:
        return {"SurveyID": sid, "Element": kind, "PrimaryAttribute": primary, "SecondaryAttribute": secondary,
                "TertiaryAttribute": tertiary, "Payload": payload}

    entry = {
        "SurveyID": sid, "SurveyName": p.title or p.name, "SurveyDescription": p.source or None,
        "SurveyOwnerID": "UR_shapemotion", "SurveyBrandID": "", "DivisionID": None, "SurveyLanguage": "EN",
        "SurveyActiveResponseSet": response_set, "SurveyStatus": "Inactive", "SurveyStartDate": NEVER,
        "SurveyExpirationDate": NEVER, "SurveyCreationDate": NEVER, "CreatorID": "UR_shapemotion",
        "LastModified": NEVER, "LastAccessed": NEVER, "LastActivated": NEVER, "Deleted": None,
    }
    options = {
        "BackButton": "false", "SaveAndContinue": "true", "SurveyProtection": "PublicSurvey",
        "BallotBoxStuffingPrevention": "true", "NoIndex": "Yes", "SecureResponseFiles": "true",
        "SurveyExpiration": "None", "SurveyTermination": "DefaultMessage", "Header": "", "Footer": "",
        "ProgressBarDisplay": "None", "PartialData": "+1 week", "ValidationMessage": "", "PreviousButton": "",
        "NextButton": " → ", "SurveyTitle": p.title or p.name, "SkinLibrary": "", "SkinType": "MQ", "Skin": "",
        "NewScoring": 1,
    }
    elements = [
        element("BL", "Survey Blocks", [b.blocks[0], trash] + b.blocks[1:]),
        element("FL", "Survey Flow", {"Type": "Root", "FlowID": "FL_1", "Flow": flow,
                                       "Properties": {"Count": b.flow_count, "RemovedFieldsets": []}}),
        element("PL", "Preview Link", {"PreviewType": "Brand", "PreviewID": qualtrics_id("", b.name, "preview")}),
        element("RS", response_set, None, "Default Response Set"),
        element("SCO", "Scoring", {"ScoringCategories": [], "ScoringCategoryGroups": [],
                                   "ScoringSummaryCategory": None, "ScoringSummaryAfterQuestions": 0,
                                   "ScoringSummaryAfterSurvey": 0, "DefaultScoringCategory": None,
                                   "AutoScoringCategory": None}),
        element("PROJ", "CORE", {"ProjectCategory": "CORE", "SchemaVersion": "1.1.0"}, None, "1.1.0"),
        element("STAT", "Survey Statistics", {"MobileCompatible": True, "ID": "Survey Statistics"}),
        element("QC", "Survey Question Count", None, str(len(b.questions))),
        element("SO", "Survey Options", options),
    ] + b.questions
    return {"SurveyEntry": entry, "SurveyElements": elements}


def qsf_text(source: SurveySource, video_base_url: str | None = None) -> str:
    """The QSF file's text: UTF-8 JSON, keys in Qualtrics's order."""
    return json.dumps(build_qsf(source, video_base_url), indent=2, ensure_ascii=False) + "\n"
