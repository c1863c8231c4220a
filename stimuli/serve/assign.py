"""Which design list a new participant gets: the least-filled one.

A list is filled by its finished sessions and by the sessions still in progress (seen within the
expiry time); an abandoned session expires and frees its slot. Ties go to the lowest list number, so
with no dropouts the first N participants get exactly the design's N lists, in order.

>>> least_filled([1, 2, 3], {1: 1, 2: 0, 3: 1})
2
>>> least_filled([1, 2, 3, 4], {})
1
>>> least_filled([3, 4], {3: 2, 4: 2})
3
"""

from __future__ import annotations


def least_filled(lists: list[int], occupancy: dict[int, int]) -> int:
    """The list with the fewest occupied slots (lowest number among equals)."""
    if not lists:
        raise ValueError("no list to choose from")
    return min(lists, key=lambda n: (occupancy.get(n, 0), n))


def candidate_lists(lists: dict[int, dict], params: dict[str, str], between: list[str]) -> list[int]:
    """The lists a participant may get: all, or those of the between-group levels the URL names.

    A URL level that matches no list is ignored (the participant still gets a balanced list).

    >>> lists = {1: {"groups": {"SEX": "F"}}, 2: {"groups": {"SEX": "M"}}}
    >>> candidate_lists(lists, {"SEX": "M"}, ["SEX"])
    [2]
    >>> candidate_lists(lists, {"SEX": "X"}, ["SEX"])
    [1, 2]
    """
    pool = [n for n, entry in sorted(lists.items())
            if all(f not in params or entry["groups"].get(f) == params[f] for f in between)]
    return pool or sorted(lists)
