"""Design expansion: a protocol → its stimuli, blocks and seeded per-participant trial lists.

>>> from stimuli.protocol import load_protocol
>>> from stimuli.design import build_design
>>> d = build_design(load_protocol("protocols/exp1_shape_motion.yaml"), participants=16, seed=1)
>>> len([s for s in d.stimuli if s.kind == "test"])
64
>>> sum(1 for t in d.trials if t.participant == 1 and t.kind == "test")
64

Counterbalancing rules (all seeded, so the same protocol + seed gives the same lists; the orders
themselves are made in :mod:`stimuli.orders`):
- between-subject groups: every cell of the between factors gets the same number of participants;
- block order: ``counterbalanced`` uses the rows of a Williams Latin square (each block equally often
  in each position and, for an even number of blocks, after each other block), dealt out evenly
  within each between group, the rotation going on from one group to the next so that a group size
  the orders do not divide still gives totals as even as possible (``Design.notes`` then says so);
  ``random`` shuffles per participant; ``fixed`` keeps the declared order;
- nested blocks (``blocks.nested``): the first ``blocks.by`` factor makes main blocks, the others
  sub-blocks shown one after the other inside each main block. ``counterbalanced`` crosses the
  Williams rows over the main blocks with those over the sub-blocks (one sub-block order per
  participant, the same inside each of their main blocks) and deals the combinations as above, listed
  so that a group size they do not divide still keeps each level's orders nearly even
  (:func:`stimuli.orders.nested_orders`); ``random`` shuffles the main blocks and, separately inside each,
  the sub-blocks; ``fixed`` keeps the declared order. Labels and block numbers stay those of the
  sub-blocks (``SEX=F|GAIT=walk``, 1…), so trials.csv reads as for flat blocks;
- practice: ``practice.per_block`` clips drawn from the block's practice pool, whole shuffled copies of
  the pool first when it asks for more (copies numbered repetition 2, 3, …), before every block (with
  nested blocks: every sub-block);
- familiarisation: the block's bodies before each block; with nested blocks, the main block's bodies
  once, before its first sub-block (:func:`stimuli.orders.familiarization_scopes`);
- side-by-side/row placement of an ``alternatives`` factor: ``within`` shows every arrangement to
  everyone; ``between`` rotates arrangements over participants so every position is balanced over
  every k participants (:func:`stimuli.orders.arrangement_index`); with three or more levels the arrangements are
  shuffled by the protocol's seed (:func:`stimuli.orders.arrangements`), so no row keeps the declared order;
- test trial order within a block (``blocks.trials``): ``random`` (the default) shuffles per participant
  with no stimulus twice in a row (when that is possible); ``fixed`` keeps the declared order of the
  factor levels (``test_stimuli``'s order: the first-declared factor varies slowest, screen
  arrangements last) for everyone, the whole sequence once per repetition (repetition 1 of every
  clip, then repetition 2, …), so a clip never follows itself unless a block has one clip only,
  which the protocol refuses when ``repetitions`` > 1. Practice and familiarisation keep their rules.
"""

from __future__ import annotations

import itertools
import json
from collections import Counter
from dataclasses import asdict, dataclass, field

import numpy as np

from stimuli.errors import StimuliError
from stimuli.fileio import csv_text, write_all_or_nothing
from stimuli.orders import (arrangement_balance_notes, arrangement_count_notes, arrangement_index, arrangements,
                            balanced_labels,
                            block_cells, block_label,
                            counterbalanced_orders, familiarization_scopes, main_blocks, order_balance_notes,
                            random_block_order, shuffle_no_repeats)
from stimuli.protocol import Protocol


@dataclass(frozen=True)
class Stimulus:
    """One video clip to render: the factor levels it shows and where each alternative sits."""

    stimulus_id: str
    condition_id: str
    kind: str                     # "test" | "practice" | "familiarization"
    levels: dict[str, str]        # factor → level, for every factor that is not an alternatives factor
    arrangement: tuple[str, ...] = ()   # alternatives levels by screen position (left → right)
    body_actor: str = ""
    motion_actor: str = ""

    @property
    def practice(self) -> bool:
        return self.kind != "test"


@dataclass(frozen=True)
class Trial:
    participant: int
    groups: dict[str, str]        # between factor → level
    block: int                    # 1-based position of the block in this participant's order
    block_label: str
    trial: int                    # 1-based within the participant
    stimulus_id: str
    repetition: int
    kind: str

    @property
    def practice(self) -> bool:
        return self.kind != "test"


@dataclass
class Design:
    protocol: Protocol
    participants: int
    seed: int
    stimuli: list[Stimulus]
    trials: list[Trial]
    blocks: list[str]                                   # block labels in declared order
    block_orders: dict[int, list[str]] = field(default_factory=dict)  # participant → block labels
    notes: list[str] = field(default_factory=list)      # what the user should know (e.g. unbalanced orders)

    def stimulus(self, stimulus_id: str) -> Stimulus:
        return self._by_id()[stimulus_id]

    def _by_id(self) -> dict[str, Stimulus]:
        return {s.stimulus_id: s for s in self.stimuli}


# -- stimuli ------------------------------------------------------------------------------------

def _safe(text: str) -> str:
    return "".join(c if c.isalnum() or c in "_.+" else "_" for c in text)


def _actors_for(protocol: Protocol, levels: dict[str, str]) -> tuple[str, str]:
    """Actor ids whose body and motion a stimulus shows (motion blank when another factor decides it)."""
    sex_factor = protocol.factor_mapped_to("sex")
    sex = levels.get(sex_factor.name) if sex_factor else None
    body_factor = protocol.factor_mapped_to("body")
    motion_factor = protocol.factor_mapped_to("motion")
    body = protocol.actor(sex, levels[body_factor.name]).id if body_factor else protocol.display.body
    motion = protocol.actor(sex, levels[motion_factor.name]).id if motion_factor else ""
    return body or "", motion


def _stimuli_for(protocol: Protocol, level_lists: list[list[str]], kind: str) -> list[Stimulus]:
    names = [f.name for f in protocol.factors if f.role != "alternatives"]
    prefix = "" if kind == "test" else "practice-"
    out = []
    for combo in itertools.product(*level_lists):
        levels = dict(zip(names, combo))
        condition_id = prefix + "-".join(_safe(v) for v in combo) if combo else prefix + "all"
        body, motion = _actors_for(protocol, levels)
        for arrangement in arrangements(protocol):
            stimulus_id = condition_id + ("-" + "_".join(_safe(a) for a in arrangement) if arrangement else "")
            out.append(Stimulus(stimulus_id, condition_id, kind, levels, arrangement, body, motion))
    return out


def test_stimuli(protocol: Protocol) -> list[Stimulus]:
    """Every test condition crossed with every screen arrangement, factors in declared order."""
    return _stimuli_for(protocol, [f.levels for f in protocol.factors if f.role != "alternatives"], "test")


def practice_stimuli(protocol: Protocol) -> list[Stimulus]:
    """Practice conditions: the test crossing with the practice-only levels substituted; none when
    ``practice.per_block`` is 0 (no trial would show them: :func:`practice_notes` says so)."""
    if not protocol.practice.levels or not protocol.practice.per_block:
        return []
    lists = [protocol.practice.levels.get(f.name, f.levels) for f in protocol.factors if f.role != "alternatives"]
    return _stimuli_for(protocol, lists, "practice")


def practice_pool(protocol: Protocol) -> int:
    """Distinct practice clips one block offers (the same for every block and between group).

    >>> from stimuli.protocol import load_protocol
    >>> practice_pool(load_protocol("protocols/exp1_shape_motion.yaml"))   # BODY P1, P2 × MOTION P1, P2
    4
    """
    between = protocol.factors_with_role("between")
    scope = {f.name: f.levels[0] for f in between} | block_cells(protocol)[0]
    return sum(_matches(s, scope) for s in practice_stimuli(protocol))


def practice_notes(protocol: Protocol) -> list[str]:
    """A note when practice levels are given but ``per_block`` is 0: they are checked, not used."""
    if protocol.practice.levels and not protocol.practice.per_block:
        given = "; ".join(f"{name}: {', '.join(levels)}" for name, levels in protocol.practice.levels.items())
        return [f"practice.levels ({given}) unused: practice.per_block is 0, so no practice trials and no practice "
                "stimuli are made; set per_block > 0 to use them, or remove practice.levels"]
    return []


def familiarization_stimuli(protocol: Protocol) -> list[Stimulus]:
    """One clip per test body (per sex), to be shown before the blocks in which those bodies appear."""
    if not protocol.familiarization.enabled:
        return []
    body_factor = protocol.factor_mapped_to("body")
    if body_factor is None:
        raise StimuliError("familiarization.enabled: needs a factor that maps to body")
    sex_factor = protocol.factor_mapped_to("sex")
    out = []
    for sex in sex_factor.levels if sex_factor else [None]:
        for label in body_factor.levels:
            actor = protocol.actor(sex, label)
            levels = {body_factor.name: label} | ({sex_factor.name: sex} if sex_factor else {})
            out.append(Stimulus(f"fam-{actor.id}", f"fam-{actor.id}", "familiarization", levels, (), actor.id, ""))
    return out


# -- participants -------------------------------------------------------------------------------

def build_design(protocol: Protocol, participants: int | None = None, seed: int | None = None) -> Design:
    """Expand a protocol into stimuli and a trial list for each participant (1…N)."""
    n = protocol.participants if participants is None else participants
    seed = protocol.seed if seed is None else seed
    if n < 1:
        raise StimuliError(f"--participants: expected a positive number, got {n}")
    if seed < 0:  # numpy seeds are non-negative; a negative one would stop with a numpy traceback
        raise StimuliError(f"--seed: expected a whole number >= 0, got {seed}")
    between = protocol.factors_with_role("between")
    group_cells = [dict(zip([f.name for f in between], c)) for c in itertools.product(*(f.levels for f in between))]
    if n % len(group_cells):
        raise StimuliError(f"--participants: {n} participants cannot be balanced over {len(group_cells)} "
                           f"between-subject groups ({', '.join(f.name for f in between)}); use a multiple of "
                           f"{len(group_cells)}")
    rng = np.random.default_rng(seed)
    tests, practices, familiar = test_stimuli(protocol), practice_stimuli(protocol), familiarization_stimuli(protocol)
    blocks = block_cells(protocol)
    orders = counterbalanced_orders(protocol, len(blocks))

    group_of = balanced_labels(n, len(group_cells), rng)
    trials: list[Trial] = []
    block_orders: dict[int, list[str]] = {}
    dealt = 0  # block orders dealt to the groups before this one: the rotation goes on from there
    for g, groups in enumerate(group_cells):
        members = [p for p in range(n) if group_of[p] == g]
        order_of = balanced_labels(len(members), len(orders), rng, dealt) if orders else [0] * len(members)
        dealt += len(members)
        for rank, p in enumerate(members):
            if protocol.blocks.order == "random":
                order = random_block_order(protocol, len(blocks), rng)
            else:
                order = orders[order_of[rank]] if orders else list(range(len(blocks)))
            block_orders[p + 1] = [block_label(blocks[i]) for i in order]
            trials += _participant_trials(protocol, p + 1, rank, groups, [blocks[i] for i in order],
                                          tests, practices, familiar, rng)
    trials.sort(key=lambda t: (t.participant, t.trial))
    block_orders = dict(sorted(block_orders.items()))
    order_labels = [[block_label(blocks[i]) for i in order] for order in orders or []]
    notes = (order_balance_notes(group_cells, group_of, block_orders, order_labels)
             + arrangement_balance_notes(protocol, list(Counter(group_of).values()))
             + arrangement_count_notes(protocol) + practice_notes(protocol)
             + back_to_back_notes(trials))
    return Design(protocol, n, seed, tests + practices + familiar, trials,
                  [block_label(b) for b in blocks], block_orders, notes)


def back_to_back_notes(trials: list[Trial]) -> list[str]:
    """A note when some participant sees one test clip twice in a row (a block that holds a single test clip
    per participant, shown ``repetitions`` times: no order can keep its copies apart)."""
    pairs = [(a, b) for a, b in zip(trials, trials[1:]) if a.participant == b.participant and a.kind == b.kind == "test"
             and a.block == b.block and a.stimulus_id == b.stimulus_id]
    if not pairs:
        return []
    first = pairs[0][1]
    return [f"repetitions: {len({a.participant for a, _ in pairs})} participant(s) see the same test clip twice in a "
            f"row ({len(pairs)} time(s); e.g. participant {first.participant}, {first.stimulus_id}, trial "
            f"{first.trial}): their block holds a single test clip, so its repetitions cannot be kept apart"]


def _matches(stimulus: Stimulus, cell: dict[str, str]) -> bool:
    return all(stimulus.levels.get(k, v) == v for k, v in cell.items())


def _participant_trials(protocol, participant, rank, groups, blocks, tests, practices, familiar, rng):
    shown = {arrangement: i for i, arrangement in enumerate(arrangements(protocol))}
    n_arrangements, k = len(shown), len(next(iter(shown)))
    between_arrangement = protocol.alternatives.counterbalance == "between" and n_arrangements > 1
    conditions = list(dict.fromkeys(s.condition_id for s in tests))
    trials, number = [], 0

    def add(stimulus_id: str, position: int, repetition: int, kind: str) -> None:
        nonlocal number
        number += 1
        trials.append(Trial(participant, groups, position, block_label(cell), number, stimulus_id, repetition, kind))

    for position, (cell, fam_scope) in enumerate(zip(blocks, familiarization_scopes(protocol, blocks)), start=1):
        scope = groups | cell
        fam = [s for s in familiar if fam_scope is not None and _matches(s, groups | fam_scope)]
        for s in _familiarization_order(protocol, fam):
            add(s.stimulus_id, position, 1, "familiarization")
        pool = [s.stimulus_id for s in practices if _matches(s, scope)]
        if protocol.practice.per_block and pool:
            chosen = [pool[i] for i in _practice_pick(len(pool), protocol.practice.per_block, rng)]
            for sid, repetition in _numbered(shuffle_no_repeats(chosen, rng)):
                add(sid, position, repetition, "practice")
        block_tests = [s for s in tests if _matches(s, scope)]
        if between_arrangement:  # one arrangement per condition, rotated over participants
            block_tests = [s for s in block_tests
                           if shown[s.arrangement]
                           == arrangement_index(n_arrangements, k, rank, conditions.index(s.condition_id))]
        ids = [s.stimulus_id for s in block_tests] * protocol.repetitions   # declared order, once per repetition
        for sid, repetition in _numbered(ids if protocol.blocks.trials == "fixed" else shuffle_no_repeats(ids, rng)):
            add(sid, position, repetition, "test")
    return trials


def _numbered(ids: list[str]) -> list[tuple[str, int]]:
    """Each id with its repetition number: 1 the first time it appears, 2 the second, …

    >>> _numbered(["a", "b", "a"])
    [('a', 1), ('b', 1), ('a', 2)]
    """
    seen: Counter = Counter()
    out = []
    for sid in ids:
        seen[sid] += 1
        out.append((sid, seen[sid]))
    return out


def _practice_pick(available: int, wanted: int, rng) -> list[int]:
    """``wanted`` practice items: whole shuffled copies of the pool, then a random part of one."""
    picks = []
    while len(picks) < wanted:
        picks += [int(i) for i in rng.permutation(available)]
    return picks[:wanted]


def _familiarization_order(protocol: Protocol, stimuli: list[Stimulus]) -> list[Stimulus]:
    order = protocol.familiarization.order
    if order == "declared":
        return stimuli
    bmi = {a.id: a.bmi for a in protocol.actors}
    return sorted(stimuli, key=lambda s: bmi[s.body_actor], reverse=order == "bmi_descending")


# -- files ----------------------------------------------------------------------------------------

def _alternative_columns(protocol: Protocol, arrangement: tuple[str, ...]) -> dict[str, str]:
    alternatives = protocol.factors_with_role("alternatives")
    if not alternatives:
        return {}
    if len(alternatives[0].levels) == 2:
        return {"left": arrangement[0] if arrangement else "", "right": arrangement[1] if arrangement else ""}
    return {"positions": "|".join(arrangement)}


def conditions_rows(design: Design) -> list[dict[str, object]]:
    """Rows of ``conditions.csv``: one per stimulus."""
    p = design.protocol
    factor_names = [f.name for f in p.factors if f.role != "alternatives"]
    rows = []
    for s in design.stimuli:
        row = {"condition_id": s.condition_id} | {n: s.levels.get(n, "") for n in factor_names}
        row |= {"stimulus_id": s.stimulus_id, "practice": int(s.practice), "kind": s.kind,
                "body_actor": s.body_actor, "motion_actor": s.motion_actor}
        rows.append(row | _alternative_columns(p, s.arrangement))
    return rows


def trials_rows(design: Design) -> list[dict[str, object]]:
    """Rows of ``trials.csv``: one per participant × trial, in presentation order."""
    p = design.protocol
    by_id = design._by_id()
    between = [f.name for f in p.factors_with_role("between")]
    rows = []
    for t in design.trials:
        row = {"participant": t.participant} | {n: t.groups[n] for n in between}
        row |= {"block": t.block, "block_label": t.block_label, "trial": t.trial, "stimulus_id": t.stimulus_id,
                "repetition": t.repetition, "practice": int(t.practice), "kind": t.kind}
        rows.append(row | _alternative_columns(p, by_id[t.stimulus_id].arrangement))
    return rows


def design_json(design: Design) -> dict:
    """Everything the analysis half needs to know about the experiment, as plain JSON."""
    p = design.protocol
    alternatives = p.factors_with_role("alternatives")
    response = p.response.model_dump() | {
        "k": len(p.response.labels) if p.response.type == "likert" else len(alternatives[0].levels),
        "position_labels": p.display.labels or ([] if not alternatives else
                                                (["left", "right"] if len(alternatives[0].levels) == 2 else [])),
    }
    analysis_within = [f.name for f in p.factors if f.role == "within"] + [f.name for f in alternatives]
    return {
        "generator": "shapemotion 0.1.0",
        "name": p.name,
        "participants": design.participants,
        "seed": design.seed,
        "factors": [{"name": f.name, "role": f.role, "levels": f.levels, "maps_to": f.maps_to,
                     "abbreviations": {lv: f.abbreviation(lv) for lv in f.levels}} for f in p.factors],
        "response": response,
        "dependent_measure": p.analysis.dependent_measure,
        "chosen_factor": alternatives[0].name if alternatives else None,
        "analysis": {"within": analysis_within, "between": [f.name for f in p.factors_with_role("between")],
                     "alpha": p.analysis.alpha, "posthoc": p.analysis.posthoc},
        "repetitions": p.repetitions,
        "blocks": design.blocks,
        "block_orders": {str(k): v for k, v in design.block_orders.items()},
    } | _nesting_json(design) | {
        "stimuli": [asdict(s) | {"arrangement": list(s.arrangement), "practice": s.practice} for s in design.stimuli],
        "protocol": p.to_json_dict(),
    }


def _nesting_json(design: Design) -> dict:
    """``block_nesting`` for nested blocks (main and sub factors, each main block's sub-block labels);
    nothing for flat blocks, whose design.json stays as it was before the option."""
    p = design.protocol
    mains = main_blocks(p)
    if not mains:
        return {}
    labels = design.blocks
    return {"block_nesting": {"main": p.blocks.by[:1], "sub": p.blocks.by[1:],
                              "main_blocks": {block_label(cell): [labels[i] for i in subs] for cell, subs in mains}}}


def write_design(design: Design, out_dir) -> list:
    """Write ``conditions.csv``, ``trials.csv`` and ``design.json`` into ``out_dir`` (each atomically)."""
    return write_all_or_nothing(out_dir, {
        "conditions.csv": csv_text(conditions_rows(design)),
        "trials.csv": csv_text(trials_rows(design)),
        "design.json": json.dumps(design_json(design), indent=2) + "\n",
    })
