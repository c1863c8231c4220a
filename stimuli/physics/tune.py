"""Find the controller gains once, for the base character, then keep them fixed (paper, appendix).

The paper minimised the squared difference between ragdoll and reference joint angles for its
base character and then fixed the gains for every body. Stiffer is always more accurate, so the
search is two-stage: (1) the smallest joint stiffness ``k_p`` on a doubling grid whose tracking
RMS error is within ``target_rms_deg`` (critically damped, ``k_d = 2√k_p``); (2) a short bounded
Nelder–Mead search over the damping and the root force gains (log scale) minimising the tracking
error at that stiffness. Damping stays within 0.5–1.5 × critical: with the paper's ``−k_d q̇``
less damping always tracks better (no lag) until the simulation blows up, and the gains must stay
stable for bodies up to twice the base weight. The root torque gains follow the force gains through a fixed lever arm
(``k_pr = k_pf·L²``). The result, with the base character's per-DoF inertia profile, goes to
``stimuli/physics/gains.json`` (absolute units) and is used unchanged for every body.

Base character: the bundled CMU walk (subject 35, trial 01) on an Anny body of 1.75 m, BMI 23.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from stimuli.physics.controller import GAINS_FILE, Gains, inertia_profile, set_joint_gains
from stimuli.physics.ragdoll import build_ragdoll, compile_model
from stimuli.physics.reference import build_reference
from stimuli.physics.retarget import tracking_rms
from stimuli.physics.simulate import simulate

BASE = {"sex": "M", "height_m": 1.75, "bmi": 23.0, "motion": "cmu_35_01_walk.bvh", "cycles": 2, "fps": 30.0}
LEVER_M = 0.5
DATA = Path(__file__).resolve().parents[1] / "data"


def base_setup(base: dict = BASE):
    """The base character's body and looped reference motion."""
    from stimuli.bodies import fit_body
    from stimuli.motion.bvh import read_bvh
    from stimuli.motion.loop import make_loop

    body = fit_body(base["sex"], base["height_m"], base["bmi"])
    motion = make_loop(read_bvh(DATA / base["motion"]), cycles=base["cycles"]).resample(base["fps"])
    return body, motion


def make_gains(k_p: float, k_d: float, k_pf: float, k_df: float, profile: dict, base: dict) -> Gains:
    return Gains(k_p=k_p, k_d=k_d, k_pf=k_pf, k_df=k_df, k_pr=k_pf * LEVER_M**2, k_dr=k_df * LEVER_M**2,
                 profile=profile, base=base)


def evaluate(model, ref, ragdoll, gains: Gains) -> float:
    """Overall tracking RMS (degrees) of one recorded loop; 1e3 if the ragdoll falls."""
    set_joint_gains(model, *gains.joint_gains(ragdoll.dof_names))
    sim = simulate(model, ref, gains, warmup_loops=1)
    if sim.fell:
        return 1e3
    track = tracking_rms(sim, ragdoll)
    return float(np.sqrt(np.mean(np.square(list(track.values())))))


def tune(base: dict = BASE, target_rms_deg: float = 2.5, max_evals: int = 24, out: Path | None = GAINS_FILE,
         progress=print) -> Gains:
    """Run the two-stage search and (optionally) write ``gains.json``."""
    body, motion = base_setup(base)
    ref, ragdoll = build_reference(motion, body, lambda axes: build_ragdoll(body, None, axes))
    ones = {d: 1.0 for d in ragdoll.dof_names}
    model = compile_model(ragdoll, 1e-3, ones, ones)
    profile = inertia_profile(model)
    k_pf, k_df = 1e4, 1e3
    history = []
    k_p = 1000.0
    while True:
        rms = evaluate(model, ref, ragdoll, make_gains(k_p, 2 * np.sqrt(k_p), k_pf, k_df, profile, base))
        history.append({"k_p": k_p, "k_d": 2 * np.sqrt(k_p), "k_pf": k_pf, "k_df": k_df, "rms_deg": rms})
        progress(f"k_p {k_p:g}: tracking RMS {rms:.2f}°")
        if rms <= target_rms_deg or k_p >= 64000:
            break
        k_p *= 2

    def cost(x):
        g = make_gains(k_p, 2 * np.sqrt(k_p) * np.exp(x[0]), k_pf * np.exp(x[1]), k_df * np.exp(x[2]), profile, base)
        rms = evaluate(model, ref, ragdoll, g)
        history.append({"k_p": g.k_p, "k_d": g.k_d, "k_pf": g.k_pf, "k_df": g.k_df, "rms_deg": rms})
        progress(f"k_d {g.k_d:.1f} k_pf {g.k_pf:.0f} k_df {g.k_df:.0f}: tracking RMS {rms:.3f}°")
        return rms

    bounds = [(np.log(0.5), np.log(1.5)), (np.log(0.25), np.log(4.0)), (np.log(0.25), np.log(4.0))]
    res = minimize(cost, np.zeros(3), method="Nelder-Mead", bounds=bounds,
                   options={"maxfev": max_evals, "initial_simplex": np.array(
                       [[0, 0, 0], [-0.4, 0, 0], [0, 0.7, 0], [0, 0, 0.7]], float)})
    x = res.x
    gains = make_gains(k_p, 2 * np.sqrt(k_p) * np.exp(x[0]), k_pf * np.exp(x[1]), k_df * np.exp(x[2]), profile, base)
    gains.tuning = {"method": "doubling grid on k_p then Nelder-Mead on k_d, k_pf, k_df",
                    "target_rms_deg": target_rms_deg, "best_rms_deg": float(res.fun),
                    "evaluations": len(history), "history": history}
    gains.base = dict(base, body_id=body.body_id, weight_kg=float(body.anthropometry.mass_kg))
    if out is not None:
        gains.save(out)
    return gains


def as_dict(gains: Gains) -> dict:
    return dataclasses.asdict(gains)
