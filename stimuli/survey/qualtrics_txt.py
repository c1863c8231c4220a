"""Qualtrics Advanced Format TXT: a plain-text fallback for accounts that cannot import QSF.

The format carries blocks, page breaks, questions (``[[ID:…]]`` sets the export tag), choices and
embedded data (``[[ED:field:value]]``), but no survey flow, randomisation or JavaScript. Those are
listed by :func:`manual_steps` (the CLI prints them) and must be set by hand after the import.

The questions of a block are imported in the order written, one per page, and the format has no way
to randomise them: that takes a manual step (random test order), while ``blocks.trials: fixed``
needs none — the test questions are written in the design's fixed order (every clip once per
repetition), and question randomisation must simply stay off.

The blocks are written group by group (and rotation by rotation), as in the QSF file; with
``blocks.nested``, main block by main block: its familiarisation block once, then its sub-blocks'
practice and test blocks (the manual steps say how to nest the randomizers). A ranking is
written as a matrix (items × rank) because the format has no rank-order question — its export columns
(``<tag>_1`` … ``<tag>_k`` = rank of the clip at each position) match a rank-order question's.

With ``attention_checks`` the test blocks hold the check questions (``attention_check_1``, …) at the
slots :mod:`stimuli.survey.checks` gives; a manual step says to keep them there when randomising.
"""

from __future__ import annotations

import math
import re

from stimuli.errors import StimuliError
from stimuli.orders import block_label
from stimuli.protocol import shown
from stimuli.survey.checks import CHECK_TAG, block_slots
from stimuli.survey.plan import BlockPlan, build_plan, export_tag
from stimuli.survey.qsf import PROTOCOL_FIELD, ROTATION_FIELD
from stimuli.survey.qsf_questions import NEXT_AFTER_VIEW_JS
from stimuli.survey.source import SurveySource, clip_url
from stimuli.survey.text import (FAMILIARIZATION_INTRO, PRACTICE_INTRO, answer_labels, attention_html, consent_html,
                                 escape, instructions_html, question_html, video_html)


# What ends a line of the TXT (Python's str.splitlines set): a question's text, a choice or an answer
# is one line, and a tag's text runs to its "]]".
LINE_BREAK = re.compile("[\n\r\v\f\x1c\x1d\x1e\x85\u2028\u2029]")


def txt_html(html_text: str) -> str:
    """HTML as one line of the TXT, its brackets as character references.

    A question's text and each choice are one line (a line break in a label made two choices), and a
    ``[[`` in them could open a tag; in HTML both forms show the same (a line break shows as a space).

    >>> txt_html("<p>Rate it\\n[[Block:x]]</p>")
    '<p>Rate it &#91;&#91;Block:x&#93;&#93;</p>'
    """
    return " ".join(html_text.split()).replace("[", "&#91;").replace("]", "&#93;")


def check_txt_text(source: SurveySource) -> None:
    """Refuse a protocol whose ``name`` the TXT cannot carry unchanged: it is written verbatim into
    ``[[ED:shapemotion_protocol:…]]`` (the response import matches the recorded name to the design's,
    so it cannot be escaped), where a line break or a bracket would end the tag and let the rest be
    read as blocks and questions.

    Everything else of the protocol is HTML here and is escaped (:func:`txt_html`).
    """
    name = source.protocol.name
    if LINE_BREAK.search(name) or "[" in name or "]" in name:
        raise StimuliError(f"{source.folder / 'design.json'}: protocol field name {shown(name)}: a Qualtrics TXT "
                           "records it in an [[ED:…]] tag, which a line break, '[' or ']' would end (the rest "
                           "of the name would be read as blocks and questions); rename the protocol without them")


def _tag_text(value: str, what: str) -> str:
    """A block name or export tag, which the TXT writes inside ``[[…]]``: made of factor levels and actor
    labels (letters, digits, ``_.+-``), so a line break or bracket here is a protocol the loader let through."""
    if LINE_BREAK.search(value) or "[" in value or "]" in value:
        raise StimuliError(f"{what} {shown(value)} (made of the protocol's factor levels and actor labels) holds a "
                           "line break or a bracket, which would end its [[…]] tag in the Qualtrics TXT")
    return value


class TxtWriter:
    def __init__(self, source: SurveySource, base_url: str | None):
        self.source, self.protocol, self.base_url = source, source.protocol, base_url
        self.lines = ["[[AdvancedFormat]]", ""]
        self.checks = 0

    def clip(self, stimulus) -> str:
        p = self.protocol
        return video_html(clip_url(self.base_url, stimulus.file), p.clip.width, p.clip.height)

    def block(self, name: str) -> None:
        self.lines += [f"[[Block:{_tag_text(name, 'block name')}]]", ""]

    def page_break(self) -> None:
        self.lines += ["[[PageBreak]]", ""]

    def text(self, tag: str, html_text: str) -> None:
        self.lines += ["[[Question:DB]]", f"[[ID:{_tag_text(tag, 'export tag')}]]", txt_html(html_text), ""]

    def check(self) -> None:
        """An attention check: the protocol's request and the answer buttons (no clip)."""
        self.checks += 1
        labels = [txt_html(escape(label)) for label in answer_labels(self.protocol)]
        self.lines += ["[[Question:MC:SingleAnswer:Horizontal]]", f"[[ID:{CHECK_TAG.format(k=self.checks)}]]",
                       txt_html(attention_html(self.protocol)), "[[Choices]]", *labels, ""]

    def video_question(self, tag: str, stimulus) -> None:
        labels = [txt_html(escape(label)) for label in answer_labels(self.protocol)]
        tag = _tag_text(tag, "export tag")
        body = txt_html(question_html(self.protocol) + self.clip(stimulus))
        if self.protocol.response.type == "ranking":
            ranks = [f"{i}" for i in range(1, len(labels) + 1)]
            self.lines += ["[[Question:Matrix]]", f"[[ID:{tag}]]", body, "[[Choices]]", *labels,
                           "[[Answers]]", *ranks, ""]
        else:
            self.lines += ["[[Question:MC:SingleAnswer:Horizontal]]", f"[[ID:{tag}]]", body, "[[Choices]]",
                           *labels, ""]


def txt_text(source: SurveySource, video_base_url: str | None = None) -> str:
    """The Advanced Format TXT file of ``source``."""
    check_txt_text(source)
    w = TxtWriter(source, video_base_url)
    p = source.protocol
    w.lines += [f"[[ED:{PROTOCOL_FIELD}:{p.name}]]", ""]
    w.block("Consent")
    w.text("consent", consent_html(p))
    w.block("Instructions")
    w.text("instructions", instructions_html(p))
    for plan in build_plan(source):
        for rotation in plan.rotations:
            suffix = f" rotation {rotation.index}" if rotation.index is not None else ""
            slots = block_slots(rotation.blocks, p.attention_checks)
            if not rotation.main_blocks:
                for block in rotation.blocks:
                    _write_block(w, f"{plan.label} | {block.label}{suffix}", block, slots.get(id(block), []))
            for main in rotation.main_blocks:           # nested: a main block's familiarisation, its sub-blocks
                _write_familiarization(w, f"{plan.label} | {main.label}{suffix}", main.familiarization)
                for block in main.blocks:
                    _write_block(w, f"{plan.label} | {block.label}{suffix}", block, slots.get(id(block), []))
    return "\n".join(w.lines).rstrip("\n") + "\n"


def _write_familiarization(w: TxtWriter, name: str, clips: list) -> None:
    """A familiarisation block: the intro, then one clip per page (nothing when there are no clips)."""
    if not clips:
        return
    w.block(f"{name} familiarization")
    w.text("fam_intro", f"<p>{escape(FAMILIARIZATION_INTRO)}</p>")
    for s in clips:
        w.page_break()
        w.text(s.stimulus_id, w.clip(s))


def _write_block(w: TxtWriter, name: str, block: BlockPlan, checks: list[int]) -> None:
    """A block's familiarisation, practice and test blocks; a check after each test position in ``checks``."""
    repetitions = w.protocol.repetitions
    _write_familiarization(w, name, block.familiarization)
    if block.practice_count:
        w.block(f"{name} practice")
        w.text("practice_intro", f"<p>{escape(PRACTICE_INTRO)}</p>")
        copies = math.ceil(block.practice_count / len(block.practice))
        for c in range(1, copies + 1):
            for s in block.practice:
                w.page_break()
                w.video_question(export_tag(s.stimulus_id, c, copies), s)
    w.block(f"{name} test")
    for i, (s, rep) in enumerate(block.tests):
        if i:
            w.page_break()
        w.video_question(export_tag(s.stimulus_id, rep, repetitions), s)
        if i + 1 in checks:
            w.page_break()
            w.check()


def manual_steps(source: SurveySource) -> list[str]:
    """What the TXT import cannot express, to be set in Qualtrics by hand (in this order)."""
    p = source.protocol
    plans = build_plan(source)
    steps = ["Survey flow: keep Consent, then Instructions first."]
    if len(plans) > 1:
        fields = ", ".join(source.between)
        steps.append(f"Survey flow: add a Randomizer (present 1 element, 'Evenly Present Elements' on) with one "
                     f"Group per between group ({', '.join(g.label for g in plans)}); in each Group set Embedded "
                     f"Data {fields} to the group's level(s) and put that group's blocks inside.")
    if any(len(g.rotations) > 1 for g in plans):
        where = "inside each group, " if len(plans) > 1 else ""
        steps.append(f"Survey flow: {where}add a Randomizer (present 1, evenly) with one Group per "
                     f"rotation ('rotation 0' …); set Embedded Data {ROTATION_FIELD} to its number.")
    mains = plans[0].rotations[0].main_blocks
    if mains and p.blocks.order != "fixed":
        steps.append(_nested_randomizer_step(p, mains))
    elif len(plans[0].rotations[0].blocks) > 1 and p.blocks.order != "fixed":
        steps.append(f"Survey flow: put each part's blocks (familiarization, practice, test) in a Group and add a "
                     f"Randomizer presenting all {len(plans[0].rotations[0].blocks)} Groups, evenly "
                     f"(block order: {p.blocks.order}).")
    if p.blocks.trials == "fixed":
        steps.append("Each 'test' block: leave Block Options > Question Randomization off (blocks.trials: fixed: "
                     "the questions are imported in the protocol's fixed order, one per page).")
    elif p.attention_checks is not None:
        steps.append("Each 'test' block: Block Options > Question Randomization > Advanced Randomization: put the "
                     "attention_check_… questions under 'Present in fixed order' in the places they were imported "
                     "(they keep their slot), every other question under 'Randomize these questions' (their slots "
                     "are filled in random order); keep the page breaks (one question per page).")
    else:
        steps.append("Each 'test' block: Block Options > Question Randomization > 'Randomly present … questions "
                     "per page' with 1 question per page (order is random within the block).")
    if any(b.practice_count for g in plans for r in g.rotations for b in r.blocks):
        steps.append("Each 'practice' block: Question Randomization > random order, one question per page "
                     f"(present {p.practice.per_block} of them).")
    steps.append("Every question with a clip: Add JavaScript (paste the snippet below) so that Next appears only "
                 "after the clip has played once; make the answer questions 'Force response'"
                 + (" (the attention_check_… questions too; they have no clip and need no JavaScript)."
                    if p.attention_checks is not None else "."))
    if p.response.type == "ranking":
        steps.append("Ranking questions were imported as matrices (rows = clips A…, columns = rank 1 = best); "
                     "add validation so that each rank is used once, or change them to Rank Order (drag and drop).")
    return steps + ["JavaScript for the clip questions:\n" + NEXT_AFTER_VIEW_JS]


def _nested_randomizer_step(p, mains) -> str:
    """The survey-flow step for nested blocks: a randomizer over main-block Groups, one over the sub-blocks
    inside each (with ``order: fixed`` the imported order is already the declared one: no step)."""
    first = p.blocks.by[0]
    subs = [block_label({k: v for k, v in b.cell.items() if k != first}) for b in mains[0].blocks]
    familiarization = ", after its familiarization block," if any(m.familiarization for m in mains) else ""
    return (f"Survey flow (blocks.nested): make one Group per main block ({', '.join(m.label for m in mains)}) "
            f"and inside it{familiarization} a Randomizer presenting its {len(subs)} sub-block Groups "
            f"({', '.join(subs)}: each the sub-block's practice and test blocks), evenly; then add a Randomizer "
            f"presenting all {len(mains)} main-block Groups, evenly (block order: {p.blocks.order}, the same "
            "rule at both levels; a main block's sub-blocks always come together).")
