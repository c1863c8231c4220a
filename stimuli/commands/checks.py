"""Checks of command-line numbers, shared by the commands: a bad value stops before any work with
a message naming the option, what was given and what was expected (never a silent default).

>>> positive("--fps", 30.0)
30.0
>>> in_range("--height", 1.8, (1.2, 2.3), "m")
1.8
"""

from __future__ import annotations

import math

from stimuli.errors import StimuliError


def positive(option: str, value, what: str = "a number > 0"):
    """``value`` if it is a finite number > 0 (None, the option not given, passes)."""
    if value is not None and not (math.isfinite(value) and value > 0):
        raise StimuliError(f"{option}: expected {what}, got {value}")
    return value


def at_least(option: str, value, low: int):
    """``value`` if it is >= ``low`` (None passes); for counts such as --cycles or --workers."""
    if value is not None and value < low:
        raise StimuliError(f"{option}: expected a whole number >= {low}, got {value}")
    return value


def in_range(option: str, value, bounds: tuple[float, float], unit: str = ""):
    """``value`` if it lies in the closed range ``bounds`` (None passes)."""
    low, high = bounds
    if value is not None and not (math.isfinite(value) and low <= value <= high):
        unit = f" {unit}" if unit else ""
        raise StimuliError(f"{option}: {value:g} is outside the human range {low:g}–{high:g}{unit}")
    return value


def human_body(height_m, bmi, height_option: str = "--height", bmi_option: str = "--bmi") -> None:
    """Height (m) and BMI within the protocol's human ranges (the same limits a protocol's actors have)."""
    from stimuli.protocol import BMI_RANGE, HEIGHT_RANGE_M

    in_range(height_option, height_m, HEIGHT_RANGE_M, "m (metres, not centimetres)")
    in_range(bmi_option, bmi, BMI_RANGE, "kg/m²")
