"""Running leg kinematics for the generator's jog, from the bundled CMU run capture (35_17).

CGM2.3's normative curves are walking. A jog made by time-warping them keeps walking's knee: two
stance peaks, the swing peak at 57 % of the cycle, then a nearly straight knee reaching for the
belt while the body is still in flight. Runners land on a knee bent about 20°, flex it to 40–50°
at mid-stance and peak near 90° late in swing (Novacheck 1998). The bundled capture of CMU
subject 35 running has that pattern; its left gait cycle, heel strike to heel strike (foot
contacts from the foot's speed over the ground), gives the jog's sagittal leg curves, measured in
the plane of the vertical and the runner's mean facing direction:

- ``hip``: the thigh's angle to the vertical (flexion positive; the generator's pelvis is level),
- ``knee``: knee flexion, thigh angle minus shank angle,
- ``ankle``: dorsiflexion, the foot–shank angle relative to the capture's rest pose.

Each is a periodic Fourier series of :data:`HARMONICS` harmonics least-squares fitted to the
cycle's frames (it joins the cycle's two ends smoothly and removes capture noise).

Examples
--------
>>> import numpy as np
>>> knee = run_curve("knee")
>>> bool(15 < knee(np.array([0.0]))[0] < 35), bool(80 < knee(np.linspace(0, 1, 100)).max() < 100)
(True, True)
>>> bool(0.15 < run_toe_off() < 0.35)      # a run: stance is a quarter of the cycle
True
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1] / "data" / "cmu_35_17_run.bvh"
HARMONICS = 8
# A foot is on the ground while it moves slower than this over it (m/s). The capture's feet
# settle within 0.5 m/s for 22 of the cycle's 90 frames (24 %), within 0.3 m/s for 16 (18 %):
# the looser bound keeps the heel's landing and the push-off roll in stance.
CONTACT_SPEED_MPS = 0.5
CURVES = ("hip", "knee", "ankle")


def _sagittal_angle(v: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """Angle (degrees) of segment vectors from straight down, positive towards ``forward``."""
    return np.degrees(np.arctan2(v @ forward, -v[..., 1]))


@lru_cache(maxsize=1)
def _cycle() -> tuple[dict[str, np.ndarray], float]:
    """The capture's left cycle: per curve the sampled values, and the toe-off fraction."""
    from stimuli.motion.bvh import read_bvh
    from stimuli.motion.events import contacts, facing, foot_points
    from stimuli.motion.skeleton import role_indices

    run = read_bvh(DATA)
    roles = role_indices(run)
    _, pos = run.global_transforms()
    forward = facing(pos, roles).mean(axis=0)
    forward[1] = 0.0
    forward /= np.linalg.norm(forward)
    contact = contacts(foot_points(run, pos)["l"], run.fps, speed_tol=CONTACT_SPEED_MPS)
    strikes = np.flatnonzero(np.diff(contact.astype(int)) == 1) + 1
    if len(strikes) < 2:
        raise ValueError(f"{DATA.name}: fewer than two left foot contacts, no whole cycle")
    start, end = int(strikes[0]), int(strikes[1])
    toe_off = int(np.argmin(contact[start:end]))  # frames from heel strike to the first one off the ground
    joint = {k: pos[start:end, roles[f"l_{k}"]] for k in ("hip", "knee", "ankle", "toe")}
    thigh = _sagittal_angle(joint["knee"] - joint["hip"], forward)
    shank = _sagittal_angle(joint["ankle"] - joint["knee"], forward)
    foot = _sagittal_angle(joint["toe"] - joint["ankle"], forward)
    rest = run.rest_positions()
    rest_foot = (_sagittal_angle(rest[roles["l_toe"]] - rest[roles["l_ankle"]], forward)
                 - _sagittal_angle(rest[roles["l_ankle"]] - rest[roles["l_knee"]], forward))
    values = {"hip": thigh, "knee": thigh - shank, "ankle": foot - shank - rest_foot}
    return values, toe_off / (end - start)


def run_curve(name: str):
    """A function of cycle fraction φ (any real; wraps; 0 = left heel strike) giving degrees."""
    if name not in CURVES:
        raise ValueError(f"running curves are {', '.join(CURVES)}, not {name!r}")
    y = _cycle()[0][name]
    coef = np.fft.rfft(y)[: HARMONICS + 1] / len(y)
    coef[1:] *= 2.0
    k = np.arange(HARMONICS + 1)

    def f(phi: np.ndarray) -> np.ndarray:
        phase = np.exp(2j * np.pi * np.multiply.outer(np.asarray(phi, float), k))
        return (phase @ coef).real

    return f


def run_toe_off() -> float:
    """Fraction of the capture's cycle at left toe off (stance share of the cycle)."""
    return _cycle()[1]
