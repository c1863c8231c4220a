"""Turn one raw answer into a score on the design's response scale, or say why it is outside the scale.

- Likert: ``1``…``k`` or a label of the protocol's scale (case and spacing ignored) → rating 1…k.
- k-AFC: the chosen screen position, or the chosen level → the chosen level, through the stimulus's
  left/right (or positions) placement.
- Ranking: ranks per position (Qualtrics rank order) or an order ``A>C>B>D`` (best first) → levels best first.

What a forced-choice value means is fixed by where it comes from (its *reading*), never guessed from the
value — a level may well be called ``3`` or ``B`` (point-light strengths ``3``, ``12``, ``35`` on positions
``A``–``C``):

- ``CHOICE`` — an answer option of the survey (Qualtrics values, jsPsych ``response``): a number is the
  option's 1-based screen position (Qualtrics numeric export = the choice's recode; jsPsych's 0-based button
  index + 1), text is the option's label: a position label (``A``…) or, for two clips, ``left``/``right``.
  A level name is accepted only where it cannot be read as a position (it is no position label, side or
  number); a value that reads as two different positions (a position label that is a number other than its
  own position) is outside the scale.
- ``LABEL`` — a Qualtrics choice-text export: as ``CHOICE`` for choices; a Likert value is the scale label
  first, so a scale labelled ``0``…``4`` is read by its labels (the numeric export's recodes are 1…k).
- ``LEVEL`` — the long format's ``response``: the chosen level's name. A position label or side is read as a
  position only if no level is called like one, and a number only if no level name is a number.

>>> score_likert("Very Consistent", ["Very Inconsistent", "Inconsistent", "Neutral", "Consistent", "Very Consistent"])
5
>>> score_choice("right", ["NoCOM", "COM"], ["left", "right"])
('COM', 2)
>>> score_choice("3", ["12", "35", "3"], ["A", "B", "C"], CHOICE), score_choice("3", ["12", "35", "3"], ["A", "B", "C"], LEVEL)
(('3', 3), ('3', 3))
>>> score_choice("1", ["12", "35", "3"], ["A", "B", "C"], CHOICE)
('12', 1)
>>> score_ranking(None, "B>A>C", ["x", "y", "z"], ["A", "B", "C"])
['y', 'x', 'z']
"""

from __future__ import annotations

import re

from analysis.responses.read import shown

CHOICE = "choice"   # a survey's answer option: number = 1-based position, text = its position label
LABEL = "label"     # a Qualtrics choice-text export: the answer option's text, even when it looks like a number
LEVEL = "level"     # the long format: the chosen level's name
READINGS = (CHOICE, LABEL, LEVEL)


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


def score_likert(value: str, labels: list[str], k: int | None = None, reading: str = CHOICE) -> int:
    """Rating 1…k from a number or a scale label. A choice-text export (``LABEL``) names the label, so a
    scale labelled ``0``…``4`` reads ``3`` as its fourth point; elsewhere a number is the rating itself.

    >>> score_likert("3", ["0", "1", "2", "3", "4"], reading=LABEL), score_likert("3", ["0", "1", "2", "3", "4"])
    (4, 3)
    """
    k = k or len(labels)
    names = {_norm(label): i + 1 for i, label in enumerate(labels)}
    if reading == LABEL and _norm(value) in names:
        return names[_norm(value)]
    number = _integer(value)
    if number is not None:
        if 1 <= number <= k:
            return number
        raise OutsideScale(f"{shown(value)} is outside 1…{k}")
    if _norm(value) in names:
        return names[_norm(value)]
    raise OutsideScale(f"{shown(value)} is neither 1…{k} nor one of the labels {labels}")


def screen_labels(position_labels: list[str], k: int) -> list[str]:
    """What the k screen positions are called: the design's position labels, else ``A``, ``B``, … (as the
    survey exporters name them)."""
    return list(position_labels) if len(position_labels) == k else [chr(ord("A") + i) for i in range(k)]


def _label_positions(k: int, position_labels: list[str]) -> dict[str, set[int]]:
    """Normalised position label or side → the 1-based position(s) it names."""
    out: dict[str, set[int]] = {}
    names = [screen_labels(position_labels, k)] + ([["left", "right"]] if k == 2 else [])
    for labels in names:
        for i, label in enumerate(labels):
            out.setdefault(_norm(label), set()).add(i + 1)
    return out


def _position(token: str, arrangement: list[str], position_labels: list[str], reading: str) -> int:
    """1-based screen position an answer names, read as ``reading`` says (see the module docstring)."""
    if reading not in READINGS:
        raise ValueError(f"unknown reading {reading!r}")
    reading = CHOICE if reading == LABEL else reading   # a choice's text is its position label or side
    k = len(arrangement)
    text = _norm(token)
    levels = [_norm(level) for level in arrangement]
    labels = _label_positions(k, position_labels)
    number = _integer(token)
    as_level = levels.index(text) + 1 if text in levels else None
    as_label = labels.get(text, set())
    if len(as_label) > 1:
        raise OutsideScale(f"{shown(token)} names several screen positions {sorted(as_label)}")
    as_label = next(iter(as_label), None)
    as_number = number if number is not None and 1 <= number <= k else None
    on_screen = screen_labels(position_labels, k)
    if reading == LEVEL:
        if as_level is not None:
            return as_level
        level_like_label = any(lv in labels for lv in levels)
        level_like_number = any(_integer(lv) is not None for lv in arrangement)
        if as_label is not None and not level_like_label:
            return as_label
        if as_number is not None and not level_like_number:
            return as_number
        allowed = ["a level name " + str(arrangement)]
        if not level_like_label:
            allowed.append(f"a position label {on_screen}" + (" or left/right" if k == 2 else ""))
        if not level_like_number:
            allowed.append(f"a 1-based position 1…{k}")
        note = ""
        if level_like_number and number is not None:
            note = " (the long format reads numbers as level names here, as some levels are numbers)"
        elif level_like_label and as_label is not None:
            note = " (the long format reads it as a level name here, as some levels are named like positions)"
        raise OutsideScale(f"{shown(token)} is not {' or '.join(allowed)}{note}")
    # CHOICE: number → position; text → position label / side; a level name only where it is neither
    if number is not None:
        if as_number is None:
            raise OutsideScale(f"{shown(token)} is not a screen position 1…{k} (a number in a survey export is the "
                               f"answer option's position, not a level)")
        if as_label is not None and as_label != as_number:
            raise OutsideScale(f"{shown(token)} is ambiguous: position {as_number}, but also the label of position "
                               f"{as_label} ({on_screen})")
        return as_number
    if as_label is not None:
        return as_label
    if as_level is not None:
        return as_level
    raise OutsideScale(f"{shown(token)} names none of the {k} screen positions (labels {on_screen}"
                       f"{', left/right' if k == 2 else ''} or 1…{k}) nor one of the levels {arrangement}")


def score_choice(value: str, arrangement: list[str], position_labels: list[str],
                 reading: str = CHOICE) -> tuple[str, int]:
    """(chosen level, 1-based position) of a forced-choice answer."""
    pos = _position(value, arrangement, position_labels, reading)
    return arrangement[pos - 1], pos


def score_ranking(ranks: list[str] | None, order: str, arrangement: list[str],
                  position_labels: list[str], reading: str = CHOICE) -> list[str]:
    """Alternatives levels best first, from ranks per position or from an order string."""
    k = len(arrangement)
    if ranks is not None:
        numbers = [_integer(r) for r in ranks]
        if len(numbers) != k or sorted(n or 0 for n in numbers) != list(range(1, k + 1)):
            raise OutsideScale(f"ranks {ranks} are not a permutation of 1…{k}")
        return [arrangement[numbers.index(r)] for r in range(1, k + 1)]
    tokens = [t for t in re.split(r"\s*[>,;|]\s*", str(order).strip()) if t]
    if len(tokens) != k:
        raise OutsideScale(f"{shown(order)} is not an order of all {k} alternatives (e.g. "
                           f"{'>'.join(screen_labels(position_labels, k) if reading == CHOICE else arrangement)})")
    try:
        positions = [_position(t, arrangement, position_labels, reading) for t in tokens]
    except OutsideScale as exc:
        raise OutsideScale(f"{shown(order)} is not an order of all {k} alternatives: {exc}") from None
    if len(set(positions)) != k:
        raise OutsideScale(f"{shown(order)} names a position twice; expected each of the {k} alternatives once")
    return [arrangement[p - 1] for p in positions]
