"""Where the Qualtrics and PsychoPy exports put the protocol's attention checks.

jsPsych and ``shapemotion serve`` add a check after every ``every``-th test trial of a participant's
list, counted across blocks, none after the last (``floor((N - 1) / every)`` checks for N test trials).
Qualtrics and PsychoPy randomise the trials (and often the blocks) at run time, so a check cannot follow
"the participant's 16th trial"; it takes a fixed slot inside one block instead. The slots are those
jsPsych's rule gives the blocks in declared order: the check after overall test position ``j * every``
goes after that position's place in its block. Every block is shown once, so each participant gets
the same number of checks as in jsPsych whatever the block order, at the same places when the order
is fixed; with blocks in random order they keep their in-block positions.

>>> check_slots([10, 10, 10], 8)
[[8], [6], [4]]
>>> check_slots([4, 4], 4)     # a check may end a block; none after the last trial of the last
[[4], []]
"""

from __future__ import annotations

# Export tag of the k-th check question of a Qualtrics survey (k = 1, 2, … through the whole file);
# the response import recognises these columns (analysis/responses/qualtrics.py ATTENTION_TAG).
CHECK_TAG = "attention_check_{k}"


def check_slots(test_counts: list[int], every: int) -> list[list[int]]:
    """Per block (declared order, ``test_counts`` its test trials): after which of its test trials
    (1-based) a check comes."""
    total = sum(test_counts)
    slots: list[list[int]] = [[] for _ in test_counts]
    start = 0
    for block, count in enumerate(test_counts):
        slots[block] = [p - start for p in range(every, total, every) if start < p <= start + count]
        start += count
    return slots


def block_slots(blocks: list, checks) -> dict[int, list[int]]:
    """``id(block)`` → :func:`check_slots` of each of one rotation's blocks (declared order, with nesting
    every sub-block); ``{}`` when ``checks`` (the protocol's ``attention_checks``) is None."""
    if checks is None:
        return {}
    return {id(b): s for b, s in zip(blocks, check_slots([len(b.tests) for b in blocks], checks.every))}


def checks_per_participant(test_counts: list[int], every: int) -> int:
    """How many checks one participant answers: jsPsych's count for the same number of test trials.

    >>> checks_per_participant([10, 10, 10], 8), (30 - 1) // 8
    (3, 3)
    """
    return sum(len(s) for s in check_slots(test_counts, every))


def after_every_test(trials: list[dict], every: int, check) -> list[dict]:
    """``trials`` with ``check(trial)`` after every ``every``-th test trial (``kind`` = ``test``), none after
    the last: the static jsPsych page's rule, shared by the served lists and the PsychoPy replay lists.

    >>> [t["kind"] for t in after_every_test([{"kind": "test"}] * 3, 1, lambda t: {"kind": "check"})]
    ['test', 'check', 'test', 'check', 'test']
    """
    n_tests = sum(t["kind"] == "test" for t in trials)
    tests = 0
    out = []
    for trial in trials:
        out.append(trial)
        tests += trial["kind"] == "test"
        if trial["kind"] == "test" and tests % every == 0 and tests < n_tests:
            out.append(check(trial))
    return out


def with_check_rows(trials: list[dict], every: int) -> list[dict]:
    """A participant's trial rows (``kind`` test/practice/…) with a check row after every ``every``-th test
    trial, none after the last: jsPsych's rule on the seeded list. A check row has the columns of the
    others, empty but for ``participant``, ``block``, ``block_label`` and ``kind`` = ``attention_check``.

    >>> rows = [{"participant": "1", "block": "1", "kind": "test", "stimulus_id": s} for s in "abc"]
    >>> [r["stimulus_id"] or r["kind"] for r in with_check_rows(rows, 2)]
    ['a', 'b', 'attention_check', 'c']
    """
    def check_row(trial: dict) -> dict:
        kept = {k: trial[k] for k in ("participant", "block", "block_label") if k in trial}
        return {k: "" for k in trial} | kept | {"kind": "attention_check"}

    return after_every_test(trials, every, check_row)


def interleave(items: list, slots: list[int], check) -> list:
    """``items`` with ``check()``'s value after each 1-based position of ``slots``.

    >>> interleave(["a", "b", "c"], [2], lambda: "CHECK")
    ['a', 'b', 'CHECK', 'c']
    """
    out = []
    for i, item in enumerate(items, start=1):
        out.append(item)
        if i in slots:
            out.append(check())
    return out
