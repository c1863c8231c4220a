"""Property tests: over random valid protocols, every trial list satisfies the protocol's constraints."""

from __future__ import annotations

from collections import Counter

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from stimuli.design import build_design
from stimuli.orders import arrangements, williams_orders
from stimuli.protocol import Protocol


@st.composite
def protocols(draw):
    n_between = draw(st.integers(0, 2))
    n_within = draw(st.integers(1, 3))
    factors = []
    for i in range(n_between):
        factors.append({"name": f"B{i}", "role": "between", "levels": [f"b{i}{j}" for j in range(draw(st.integers(2, 3)))]})
    for i in range(n_within):
        factors.append({"name": f"W{i}", "role": "within", "levels": [f"w{i}{j}" for j in range(draw(st.integers(2, 4)))]})
    has_alternatives = draw(st.booleans())
    display = {"layout": "treadmill", "body": "A1"}
    alternatives = {}
    response = {"type": "likert", "question": "q?", "labels": ["no", "maybe", "yes"]}
    measure = "mean_rating"
    if has_alternatives:
        k = draw(st.integers(2, 4))
        # a mapping the renderer makes a distinct motion for at every level: body-fat strengths
        factors.append({"name": "ALT", "role": "alternatives", "levels": ["12", "23.5", "35", "46.5"][:k],
                        "maps_to": "strength"})
        display["layout"] = "side_by_side" if k == 2 else "row"
        alternatives = {"arrangements": draw(st.sampled_from(["all", "latin_square", "fixed"])),
                        "counterbalance": draw(st.sampled_from(["within", "between"]))}
        response = {"type": draw(st.sampled_from(["afc", "ranking"])), "question": "which?"}
        measure = "percent_chosen" if response["type"] == "afc" else "rank_points"
    within_names = [f["name"] for f in factors if f["role"] == "within"]
    block_by = draw(st.lists(st.sampled_from(within_names), unique=True, max_size=2))
    cells = 1
    for f in factors:
        if f["role"] == "between":
            cells *= len(f["levels"])
    data = {
        "name": "random", "seed": draw(st.integers(0, 2**31)), "participants": cells * draw(st.integers(1, 4)),
        "actors": [{"id": "A1", "label": "A1", "sex": "F", "height_m": 1.65, "bmi": 23}],
        "factors": factors, "display": display, "alternatives": alternatives,
        "clip": {"duration_s": 2}, "blocks": {"by": block_by, "order": draw(st.sampled_from(["counterbalanced", "latin_square", "random", "fixed"]))},
        "repetitions": draw(st.integers(1, 3)), "response": response,
        "analysis": {"dependent_measure": measure},
    }
    return Protocol.model_validate(data)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(protocols())
def test_trial_lists_satisfy_the_protocol(protocol):
    design = build_design(protocol)
    by_id = {s.stimulus_id: s for s in design.stimuli}
    between = [f.name for f in protocol.factors_with_role("between")]
    n_arr = len(arrangements(protocol))
    per_participant_arrangements = n_arr if protocol.alternatives.counterbalance == "within" else 1
    n_conditions = len({s.condition_id for s in design.stimuli})
    groups = Counter(tuple(t.groups[n] for n in between) for t in design.trials if t.trial == 1)
    assert len(set(groups.values())) == 1  # balanced between groups
    for p in range(1, design.participants + 1):
        trials = [t for t in design.trials if t.participant == p]
        assert [t.trial for t in trials] == list(range(1, len(trials) + 1))
        counts = Counter(t.stimulus_id for t in trials)
        assert set(counts.values()) == {protocol.repetitions}
        conditions = Counter(by_id[s].condition_id for s in counts)
        n_group_cells = 1
        for f in protocol.factors_with_role("between"):
            n_group_cells *= len(f.levels)
        assert len(conditions) == n_conditions // n_group_cells  # every within condition of its group
        assert set(conditions.values()) == {per_participant_arrangements}
        for t in trials:
            stimulus = by_id[t.stimulus_id]
            assert all(stimulus.levels[n] == t.groups[n] for n in between)
            block = dict(kv.split("=") for kv in t.block_label.split("|")) if t.block_label != "all" else {}
            assert all(stimulus.levels[k] == v for k, v in block.items())
        labels = list(dict.fromkeys(t.block_label for t in trials))
        assert sorted(labels) == sorted(design.blocks)
    if protocol.blocks.order in ("counterbalanced", "latin_square") and len(design.blocks) > 1:
        _assert_orders_as_even_as_possible(design, between)
        for label in labels:
            ids = [t.stimulus_id for t in trials if t.block_label == label]
            if max(Counter(ids).values()) <= (len(ids) + 1) // 2:
                assert all(a != b for a, b in zip(ids, ids[1:]))


def _assert_orders_as_even_as_possible(design, between: list[str]) -> None:
    """Each counterbalanced block order is dealt equally often, give or take one, within every between
    group and over all participants (the rotation goes on from one group to the next)."""
    group = {t.participant: tuple(t.groups[n] for n in between) for t in design.trials}
    orders = {p: tuple(order) for p, order in design.block_orders.items()}
    n_orders = len(williams_orders(len(design.blocks)))
    for members in ([p for p in orders if group[p] == g] for g in set(group.values())):
        counts = Counter(orders[p] for p in members)
        assert max(counts.values()) - (min(counts.values()) if len(counts) == n_orders else 0) <= 1
    counts = Counter(orders.values())
    assert max(counts.values()) - (min(counts.values()) if len(counts) == n_orders else 0) <= 1
