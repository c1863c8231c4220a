"""Figures in the style of the paper, saved as PNG, SVG and PDF (deterministic: no dates, fixed SVG ids).

- :func:`figure4`: mean rating per BODY × MOTION, one panel per SEX × GAIT, consistent cells (body and
  motion of the same actor) starred, error bars ± standard error (the paper's Figure 4);
- :func:`figure9`: percentage of trials each METHOD was chosen, by SEX and GAIT, ± SE (Figure 9);
- :func:`interaction_plot`: means ± SE of any effect (x = first factor, lines = second, panels = the rest);
- :func:`choice_bars`: votes or rank points per alternative (thesis designs);
- :func:`cell_means_plot`: means ± SE of every design cell, for designs no paper figure fits.

Standard errors are across participants (SD / √n of the participants' cell values).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from analysis.io_design import DesignInfo

FORMATS = ("png", "svg", "pdf")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update({"svg.hashsalt": "shapemotion", "font.size": 9, "axes.spines.top": False,
                         "axes.spines.right": False})
    return plt


def save_figure(fig, stem: Path) -> list[Path]:
    """Write ``stem.png``, ``stem.svg`` and ``stem.pdf`` without timestamps (same data → same bytes)."""
    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = []
    for ext in FORMATS:
        path = stem.with_suffix(f".{ext}")
        metadata = {"png": {"Software": None}, "svg": {"Date": None}, "pdf": {"CreationDate": None}}[ext]
        fig.savefig(path, dpi=150 if ext == "png" else None, metadata=metadata, bbox_inches="tight")
        paths.append(path)
    _pyplot().close(fig)
    return paths


def mean_se(frame: pd.DataFrame, dv: str, by: list[str]) -> pd.DataFrame:
    """Mean, SE and n of ``dv`` over participants per ``by`` cell (participant values averaged first).

    >>> f = pd.DataFrame({"participant": [1, 2, 1, 2], "A": ["x", "x", "y", "y"], "v": [1.0, 3.0, 2.0, 2.0]})
    >>> mean_se(f, "v", ["A"])[["A", "mean", "se"]].values.tolist()
    [['x', 2.0, 1.0], ['y', 2.0, 0.0]]
    """
    per_person = frame.groupby(["participant", *by], observed=True)[dv].mean().reset_index()
    out = per_person.groupby(by, observed=True)[dv].agg(["mean", "std", "size"]).reset_index()
    out["se"] = (out["std"] / np.sqrt(out["size"])).fillna(0.0)
    return out.rename(columns={"size": "n"}).drop(columns="std")


def _ordered(frame: pd.DataFrame, design: DesignInfo, factors: list[str]) -> pd.DataFrame:
    frame = frame.copy()
    for f in factors:
        frame[f] = pd.Categorical(frame[f].astype(str), categories=design.factor(f).levels, ordered=True)
    return frame.sort_values(factors)


def _bars(ax, stats: pd.DataFrame, x: str, hue: str, design: DesignInfo, dv_label: str, star=None, ylim=None):
    """Grouped bars: groups along ``x``, one bar per ``hue`` level, ± SE error bars."""
    x_levels, hue_levels = design.factor(x).levels, design.factor(hue).levels
    width = 0.8 / len(hue_levels)
    colours = _pyplot().get_cmap("viridis")(np.linspace(0.15, 0.85, len(hue_levels)))
    for j, level in enumerate(hue_levels):
        sub = stats[stats[hue].astype(str) == level].set_index(x).reindex(x_levels)
        pos = np.arange(len(x_levels)) + (j - (len(hue_levels) - 1) / 2) * width
        ax.bar(pos, sub["mean"], width, yerr=sub["se"], capsize=2, color=colours[j],
               label=design.factor(hue).abbreviation(level) if hue != x else level, edgecolor="black", linewidth=0.4)
        if star is not None:
            for p, xl, m, se in zip(pos, x_levels, sub["mean"], sub["se"]):
                if star(xl, level) and np.isfinite(m):
                    ax.text(p, m + se + 0.05 * (ylim[1] - ylim[0] if ylim else 1), "*", ha="center", fontsize=12)
    ax.set_xticks(np.arange(len(x_levels)), [design.factor(x).abbreviation(v) for v in x_levels])
    ax.set_xlabel(x)
    ax.set_ylabel(dv_label)
    if ylim:
        ax.set_ylim(*ylim)


def _panels(design: DesignInfo, factors: list[str]) -> list[dict[str, str]]:
    import itertools
    return [dict(zip(factors, combo)) for combo in itertools.product(*(design.factor(f).levels for f in factors))]


def figure4(cells: pd.DataFrame, design: DesignInfo, stem: Path, dv: str = "rating") -> list[Path]:
    """Mean rating per BODY × MOTION, panels by the other factors (SEX × GAIT), consistent cells starred."""
    plt = _pyplot()
    body = next((f.name for f in design.factors if f.maps_to == "body"), None)
    motion = next((f.name for f in design.factors if f.maps_to == "motion"), None)
    if body is None or motion is None:
        raise ValueError("figure 4 needs factors mapped to body and motion")
    panel_factors = [f for f in design.between + design.within if f not in (body, motion)]
    panels = _panels(design, panel_factors)
    ncols = len(design.factor(panel_factors[-1]).levels) if panel_factors else 1
    nrows = max(1, len(panels) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.2 * ncols, 2.9 * nrows), squeeze=False, sharey=True)
    k = design.k or 5
    for ax, panel in zip(axes.ravel(), panels):
        sub = cells
        for f, v in panel.items():
            sub = sub[sub[f].astype(str) == v]
        stats = mean_se(sub, dv, [body, motion])
        _bars(ax, stats, body, motion, design, "mean rating", star=lambda b, m: b == m, ylim=(1, k + 0.6))
        ax.set_title(", ".join(f"{f} = {design.factor(f).abbreviation(v)}" for f, v in panel.items()))
    handles, labels = axes.ravel()[0].get_legend_handles_labels()
    fig.legend(handles, labels, title=motion, fontsize=8, title_fontsize=8, ncols=len(labels), loc="lower center")
    fig.suptitle("Mean rating per body and motion (* consistent: same actor's body and motion; ± SE)", fontsize=9)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    return save_figure(fig, stem)


def figure9(percent: pd.DataFrame, design: DesignInfo, stem: Path) -> list[Path]:
    """Percentage of trials each alternative (METHOD) was chosen, per SEX × GAIT cell, ± SE."""
    plt = _pyplot()
    alt = design.alternatives.name
    group_factors = [f for f in design.between + design.within
                     if design.factor(f).maps_to in ("sex", "gait")] or (design.between + design.within)[:2]
    frame = percent.copy()
    frame["cell"] = frame[group_factors].astype(str).agg(" / ".join, axis=1) if group_factors else "all"
    stats = mean_se(frame, "percent", ["cell", alt])
    cells = list(dict.fromkeys(" / ".join(p.values()) for p in _panels(design, group_factors))) or ["all"]
    fig, ax = plt.subplots(figsize=(1.4 * len(cells) + 2, 3.2))
    levels = design.alternatives.levels
    width = 0.8 / len(levels)
    colours = plt.get_cmap("viridis")(np.linspace(0.2, 0.8, len(levels)))
    for j, level in enumerate(levels):
        sub = stats[stats[alt].astype(str) == level].set_index("cell").reindex(cells)
        pos = np.arange(len(cells)) + (j - (len(levels) - 1) / 2) * width
        ax.bar(pos, sub["mean"], width, yerr=sub["se"], capsize=3, color=colours[j], label=level, edgecolor="black",
               linewidth=0.4)
    ax.axhline(100.0 / len(levels), color="grey", linewidth=0.8, linestyle="--")
    ax.set_xticks(np.arange(len(cells)), cells)
    ax.set_xlabel(" / ".join(group_factors))
    ax.set_ylabel("% of trials chosen")
    ax.set_ylim(0, 100)
    ax.legend(title=alt, fontsize=8)
    ax.set_title(f"Percentage of time each {alt} was chosen (± SE; dashed: chance)", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, stem)


def interaction_plot(frame: pd.DataFrame, dv: str, factors: list[str], design: DesignInfo, stem: Path,
                     title: str = "") -> list[Path]:
    """Means ± SE of one effect: x = first factor, one line per level of the second, panels for the rest."""
    plt = _pyplot()
    x, hue, rest = factors[0], (factors[1] if len(factors) > 1 else None), factors[2:]
    panels = _panels(design, rest) or [{}]
    fig, axes = plt.subplots(1, len(panels), figsize=(3.4 * len(panels) + 0.6, 3.0), squeeze=False, sharey=True)
    stats = mean_se(frame, dv, factors)
    x_levels = design.factor(x).levels
    for ax, panel in zip(axes.ravel(), panels):
        sub = stats
        for f, v in panel.items():
            sub = sub[sub[f].astype(str) == v]
        for level in (design.factor(hue).levels if hue else [None]):
            line = sub if level is None else sub[sub[hue].astype(str) == level]
            line = line.set_index(line[x].astype(str)).reindex(x_levels)
            ax.errorbar(np.arange(len(x_levels)), line["mean"], yerr=line["se"], marker="o", capsize=3,
                        label=design.factor(hue).abbreviation(level) if hue else None)
        ax.set_xticks(np.arange(len(x_levels)), [design.factor(x).abbreviation(v) for v in x_levels])
        ax.set_xlabel(x)
        ax.set_title(", ".join(f"{f} = {v}" for f, v in panel.items()), fontsize=8)
    axes[0, 0].set_ylabel(dv)
    if hue:
        axes[0, 0].legend(title=hue, fontsize=7, title_fontsize=7)
    fig.suptitle(title or f"{' × '.join(factors)} (means ± SE)", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, stem)


def cell_means_plot(frame: pd.DataFrame, dv: str, within: list[str], between: list[str], design: DesignInfo,
                    stem: Path) -> list[Path]:
    """Descriptive means ± SE of every cell: the within factors on x and as lines, one panel per between level
    (and per level of any further within factor), so that every report shows its data even when the paper's
    figures (which need body × motion or a chosen level) do not apply."""
    panels = " × ".join(within[2:] + between)
    title = f"Mean {dv} per cell (± SE across participants)" + (f"; panels: {panels}" if panels else "")
    return interaction_plot(frame, dv, within + between, design, stem, title=title)


def choice_bars(values: pd.DataFrame, column: str, design: DesignInfo, stem: Path, ylabel: str,
                chance: float | None = None) -> list[Path]:
    """Votes or points per alternatives level (± SE across participants)."""
    plt = _pyplot()
    alt = design.alternatives
    stats = mean_se(values, column, [alt.name]).set_index(alt.name).reindex(alt.levels)
    fig, ax = plt.subplots(figsize=(1.0 * len(alt.levels) + 2, 3.0))
    ax.bar(np.arange(len(alt.levels)), stats["mean"], yerr=stats["se"], capsize=3, color="#4c72b0",
           edgecolor="black", linewidth=0.4)
    if chance is not None:
        ax.axhline(chance, color="grey", linestyle="--", linewidth=0.8)
    ax.set_xticks(np.arange(len(alt.levels)), alt.levels, rotation=20)
    ax.set_xlabel(alt.name)
    ax.set_ylabel(ylabel)
    fig.tight_layout()
    return save_figure(fig, stem)
