"""Orders of a design: screen arrangements of an ``alternatives`` factor, block cells and their
orders (Williams squares, flat or nested), and shuffles without back-to-back repeats.

The rules themselves are summarised in :mod:`stimuli.design`, which deals these orders to
participants. Everything here is a pure function of the protocol (and a seeded generator).

>>> williams_orders(4)
[[0, 1, 3, 2], [1, 2, 0, 3], [2, 3, 1, 0], [3, 0, 2, 1]]
"""

from __future__ import annotations

import itertools
from collections import Counter
from math import gcd

import numpy as np

from stimuli.protocol import Protocol


def arrangements(protocol: Protocol) -> list[tuple[str, ...]]:
    """Screen orders of the alternatives factor's levels (``[()]`` when there is none).

    ``latin_square``: k rows, each level once in each position. With three or more levels the
    square is a cyclic one with its columns and symbols shuffled by the protocol's seed: the
    plain cyclic rows (0.5 12 23.5 …, 12 23.5 … 0.5) keep the levels in rising order, wrapped,
    so a viewer could pick a level by its neighbours; from four levels on, no row keeps the
    levels in rising or falling order, wrapped or not. ``all``: every permutation, grouped in
    runs of k that are Latin squares (one permutation's k cyclic symbol shifts), the runs in
    seeded order: :func:`arrangement_index` deals one run to every k participants.

    >>> from stimuli.protocol import load_protocol
    >>> rows = arrangements(load_protocol("protocols/thesis_pointlight.yaml"))
    >>> len(rows), all(sorted(col) == sorted(rows[0]) for col in zip(*rows))
    (6, True)
    """
    alternatives = protocol.factors_with_role("alternatives")
    if not alternatives:
        return [()]
    levels = alternatives[0].levels
    k = len(levels)
    kind = protocol.alternatives.arrangements
    if kind == "fixed":
        return [tuple(levels)]
    if k < 3:  # both orders of two levels: nothing to hide, and existing designs stay as they were
        return [tuple(levels[(i + j) % k] for j in range(k)) for i in range(k)] if kind == "latin_square" \
            else list(itertools.permutations(levels))
    rng = np.random.default_rng(protocol.seed)
    if kind == "latin_square":
        while True:  # redrawn while a row keeps the levels in rank order (every order of 3 does)
            symbols, columns = rng.permutation(k), rng.permutation(k)
            rows = [tuple(levels[symbols[(columns[j] + i) % k]] for j in range(k)) for i in range(k)]
            if k < 4 or not set(rows) & _rotations(levels):
                return rows
    symbols = rng.permutation(k)
    starts = [(0, *rest) for rest in itertools.permutations(range(1, k))]
    return [tuple(levels[symbols[(starts[r][j] + i) % k]] for j in range(k))
            for r in rng.permutation(len(starts)) for i in range(k)]


def _rotations(levels: list[str]) -> set[tuple[str, ...]]:
    """The declared order and its reverse, each rotated: rows that keep the levels in rank order."""
    return {tuple(order[i:] + order[:i]) for order in (list(levels), list(levels)[::-1]) for i in range(len(levels))}


def arrangement_index(n_arrangements: int, k: int, rank: int, condition: int) -> int:
    """Which of :func:`arrangements` participant ``rank`` (0-based, within the group) sees for the
    ``condition``-th condition when arrangements are counterbalanced between participants.

    Every k consecutive ranks get one run of k arrangements (a Latin square), each condition a
    different arrangement, so each level is equally often in each position over every k
    participants. (Taking the permutations in order, 60 participants would all have seen the
    first level leftmost: the first 120 of the 720 orders of 6 start with it.)

    >>> [arrangement_index(6, 3, rank, 0) for rank in range(6)]
    [0, 1, 2, 3, 4, 5]
    >>> [arrangement_index(3, 3, rank, 1) for rank in range(3)]
    [1, 2, 0]
    """
    runs = max(1, n_arrangements // k)
    return (rank // k + condition) % runs * k + (rank + condition) % k


def williams_orders(k: int) -> list[list[int]]:
    """Rows of a Williams Latin square: balanced for position and (even k) first-order carry-over."""
    if k == 1:
        return [[0]]
    first, low, high = [0], 1, k - 1
    for i in range(1, k):
        first.append(low if i % 2 else high)
        low, high = (low + 1, high) if i % 2 else (low, high - 1)
    rows = [[(x + r) % k for x in first] for r in range(k)]
    if k % 2:
        rows += [list(reversed(row)) for row in rows]
    return rows


def block_cells(protocol: Protocol) -> list[dict[str, str]]:
    """The blocks in declared order, each a mapping from block factor to level ([{}] = one block)."""
    names = protocol.blocks.by
    return [dict(zip(names, combo)) for combo in itertools.product(*(protocol.factor(n).levels for n in names))]


def block_label(cell: dict[str, str]) -> str:
    return "|".join(f"{k}={v}" for k, v in cell.items()) or "all"


def main_blocks(protocol: Protocol) -> list[tuple[dict[str, str], list[int]]]:
    """With ``blocks.nested``: each main block (a level of the first ``blocks.by`` factor) and the
    indices in :func:`block_cells` of its sub-blocks, in declared order; ``[]`` for flat blocks.

    >>> from stimuli.protocol import load_protocol
    >>> main_blocks(load_protocol("protocols/exp2_com_vs_average.yaml"))
    [({'SEX': 'F'}, [0, 1]), ({'SEX': 'M'}, [2, 3])]
    """
    if not protocol.blocks.nested:
        return []
    main = protocol.blocks.by[0]
    levels = protocol.factor(main).levels
    per_main = len(block_cells(protocol)) // len(levels)   # block_cells varies the first factor slowest
    return [({main: level}, list(range(m * per_main, (m + 1) * per_main))) for m, level in enumerate(levels)]


def nested_orders(n_main: int, n_sub: int) -> list[list[int]]:
    """Counterbalanced nested block orders, as indices into :func:`block_cells`: every Williams row
    over the main blocks crossed with every Williams row over the sub-blocks (one sub-order for all
    the main blocks of a participant), a main block's sub-blocks consecutive.

    Crossing ``c`` takes main row ``c mod a`` and sub row ``(c + c div lcm(a, b)) mod b`` (a bijection):
    every ``a`` consecutive crossings hold each main row once, and inside each run of ``lcm(a, b)``
    every ``b`` consecutive ones each sub row once. Dealt in turn (:func:`balanced_labels`), a group
    size the crossings do not divide thus keeps each level nearly even on its own: 10 participants
    over Exp. 2's 4 crossings see SEX first 5 / 5 and walk first 5 / 5 (listed main row first, it
    would be 6 / 4).

    >>> nested_orders(2, 2)
    [[0, 1, 2, 3], [3, 2, 1, 0], [1, 0, 3, 2], [2, 3, 0, 1]]
    """
    mains, subs = williams_orders(n_main), williams_orders(n_sub)
    a, b = len(mains), len(subs)
    period = a * b // gcd(a, b)
    out = []
    for c in range(a * b):
        turn, step = divmod(c, period)
        out.append(_nest(mains[step % a], subs[(step + turn) % b], n_sub))
    return out


def _nest(main_order: list[int], sub_order: list[int], n_sub: int) -> list[int]:
    """Block indices of main blocks in ``main_order``, each with its sub-blocks in ``sub_order``."""
    return [m * n_sub + s for m in main_order for s in sub_order]


def familiarization_scopes(protocol: Protocol, order: list[dict[str, str]]) -> list[dict[str, str] | None]:
    """For each block of a participant's ``order`` (block cells), the levels its familiarisation clips
    must match, or None when it shows none: each block's own cell for flat blocks; with nested blocks
    the main block's level on the first of its sub-blocks, None on the others.

    >>> from stimuli.protocol import load_protocol
    >>> p = load_protocol("protocols/exp2_com_vs_average.yaml")
    >>> familiarization_scopes(p, [{"SEX": "M", "GAIT": "jog"}, {"SEX": "M", "GAIT": "walk"},
    ...                            {"SEX": "F", "GAIT": "jog"}, {"SEX": "F", "GAIT": "walk"}])
    [{'SEX': 'M'}, None, {'SEX': 'F'}, None]
    """
    if not protocol.blocks.nested:
        return list(order)
    main = protocol.blocks.by[0]
    previous = [None] + [cell[main] for cell in order[:-1]]
    return [{main: cell[main]} if cell[main] != before else None for cell, before in zip(order, previous)]


def shuffle_no_repeats(items: list[str], rng: np.random.Generator) -> list[str]:
    """A random order of ``items`` with no element twice in a row, when such an order exists.

    >>> import numpy as np
    >>> order = shuffle_no_repeats(["a", "a", "b", "b", "c"], np.random.default_rng(0))
    >>> all(x != y for x, y in zip(order, order[1:]))
    True
    """
    counts = Counter(items)
    keys = list(dict.fromkeys(items))
    if counts and max(counts.values()) > (len(items) + 1) // 2:
        return [items[i] for i in rng.permutation(len(items))]  # impossible: plain shuffle
    left = np.array([counts[k] for k in keys])
    out, previous = [], -1
    for n in range(len(items), 0, -1):
        ok = (left > 0) & _feasible(left, n)
        if previous >= 0:
            ok[previous] = False
        candidates = np.flatnonzero(ok)
        weights = left[candidates].astype(float)
        previous = int(candidates[rng.choice(len(candidates), p=weights / weights.sum())])
        left[previous] -= 1
        out.append(keys[previous])
    return out


def _feasible(counts: np.ndarray, n: int) -> np.ndarray:
    """Per key: after taking it from ``counts`` (``n`` items in all), can the rest be ordered without
    repeats and not start with it? From the two largest counts, for all keys at once: copying the
    counts for every key made a 2304-trial list of 768 stimuli take hours.

    >>> _feasible(np.array([2, 1]), 3).tolist()          # after "b", "a a" would repeat
    [True, False]
    """
    top = counts.max()
    at_top = int((counts == top).sum())
    below = counts[counts < top]
    second = below.max() if len(below) else 0
    own = counts - 1
    largest = np.where((counts < top) | (at_top > 1), top, np.maximum(own, second))
    return (largest <= n // 2) & (own <= (n - 1) // 2)


def balanced_labels(n: int, k: int, rng: np.random.Generator, start: int = 0) -> list[int]:
    """``n`` labels from ``range(k)`` as evenly as possible, in random order; the labels dealt are
    ``start``, ``start + 1``, … (mod k), so that groups dealt one after the other with ``start`` = the
    number dealt before them share the surplus out evenly over all of them."""
    return [int(x) for x in rng.permutation([(start + i) % k for i in range(n)])]


def counterbalanced_orders(protocol: Protocol, n_blocks: int) -> list[list[int]] | None:
    """The block orders dealt to participants (indices into :func:`block_cells`), None unless counterbalanced."""
    if protocol.blocks.order not in ("counterbalanced", "latin_square"):
        return None
    mains = main_blocks(protocol)
    return nested_orders(len(mains), n_blocks // len(mains)) if mains else williams_orders(n_blocks)


def random_block_order(protocol: Protocol, n_blocks: int, rng: np.random.Generator) -> list[int]:
    """A participant's random block order; nested: the main blocks shuffled, then the sub-blocks of each."""
    mains = main_blocks(protocol)
    if not mains:
        return [int(i) for i in rng.permutation(n_blocks)]
    n_sub = n_blocks // len(mains)
    return [int(m) * n_sub + int(s) for m in rng.permutation(len(mains)) for s in rng.permutation(n_sub)]


def order_balance_notes(group_cells: list[dict], group_of: list[int], block_orders: dict[int, list[str]],
                        order_labels: list[list[str]]) -> list[str]:
    """A note, with the counts, when the counterbalanced block orders (``order_labels``; none for
    ``random`` or ``fixed``) cannot be dealt equally often within each between group."""
    k = len(order_labels)
    if k < 2 or all(size % k == 0 for size in Counter(group_of).values()):
        return []
    counts = {" → ".join(order): Counter() for order in order_labels}
    for participant, order in block_orders.items():
        counts[" → ".join(order)][group_of[participant - 1]] += 1
    if len(group_cells) > 1:
        rows = "; ".join(f"{order}: " + ", ".join(f"{block_label(cell)} {dealt[g]}" for g, cell in enumerate(group_cells))
                         + f" (total {sum(dealt.values())})" for order, dealt in counts.items())
    else:
        rows = "; ".join(f"{order}: {sum(dealt.values())}" for order, dealt in counts.items())
    within = " within each between group" if len(group_cells) > 1 else ""
    return [f"blocks.order: {len(group_of)} participants cannot see the {k} counterbalanced block orders equally "
            f"often{within}; orders dealt: {rows}. A multiple of {k * len(group_cells)} participants balances them"]


def arrangement_balance_notes(protocol: Protocol, group_sizes: list[int]) -> list[str]:
    """A note when screen arrangements rotate between participants (:func:`arrangement_index`) but a
    between group's size is not a multiple of the k levels, so some levels stand in some places more
    often (each group's leftover participants start the rotation again).

    >>> from stimuli.protocol import load_protocol
    >>> arrangement_balance_notes(load_protocol("protocols/thesis_pointlight.yaml"), [67])[0][:60]
    'alternatives: 67 participants cannot see each of the 6 STREN'
    """
    shown = arrangements(protocol)
    if protocol.alternatives.counterbalance != "between" or len(shown) < 2:
        return []
    k = len(shown[0])
    if all(size % k == 0 for size in group_sizes):
        return []
    factor = protocol.factors_with_role("alternatives")[0].name
    per_group = " in each between group" if len(group_sizes) > 1 else ""
    return [f"alternatives: {sum(group_sizes)} participants cannot see each of the {k} {factor} levels equally "
            f"often in each screen position{per_group} (group sizes {', '.join(map(str, group_sizes))}); a multiple "
            f"of {k * len(group_sizes)} participants balances them"]


def arrangement_count_notes(protocol: Protocol) -> list[str]:
    """A note when ``arrangements: all`` makes far more screen orders than a Latin square needs: every
    one is a clip to render, and a Qualtrics rotation group (its randomizer then balances the groups,
    not the positions).

    >>> from stimuli.protocol import load_protocol
    >>> p = load_protocol("protocols/thesis_pointlight.yaml")
    >>> arrangement_count_notes(p.model_copy(update={"alternatives": p.alternatives.model_copy(
    ...     update={"arrangements": "all"})}))[0][:57]
    'alternatives.arrangements: all makes 720 screen orders of'
    """
    shown = arrangements(protocol)
    k = len(shown[0])
    if protocol.alternatives.arrangements != "all" or k < 4:
        return []
    return [f"alternatives.arrangements: all makes {len(shown)} screen orders of the {k} levels per condition, each a "
            f"clip to render; latin_square balances the positions with {k}"]

