"""Design expansion of the two paper protocols: counts, balance, determinism (issue 2 acceptance)."""

from __future__ import annotations

from collections import Counter

import pandas as pd
import pytest

from stimuli.design import build_design
from stimuli.orders import arrangements, shuffle_no_repeats, williams_orders
from stimuli.protocol import load_protocol


@pytest.fixture(scope="module")
def exp1(tmp_path_factory):
    from stimuli.cli import main

    out = tmp_path_factory.mktemp("exp1")
    assert main(["design", "protocols/exp1_shape_motion.yaml", "--participants", "16", "--seed", "1", "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def exp2(tmp_path_factory):
    from stimuli.cli import main

    out = tmp_path_factory.mktemp("exp2")
    assert main(["design", "protocols/exp2_com_vs_average.yaml", "--participants", "16", "--seed", "1", "--out", str(out)]) == 0
    return out


def no_back_to_back(trials: pd.DataFrame) -> bool:
    for _, part in trials.groupby("participant"):
        ids = part.sort_values("trial")["stimulus_id"].tolist()
        if any(a == b for a, b in zip(ids, ids[1:])):
            return False
    return True


def test_exp1_counts(exp1):
    conditions = pd.read_csv(exp1 / "conditions.csv")
    trials = pd.read_csv(exp1 / "trials.csv")
    test_stimuli = conditions[conditions.kind == "test"]
    assert len(test_stimuli) == 64 == test_stimuli.stimulus_id.nunique()
    assert len(test_stimuli.groupby(["SEX", "GAIT", "BODY", "MOTION"])) == 64
    assert list(trials.columns[:8]) == ["participant", "SEX", "block", "block_label", "trial", "stimulus_id",
                                        "repetition", "practice"]
    test = trials[trials.kind == "test"]
    for participant, part in test.groupby("participant"):
        assert len(part) == 64
        counts = part.stimulus_id.value_counts()
        assert len(counts) == 32 and set(counts) == {2}
        sexes = conditions.set_index("stimulus_id").loc[part.stimulus_id, "SEX"]
        assert sexes.nunique() == 1 and sexes.iloc[0] == part.SEX.iloc[0]  # sees one sex only
        for _, block in part.groupby("block"):
            assert len(block) == 32 and block.stimulus_id.nunique() == 16
        trial_numbers = trials[trials.participant == participant].trial.tolist()
        assert trial_numbers == list(range(1, len(trial_numbers) + 1))
    assert trials.groupby("participant").SEX.first().value_counts().to_dict() == {"F": 8, "M": 8}
    assert no_back_to_back(trials)


def test_exp1_block_order_balanced(exp1):
    trials = pd.read_csv(exp1 / "trials.csv")
    first = trials[trials.block == 1].groupby("participant").block_label.first()
    assert first.value_counts().to_dict() == {"GAIT=walk": 8, "GAIT=jog": 8}
    sex = trials.groupby("participant").SEX.first()
    assert pd.crosstab(sex, first).values.tolist() == [[4, 4], [4, 4]]  # balanced within each group too


def test_exp1_practice_before_each_block(exp1):
    trials = pd.read_csv(exp1 / "trials.csv")
    for _, part in trials.groupby("participant"):
        for _, block in part.groupby("block"):
            kinds = block.sort_values("trial").kind.tolist()
            assert kinds[:4] == ["practice"] * 4 and kinds[4:] == ["test"] * 32
            practice_ids = block[block.kind == "practice"].stimulus_id
            assert all(sid.startswith("practice-") for sid in practice_ids)


def test_exp2_counts_and_left_right_balance(exp2):
    conditions = pd.read_csv(exp2 / "conditions.csv")
    trials = pd.read_csv(exp2 / "trials.csv")
    test_stimuli = conditions[conditions.kind == "test"]
    assert len(test_stimuli) == 32
    assert {tuple(x) for x in test_stimuli[["left", "right"]].values} == {("NoCOM", "COM"), ("COM", "NoCOM")}
    test = trials[trials.kind == "test"]
    for _, part in test.groupby("participant"):
        assert len(part) == 64
        assert set(part.stimulus_id.value_counts()) == {2} and part.stimulus_id.nunique() == 32
        for _, block in part.groupby("block"):
            assert len(block) == 16 and block.stimulus_id.nunique() == 8
        merged = part.merge(test_stimuli[["stimulus_id", "GAIT", "SEX", "BODY"]], on="stimulus_id")
        per_cell = merged.groupby(["GAIT", "SEX", "BODY"]).left.value_counts().unstack()
        assert (per_cell["NoCOM"] == per_cell["COM"]).all()
    assert no_back_to_back(trials)
    first_blocks = trials[trials.block == 1].groupby("participant").block_label.first().value_counts()
    assert sorted(first_blocks) == [4, 4, 4, 4]  # each of the 4 blocks first for 4 participants


def test_exp2_familiarization_and_practice(exp2):
    """Nested blocks (SEX, then its GAIT sub-blocks): the SEX block's bodies before its first sub-block
    (blocks 1 and 3), practice before every sub-block (tests/test_nested_blocks.py has the rest)."""
    trials = pd.read_csv(exp2 / "trials.csv")
    design = load_protocol("protocols/exp2_com_vs_average.yaml")
    bmi = {a.id: a.bmi for a in design.actors}
    for number, block in trials[trials.participant == 3].groupby("block"):
        block = block.sort_values("trial")
        fam_first = ["familiarization"] * 4 if number in (1, 3) else []
        assert block.kind.tolist() == fam_first + ["practice"] * 4 + ["test"] * 16
        fam = [sid.removeprefix("fam-") for sid in block[block.kind == "familiarization"].stimulus_id]
        assert [bmi[a] for a in fam] == sorted(bmi[a] for a in fam)
        sex = block.block_label.iloc[0].split("|")[0].split("=")[1]
        assert all(a.startswith(sex + "_") for a in fam)


def test_same_seed_same_bytes_other_seed_other_order(tmp_path, run_cli):
    for name, seed in (("a", 7), ("b", 7), ("c", 8)):
        assert run_cli("design", "protocols/exp2_com_vs_average.yaml", "--seed", seed, "--out", tmp_path / name)[0] == 0
    for file in ("conditions.csv", "trials.csv", "design.json"):
        assert (tmp_path / "a" / file).read_bytes() == (tmp_path / "b" / file).read_bytes()
    assert (tmp_path / "a" / "trials.csv").read_bytes() != (tmp_path / "c" / "trials.csv").read_bytes()
    assert (tmp_path / "a" / "conditions.csv").read_bytes() == (tmp_path / "c" / "conditions.csv").read_bytes()


def test_thesis_protocols_balance_positions():
    pointlight = build_design(load_protocol("protocols/thesis_pointlight.yaml"))
    by_id = {s.stimulus_id: s for s in pointlight.stimuli}
    assert len(pointlight.stimuli) == 60  # 10 parameter sets × 6 Latin-square arrangements
    first_position = Counter((by_id[t.stimulus_id].levels["PARAMETER"], by_id[t.stimulus_id].arrangement[0])
                             for t in pointlight.trials)
    assert set(first_position.values()) == {10}  # each strength leftmost for 10 of 60 viewers, per video
    assert all(sum(t.participant == p for t in pointlight.trials) == 10 for p in range(1, 61))
    validation = build_design(load_protocol("protocols/thesis_validation.yaml"))
    assert [s.arrangement for s in validation.stimuli] == [("lean_mocap", "keyframed", "modifier", "obese_mocap")]
    assert len(validation.trials) == 96


def test_pointlight_rows_are_a_shuffled_latin_square():
    """The thesis randomised the six walkers "so that participants would not be able to select the lean
    walker through relative ordering"; the rows used to be the rising order 0.5 … 58, rotated."""
    protocol = load_protocol("protocols/thesis_pointlight.yaml")
    rows = arrangements(protocol)
    levels = tuple(protocol.factors_with_role("alternatives")[0].levels)
    rotations = {levels[i:] + levels[:i] for i in range(len(levels))}
    assert len(rows) == 6 and not rotations & set(rows) and not {r[::-1] for r in rotations} & set(rows)
    assert all(sorted(row) == sorted(levels) for row in rows)
    assert all(sorted(column) == sorted(levels) for column in zip(*rows))   # each strength once per position
    assert arrangements(protocol) == rows
    assert arrangements(protocol.model_copy(update={"seed": protocol.seed + 1})) != rows


def test_all_orders_between_participants_balance_positions(tmp_path):
    """`arrangements: all` + `between`: 60 viewers of 6 walkers used to see 0.5 % leftmost in all 600
    trials (the first 120 of the 720 permutations start with it)."""
    text = open("protocols/thesis_pointlight.yaml").read().replace("arrangements: latin_square", "arrangements: all")
    (tmp_path / "all.yaml").write_text(text)
    design = build_design(load_protocol(tmp_path / "all.yaml"))
    by_id = {s.stimulus_id: s for s in design.stimuli}
    assert len(design.stimuli) == 10 * 720
    shown = [by_id[t.stimulus_id] for t in design.trials]
    for position in range(6):
        counts = Counter((s.levels["PARAMETER"], s.arrangement[position]) for s in shown)
        assert set(counts.values()) == {10}, position
    assert len({s.arrangement for s in shown}) > 6   # not one Latin square for everyone
    assert any(n.startswith("alternatives.arrangements: all makes 720 screen orders") for n in design.notes)


@pytest.mark.parametrize("module, examples", [("stimuli.design", 2), ("stimuli.orders", 8)])
def test_docstring_examples(module, examples):
    import doctest
    import importlib

    result = doctest.testmod(importlib.import_module(module))
    assert result.attempted >= examples and result.failed == 0


@pytest.mark.parametrize("k", [1, 2, 3, 4, 5, 6])
def test_williams_square_balances_positions(k):
    rows = williams_orders(k)
    for position in range(k):
        counts = Counter(row[position] for row in rows)
        assert len(counts) == k and len(set(counts.values())) == 1
    if k % 2 == 0 and k > 1:  # first-order carry-over balanced too
        pairs = Counter((a, b) for row in rows for a, b in zip(row, row[1:]))
        assert set(pairs.values()) == {1} and len(pairs) == k * (k - 1)


def test_shuffle_no_repeats_when_possible_and_reports_impossible():
    import numpy as np

    rng = np.random.default_rng(3)
    for _ in range(200):
        items = list(rng.choice(list("abcd"), size=int(rng.integers(1, 12))))
        counts = Counter(items)
        order = shuffle_no_repeats(items, rng)
        assert Counter(order) == counts
        if max(counts.values()) <= (len(items) + 1) // 2:
            assert all(a != b for a, b in zip(order, order[1:]))


def _shuffle_no_repeats_by_copying(items, rng):
    """The first version, kept as the reference: it copied the counts for every candidate key."""
    import numpy as np

    def feasible(counts, chosen):
        rest = counts.copy()
        rest[chosen] -= 1
        n = sum(rest.values())
        return all(c <= (n + 1) // 2 for c in rest.values()) and rest[chosen] <= n // 2

    counts, keys = Counter(items), list(dict.fromkeys(items))
    if counts and max(counts.values()) > (len(items) + 1) // 2:
        return [items[i] for i in rng.permutation(len(items))]
    out, previous = [], None
    for _ in range(len(items)):
        candidates = [k for k in keys if counts[k] and k != previous and feasible(counts, k)]
        weights = np.array([counts[k] for k in candidates], dtype=float)
        previous = candidates[rng.choice(len(candidates), p=weights / weights.sum())]
        counts[previous] -= 1
        out.append(previous)
    return out


def test_shuffle_no_repeats_deals_the_same_orders_as_before_and_fast():
    """The feasibility check now reads the two largest counts instead of copying them per key: the same
    orders for the same seed (a protocol's trial lists do not change), and a 2304-trial list of 768
    stimuli (2 × 4 × 4 cells, 4 alternatives in all 24 arrangements, 3 repetitions: a random protocol of
    the property test) in well under a second, where it took hours."""
    import time

    import numpy as np

    pick = np.random.default_rng(11)
    for trial in range(300):
        items = [str(x) for x in pick.choice(list("abcdefg")[: int(pick.integers(1, 8))], size=int(pick.integers(0, 25)))]
        assert shuffle_no_repeats(items, np.random.default_rng(trial)) == \
            _shuffle_no_repeats_by_copying(items, np.random.default_rng(trial)), items
    items = [f"s{i}" for i in range(768)] * 3
    start = time.process_time()
    order = shuffle_no_repeats(items, np.random.default_rng(0))
    assert time.process_time() - start < 2.0
    assert Counter(order) == Counter(items) and all(a != b for a, b in zip(order, order[1:]))


EXP1_TEXT = open("protocols/exp1_shape_motion.yaml").read()


def test_block_orders_balance_over_groups_the_orders_do_not_divide(tmp_path, run_cli):
    """10 participants in 2 SEX groups of 5: walk-first 3 / jog-first 2 in one group and 2 / 3 in the
    other (5 / 5 overall, not 6 / 4), and the command says the groups cannot be balanced."""
    code, stdout, _ = run_cli("design", "protocols/exp1_shape_motion.yaml", "--participants", "10", "--out", tmp_path)
    assert code == 0
    trials = pd.read_csv(tmp_path / "trials.csv")
    first = trials[trials.block == 1].groupby("participant").block_label.first()
    assert first.value_counts().to_dict() == {"GAIT=walk": 5, "GAIT=jog": 5}
    sex = trials.groupby("participant").SEX.first()
    assert sorted(pd.crosstab(sex, first).values.tolist()) == [[2, 3], [3, 2]]
    note = " ".join(stdout.split())
    assert "note: blocks.order: 10 participants cannot see the 2 counterbalanced block orders equally often" in note
    assert "GAIT=walk → GAIT=jog: SEX=F 3, SEX=M 2 (total 5)" in note and "A multiple of 4 participants" in note


def test_balanced_block_orders_print_no_note(tmp_path, run_cli):
    code, stdout, _ = run_cli("design", "protocols/exp1_shape_motion.yaml", "--participants", "8", "--out", tmp_path)
    assert code == 0 and "note:" not in stdout


def test_practice_beyond_the_pool_repeats_numbered_never_back_to_back():
    """per_block 6 from a pool of 4: two clips come twice, as repetition 1 and 2, never in a row."""
    from stimuli.protocol import parse_protocol

    design = build_design(parse_protocol(EXP1_TEXT.replace("per_block: 4 ", "per_block: 6 ")), participants=4)
    blocks = Counter((t.participant, t.block) for t in design.trials if t.kind == "practice")
    assert set(blocks.values()) == {6}
    for participant, block in blocks:
        practice = [t for t in design.trials if (t.participant, t.block, t.kind) == (participant, block, "practice")]
        ids = [t.stimulus_id for t in practice]
        assert len(set(ids)) == 4 and all(a != b for a, b in zip(ids, ids[1:]))
        for sid in set(ids):
            assert [t.repetition for t in practice if t.stimulus_id == sid] == list(range(1, ids.count(sid) + 1))


def test_practice_levels_with_per_block_0_make_no_stimuli_and_say_so(tmp_path, run_cli):
    """Bad-input audit: with per_block 0 the practice levels are checked but no trial shows them, so no
    practice stimulus is made (conditions.csv had 16 nobody sees) and a note names the unused levels."""
    text = open("protocols/exp1_shape_motion.yaml").read().replace("per_block: 4 ", "per_block: 0 ", 1)
    path = tmp_path / "pb0.yaml"
    path.write_text(text)
    code, stdout, stderr = run_cli("design", path, "--out", tmp_path / "out")
    assert code == 0, stderr
    conditions = pd.read_csv(tmp_path / "out" / "conditions.csv")
    assert not conditions.practice.any() and not conditions.stimulus_id.str.startswith("practice-").any()
    assert "note: practice.levels (BODY: P1, P2; MOTION: P1, P2) unused: practice.per_block is 0" in stdout
    code, stdout, _ = run_cli("validate", path)
    assert code == 0 and "0 practice" in stdout and "practice.levels (BODY: P1, P2; MOTION: P1, P2) unused" in stdout


def test_a_block_of_one_clip_shown_twice_gets_a_note(protocol_path, tmp_path):
    """thesis_validation with repetitions: 2 shows each participant's single clip back to back; the design
    used to do so without a word."""
    text = open(protocol_path("thesis_validation")).read().replace("repetitions: 1", "repetitions: 2")
    assert "repetitions: 2" in text
    (tmp_path / "p.yaml").write_text(text)
    notes = build_design(load_protocol(tmp_path / "p.yaml"), seed=1).notes
    assert any("see the same test clip twice in a row" in n for n in notes), notes
    assert not [n for n in build_design(load_protocol(protocol_path("exp1_shape_motion")), seed=1).notes
                if "twice in a row" in n]


def test_positions_that_cannot_balance_get_a_note():
    """Block orders that a group size does not divide had a note; screen positions had none (the thesis's
    n = 67 viewers of six walkers show one strength in one place 12 times and the others 11)."""
    protocol = load_protocol("protocols/thesis_pointlight.yaml")
    assert [n for n in build_design(protocol, participants=67).notes if n.startswith("alternatives:")]
    assert not [n for n in build_design(protocol, participants=60).notes if n.startswith("alternatives:")]
