"""The procedure as a tree a survey tool can express: between groups → arrangement rotations → blocks.

Qualtrics and PsychoPy cannot replay ``trials.csv`` participant by participant; they randomise at run
time. This module states what they randomise over, with the same rules as :mod:`stimuli.design`:

- each cell of the between factors is one **group** (assigned evenly);
- when an ``alternatives`` factor is counterbalanced *between* participants, each group splits into
  one **rotation** per arrangement; rotation ``r`` shows condition ``c`` in the arrangement
  :func:`stimuli.orders.arrangement_index` gives participant rank ``r`` (the design's rule; for a
  Latin square ``(r + c) mod k``);
- each rotation holds the protocol's **blocks** in declared order, each with its familiarisation
  clips (in the design's order), its practice pool (and how many to draw) and its test questions
  (every test stimulus × repetition, repetition by repetition in declared order: the design's own
  order when ``blocks.trials`` is ``fixed``, which the exports then keep);
- with ``blocks.nested``, the rotation's blocks are sub-blocks and its **main blocks** group them
  (declared order): each main block holds the familiarisation clips, shown once before its
  sub-blocks, whose own familiarisation is then empty.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

from stimuli.orders import arrangement_index, arrangements, block_cells, block_label, main_blocks
from stimuli.survey.source import StimulusInfo, SurveySource


@dataclass
class BlockPlan:
    label: str                                  # "GAIT=walk", "SEX=F|GAIT=jog", "all"
    cell: dict[str, str]
    familiarization: list[StimulusInfo]
    practice: list[StimulusInfo]
    practice_count: int
    tests: list[tuple[StimulusInfo, int]]       # (stimulus, repetition 1…R), in design order


@dataclass
class MainBlockPlan:
    """With ``blocks.nested``: a main block (e.g. ``SEX=F``), its familiarisation and its sub-blocks."""

    label: str                                  # "SEX=F"
    cell: dict[str, str]
    familiarization: list[StimulusInfo]         # shown once, before the first of its sub-blocks
    blocks: list[BlockPlan]                     # its sub-blocks in declared order


@dataclass
class RotationPlan:
    index: int | None                           # None when there is no between-participant rotation
    blocks: list[BlockPlan]                     # every block (with nesting: every sub-block), declared order
    main_blocks: list[MainBlockPlan] = field(default_factory=list)   # [] unless blocks.nested


@dataclass
class GroupPlan:
    groups: dict[str, str]                      # between factor → level ({} when there is none)
    rotations: list[RotationPlan] = field(default_factory=list)

    @property
    def label(self) -> str:
        return block_label(self.groups) if self.groups else "all participants"


def build_plan(source: SurveySource) -> list[GroupPlan]:
    """The between groups of ``source`` with their rotations and blocks."""
    p = source.protocol
    between = p.factors_with_role("between")
    combos = itertools.product(*(f.levels for f in between))
    rotations = _rotation_indices(source)
    out = []
    for combo in combos:
        groups = dict(zip([f.name for f in between], combo))
        plan = GroupPlan(groups)
        for r in rotations:
            blocks = [_block(source, groups, cell, r) for cell in block_cells(p)]
            plan.rotations.append(RotationPlan(r, blocks, _main_blocks(source, groups, blocks)))
        out.append(plan)
    return out


def _main_blocks(source: SurveySource, groups: dict, blocks: list[BlockPlan]) -> list[MainBlockPlan]:
    """The main blocks of a nested protocol: the familiarisation moves from the sub-blocks to them."""
    out = []
    for cell, subs in main_blocks(source.protocol):
        fam = _familiarization_order(source, [s for s in source.of_kind("familiarization")
                                              if _matches(s, groups | cell)])
        for i in subs:
            blocks[i].familiarization = []
        out.append(MainBlockPlan(block_label(cell), cell, fam, [blocks[i] for i in subs]))
    return out


def _rotation_indices(source: SurveySource) -> list[int | None]:
    p = source.protocol
    n = len(arrangements(p))
    return list(range(n)) if p.alternatives.counterbalance == "between" and n > 1 else [None]


def _matches(stimulus: StimulusInfo, scope: dict[str, str]) -> bool:
    return all(stimulus.levels.get(k, v) == v for k, v in scope.items())


def _block(source: SurveySource, groups: dict, cell: dict, rotation: int | None) -> BlockPlan:
    p = source.protocol
    scope = groups | cell
    fam = _familiarization_order(source, [s for s in source.of_kind("familiarization") if _matches(s, scope)])
    practice = [s for s in source.of_kind("practice") if _matches(s, scope)]
    tests = [s for s in source.of_kind("test") if _matches(s, scope)]
    if rotation is not None:
        order = {arrangement: i for i, arrangement in enumerate(arrangements(p))}
        conditions = list(dict.fromkeys(s.condition_id for s in source.of_kind("test")))
        tests = [s for s in tests if order[s.arrangement] == arrangement_index(
            len(order), len(s.arrangement), rotation, conditions.index(s.condition_id))]
    questions = [(s, rep) for rep in range(1, p.repetitions + 1) for s in tests]
    count = p.practice.per_block if practice else 0
    return BlockPlan(block_label(cell), cell, fam, practice, count, questions)


def _familiarization_order(source: SurveySource, stimuli: list[StimulusInfo]) -> list[StimulusInfo]:
    """The design's order: declared, or by the body's BMI (ascending or descending)."""
    order = source.protocol.familiarization.order
    if order == "declared":
        return stimuli
    bmi = {a.id: a.bmi for a in source.protocol.actors}
    return sorted(stimuli, key=lambda s: bmi.get(s.body_actor, 0.0), reverse=order == "bmi_descending")


def export_tag(stimulus_id: str, repetition: int, repetitions: int) -> str:
    """The question's export tag: the stimulus id, ``_r<k>`` added when stimuli repeat.

    >>> export_tag("F-walk-Hi1-Lo2", 2, 2), export_tag("all-a_b", 1, 1), export_tag("x+y", 1, 1)
    ('F-walk-Hi1-Lo2_r2', 'all-a_b', 'x_y')
    """
    safe = "".join(c if c.isalnum() or c in "_-." else "_" for c in stimulus_id)
    return f"{safe}_r{repetition}" if repetitions > 1 else safe
