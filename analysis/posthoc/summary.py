"""Cell labels and the paper's compact summary strings (``"L2b > H2b"``, ``"F/L1b > F/H1b, M/H2b"``)."""

from __future__ import annotations

from analysis.errors import AnalysisError


def abbreviate(factor: str, level: str, abbreviations: dict | None) -> str:
    """Level label through ``abbreviations``: ``{level: abbr}`` or ``{factor: {level: abbr}}``.

    >>> abbreviate("GAIT", "Walk", {"GAIT": {"Walk": "W"}})
    'W'
    """
    if not abbreviations:
        return level
    per_factor = abbreviations.get(factor)
    if isinstance(per_factor, dict) and level in per_factor:
        return str(per_factor[level])
    v = abbreviations.get(level)
    return level if v is None or isinstance(v, dict) else str(v)


def cell_labels(factors, cells, abbreviations: dict | None, sep: str = "/", effect: str = "") -> list[str]:
    """``"F/L1b"``: each cell's (abbreviated) levels joined by ``sep``; refused when two cells look the same.

    >>> cell_labels(("SEX", "BODY"), [("F", "L1"), ("M", "L1")], {"L1": "L1b"})
    ['F/L1b', 'M/L1b']
    """
    labels = [sep.join(abbreviate(f, lv, abbreviations) for f, lv in zip(factors, c)) for c in cells]
    if len(set(labels)) != len(labels):
        raise AnalysisError(f"abbreviations make two cells of {effect or ':'.join(factors)} look the same; "
                            "give distinct abbreviations")
    return labels


def summarize(labels, means, i, j, p, alpha: float) -> str:
    """``"A > B, C; D > B"``: for each cell in level order, the cells it significantly exceeds.

    >>> summarize(["W", "J"], [2.0, 1.0], [0], [1], [0.01], 0.05)
    'W > J'
    """
    k = len(labels)
    beats = [[] for _ in range(k)]
    for a, b, pv in zip(i, j, p):
        if pv < alpha:
            hi, lo = (a, b) if means[a] > means[b] else (b, a)
            beats[hi].append(lo)
    parts = [f"{labels[h]} > {', '.join(labels[x] for x in sorted(lows))}" for h, lows in enumerate(beats) if lows]
    return "; ".join(parts)
