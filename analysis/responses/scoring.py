"""Turn one raw answer into a score on the design's response scale, or say why it is outside the scale.

- Likert: ``1``…``k`` or a label of the protocol's scale (case and spacing ignored) → rating 1…k.
- k-AFC: an alternatives level (``NoCOM``), a side (``left``/``right``), a position label (``A``…) or a
  1-based position → the chosen level, through the stimulus's left/right (or positions) placement.
- Ranking: ranks per position (Qualtrics rank order) or an order ``A>C>B>D`` (best first) → levels best first.

>>> score_likert("Very Consistent", ["Very Inconsistent", "Inconsistent", "Neutral", "Consistent", "Very Consistent"])
5
>>> score_choice("right", ["NoCOM", "COM"], ["left", "right"])
('COM', 2)
>>> score_ranking(None, "B>A>C", ["x", "y", "z"], ["A", "B", "C"])
['y', 'x', 'z']
"""

from __future__ import annotations

import re


class OutsideScale(ValueError):
    """The answer is not a value the response scale allows; the message says what was expected."""


def _norm(text: str) -> str:
    return re.sub(r"\s+", " ", str(text)).strip().casefold()


def _integer(text: str) -> int | None:
    try:
        number = float(text)
    except (TypeError, ValueError):
        return None
    return int(number) if number.is_integer() else None


def score_likert(value: str, labels: list[str], k: int | None = None) -> int:
    """Rating 1…k from a number or a scale label."""
    k = k or len(labels)
    number = _integer(value)
    if number is not None:
        if 1 <= number <= k:
            return number
        raise OutsideScale(f"{value!r} is outside 1…{k}")
    names = {_norm(label): i + 1 for i, label in enumerate(labels)}
    if _norm(value) in names:
        return names[_norm(value)]
    raise OutsideScale(f"{value!r} is neither 1…{k} nor one of the labels {labels}")


def _position(token: str, arrangement: list[str], position_labels: list[str]) -> int | None:
    """1-based screen position named by a level, a side/position label or a number."""
    text = _norm(token)
    for names in (arrangement, position_labels, ["left", "right"] if len(arrangement) == 2 else []):
        lowered = [_norm(n) for n in names]
        if text in lowered:
            return lowered.index(text) + 1
    number = _integer(token)
    return number if number is not None and 1 <= number <= len(arrangement) else None


def score_choice(value: str, arrangement: list[str], position_labels: list[str]) -> tuple[str, int]:
    """(chosen level, 1-based position) of a forced-choice answer."""
    pos = _position(value, arrangement, position_labels)
    if pos is None:
        raise OutsideScale(f"{value!r} names none of the {len(arrangement)} alternatives {arrangement} "
                           f"(nor a position {position_labels or list(range(1, len(arrangement) + 1))})")
    return arrangement[pos - 1], pos


def score_ranking(ranks: list[str] | None, order: str, arrangement: list[str],
                  position_labels: list[str]) -> list[str]:
    """Alternatives levels best first, from ranks per position or from an order string."""
    k = len(arrangement)
    if ranks is not None:
        numbers = [_integer(r) for r in ranks]
        if len(numbers) != k or sorted(n or 0 for n in numbers) != list(range(1, k + 1)):
            raise OutsideScale(f"ranks {ranks} are not a permutation of 1…{k}")
        return [arrangement[numbers.index(r)] for r in range(1, k + 1)]
    tokens = [t for t in re.split(r"\s*[>,;|]\s*", str(order).strip()) if t]
    positions = [_position(t, arrangement, position_labels) for t in tokens]
    if len(tokens) != k or None in positions or len(set(positions)) != k:
        raise OutsideScale(f"{order!r} is not an order of all {k} alternatives (e.g. "
                           f"{'>'.join(position_labels or arrangement)})")
    return [arrangement[p - 1] for p in positions]
