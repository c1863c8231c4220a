"""The body a motion was recorded or averaged on, read from its metadata: the reference of b.

``physics retarget`` and ``physics protocol`` both measure the COM change against this body, so
both read it here, with the same fields in the same order of preference and the same checks.
"""

from __future__ import annotations

import dataclasses
import math

from stimuli.errors import StimuliError


@dataclasses.dataclass(frozen=True)
class OwnBody:
    """Height (m), weight (kg), BMI and sex a motion's metadata records; None where absent."""

    height_m: float | None
    weight_kg: float | None
    bmi: float | None
    sex: str | None

    def weight_at(self, height_m: float) -> tuple[float, str] | None:
        """(weight kg, the metadata field it came from) for a body of ``height_m``; ``weight_kg``
        before ``bmi``; None when the metadata records neither.

        >>> OwnBody(None, None, 25.0, "F").weight_at(2.0)
        (100.0, 'bmi')
        """
        if self.weight_kg is not None:
            return self.weight_kg, "weight_kg"
        if self.bmi is not None:
            return self.bmi * height_m ** 2, "bmi"
        return None


def own_body(motion, where, hint: str = "", skip: tuple[str, ...] = ()) -> OwnBody:
    """The body ``motion``'s metadata records (``height_m``, ``weight_kg``, ``bmi``, ``sex``).

    A figure that is not a finite number is an error naming ``where`` (the motion's file), the
    field and the unit, followed by ``hint`` (how the caller lets the user give the body instead);
    the fields in ``skip`` (given by the user instead) are neither read nor checked.
    A sex other than F or M is returned as recorded, for the caller to report.

    >>> from types import SimpleNamespace
    >>> own_body(SimpleNamespace(metadata={"height_m": 1.7, "bmi": 24.0, "sex": "M"}), "walk.npz")
    OwnBody(height_m=1.7, weight_kg=None, bmi=24.0, sex='M')
    """
    meta = motion.metadata
    numbers = {field: None if field in skip else _number(meta.get(field), where, field, unit, hint)
               for field, unit in (("height_m", "metres"), ("weight_kg", "kilograms"), ("bmi", "kg/m²"))}
    sex = meta.get("sex")
    return OwnBody(**numbers, sex=None if sex is None else str(sex))


def _number(value, where, field: str, unit: str, hint: str) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise StimuliError(f"{where}: metadata {field} is {value!r}; expected a number ({unit})" + hint)
    return float(value)


def check_reference(height_m: float, weight_kg: float, height_from: str, weight_from: str) -> None:
    """The reference body's height (metres, a human one) and weight (a physical one for the ragdoll);
    errors name where each figure came from (an option, or ``file: metadata field``)."""
    from stimuli.physics.inertia import check_weight
    from stimuli.protocol import HEIGHT_RANGE_M

    low, high = HEIGHT_RANGE_M
    if not (math.isfinite(height_m) and low <= height_m <= high):
        raise StimuliError(f"{height_from}: {height_m:g} is outside the human range {low:g}–{high:g} m "
                           "(the motion's own body, in metres, not centimetres)")
    check_weight(weight_kg, height_m, where=weight_from)
