"""Tukey HSD after a split-plot ANOVA, Statistica convention (DESIGN.md), with the paper's summaries.

For effect E with error mean square MSE_E and df_E (E's own error term from the ANOVA), all pairs of
E's cell means are compared; a cell mean is the observed mean over subjects (of the subject's cell
means averaged over the within factors not in E), based on n = subjects in the between group ×
number of averaged within cells. q = |m_i − m_j| / sqrt(MSE_E/2 · (1/n_i + 1/n_j)) (Tukey–Kramer;
the plain Tukey HSD when n_i = n_j), p = P(Q_{k, df_E} > q) with k = number of cells of E.

An effect whose error term has no variance (error SS 0 up to rounding: the ANOVA's F is 0/0 or ∞) is not
tested: q and p are NaN, no pair is significant and ``untestable`` says why — a q of 1e16 against an MSE of
1e-31 is a ratio of rounding noise, not evidence.

For a mixed effect (within and between factors), a pair that differs only in its between-subjects levels
(``F/L1b`` vs ``M/L1b`` of BODY:SEX) is still tested against the effect's within-subject error, as
Statistica does; that error holds no between-subject variance, so such a test is anti-conservative next to
emmeans' pooled error. ``pairs["between_only"]`` marks those pairs (numbers unchanged).

Cell labels list the between factors' levels first, then the within factors', joined by ``/``
(``F/W``, ``H1b/L2m``), abbreviated through ``abbreviations``. The summary names, for each cell in
level order, the cells it significantly exceeds: ``"L2b > H2b"``, ``"F/L1b > F/H1b, M/H2b; F/L2b > F/H1b"``.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import product

import numpy as np
import pandas as pd

from analysis.anova import AnovaTable, anova
from analysis.errors import AnalysisError
from analysis.studentized_range import studentized_range_sf

__all__ = ["PosthocResult", "tukey", "tukey_all", "cell_means", "abbreviate"]


@dataclass
class PosthocResult:
    """Tukey HSD for one effect.

    Attributes:
        effect: canonical effect name (``GAIT:SEX``).
        factors: the factors in label order (between first, then within).
        means: DataFrame indexed by cell label: one column per factor (full level names), ``mean``, ``n``.
        pairs: DataFrame, one row per pair (i < j in level order): ``a``, ``b`` (labels), ``diff``
            (mean a − mean b), ``se``, ``q``, ``p``, ``significant`` (p < alpha), ``between_only`` (the
            pair belongs to a mixed effect and differs only in between-subjects levels, yet is tested
            against the within-subject error of the effect — see the module notes).
        k, df, mse, alpha: number of means, error df and MS of the effect's error term, level.
        summary: the paper's compact string ("" when no pair differs, or when nothing was tested).
        untestable: "" when the pairs were tested, else why not (the effect's error term has no variance):
            q, p NaN, nothing significant.
    """

    effect: str
    factors: tuple[str, ...]
    means: pd.DataFrame
    pairs: pd.DataFrame
    k: int
    df: float
    mse: float
    alpha: float
    summary: str
    untestable: str = ""

    def records(self) -> list[dict]:
        """DESIGN.md's post-hoc list: ``[{a, b, diff, q, p}]`` (q and p None where nothing was tested)."""
        def num(x):
            return float(x) if np.isfinite(x) else None

        return [
            {"a": a, "b": b, "diff": float(d), "q": num(q), "p": num(p)}
            for a, b, d, q, p in self.pairs[["a", "b", "diff", "q", "p"]].itertuples(index=False)
        ]


def abbreviate(factor: str, level: str, abbreviations: dict | None) -> str:
    """Level label through ``abbreviations``: ``{level: abbr}`` or ``{factor: {level: abbr}}``."""
    if not abbreviations:
        return level
    per_factor = abbreviations.get(factor)
    if isinstance(per_factor, dict) and level in per_factor:
        return str(per_factor[level])
    v = abbreviations.get(level)
    return level if v is None or isinstance(v, dict) else str(v)


def cell_means(table: AnovaTable, effect: str) -> tuple[tuple[str, ...], list[tuple[str, ...]], np.ndarray, np.ndarray]:
    """(factors in label order, cells as level tuples, means, n) of an effect's cells, in level order."""
    name = table.effect_name(effect)
    facs = table.effects.loc[name, "factors"]
    design = table.design
    wnames, bnames = list(design.within), list(design.between)
    w_e = [f for f in wnames if f in facs]
    b_e = [f for f in bnames if f in facs]
    n = table.n_subjects
    wk = [len(design.within[f]) for f in wnames]
    y = table.Y.reshape([n] + wk) if wnames else table.Y
    other = tuple(1 + i for i, f in enumerate(wnames) if f not in w_e)
    ye = y.mean(axis=other) if other else y
    ye = ye.reshape(n, -1)  # n × K_E (C order of w_e)
    n_other = int(np.prod([wk[i - 1] for i in other])) if other else 1
    bk = [len(design.between[f]) for f in b_e]
    if b_e:
        gcode = np.ravel_multi_index(tuple(design.groups[:, bnames.index(f)] for f in b_e), bk)
        n_groups = int(np.prod(bk))
    else:
        gcode = np.zeros(n, dtype=int)
        n_groups = 1
    sums = np.zeros((n_groups, ye.shape[1]))
    np.add.at(sums, gcode, ye)
    cnt = np.bincount(gcode, minlength=n_groups).astype(float)
    means = (sums / cnt[:, None]).ravel()  # between cells slowest
    nn = np.repeat(cnt * n_other, ye.shape[1])
    levels = [design.between[f] for f in b_e] + [design.within[f] for f in w_e]
    cells = list(product(*levels))
    return tuple(b_e + w_e), cells, means, nn


def tukey(
    table_or_data: AnovaTable | pd.DataFrame,
    effect: str,
    abbreviations: dict | None = None,
    alpha: float | None = None,
    sep: str = "/",
    **anova_kwargs,
) -> PosthocResult:
    """Tukey HSD for ``effect`` (any factor order; main, interaction, within, between or mixed).

    ``table_or_data`` is an :class:`AnovaTable`, or long data together with ``anova``'s keyword
    arguments (``dv=, subject=, within=, between=``). The result is also stored in
    ``table.posthoc[effect]`` when a table is given, so that tables and JSON include it.
    """
    if isinstance(table_or_data, pd.DataFrame):
        table = anova(table_or_data, **anova_kwargs)
    elif isinstance(table_or_data, AnovaTable):
        table = table_or_data
    else:
        raise AnalysisError(f"tukey() needs an AnovaTable or a DataFrame, got {type(table_or_data).__name__}")
    name = table.effect_name(effect)
    a = table.alpha if alpha is None else float(alpha)
    row = table.effects.loc[name]
    mse, df = float(row["mse"]), float(row["df2"])
    facs, cells, means, nn = cell_means(table, name)
    labels = [sep.join(abbreviate(f, lv, abbreviations) for f, lv in zip(facs, c)) for c in cells]
    if len(set(labels)) != len(labels):
        raise AnalysisError(f"abbreviations make two cells of {name} look the same; give distinct abbreviations")
    k = len(cells)
    i, j = np.triu_indices(k, 1)
    diff = means[i] - means[j]
    se = np.sqrt(mse / 2.0 * (1.0 / nn[i] + 1.0 / nn[j]))
    untestable = ""
    if not np.isfinite(float(row["F"])):   # the engine's verdict: error SS 0 up to rounding (F = 0/0 or ∞)
        untestable = (f"the error term {row['error']} has no variance (SS 0 up to rounding), so no pair of "
                      f"{name} can be tested against it")
        q = p = np.full(len(i), np.nan)
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            q = np.abs(diff) / se
        p = studentized_range_sf(np.nan_to_num(q, nan=0.0, posinf=1e300), k, df)
    n_between = sum(f in table.design.between for f in facs)   # between factors come first in a label
    mixed = 0 < n_between < len(facs)
    cell_arr = np.array(cells, dtype=object).reshape(k, len(facs))
    between_only = (np.all(cell_arr[i, n_between:] == cell_arr[j, n_between:], axis=1) if mixed
                    else np.zeros(len(i), dtype=bool))
    pairs = pd.DataFrame({
        "a": [labels[x] for x in i], "b": [labels[x] for x in j], "diff": diff, "se": se, "q": q, "p": p,
        "significant": p < a, "between_only": between_only.astype(bool),
    })
    mdf = pd.DataFrame([dict(zip(facs, c)) for c in cells], index=pd.Index(labels, name="cell"))
    mdf["mean"] = means
    mdf["n"] = nn
    result = PosthocResult(
        effect=name, factors=facs, means=mdf, pairs=pairs, k=k, df=df, mse=mse, alpha=a,
        summary=summarize(labels, means, i, j, p, a), untestable=untestable,
    )
    table.posthoc[name] = result
    return result


def summarize(labels, means, i, j, p, alpha: float) -> str:
    """``"A > B, C; D > B"``: for each cell in level order, the cells it significantly exceeds."""
    k = len(labels)
    beats = [[] for _ in range(k)]
    for a, b, pv in zip(i, j, p):
        if pv < alpha:
            hi, lo = (a, b) if means[a] > means[b] else (b, a)
            beats[hi].append(lo)
    parts = [f"{labels[h]} > {', '.join(labels[x] for x in sorted(lows))}" for h, lows in enumerate(beats) if lows]
    return "; ".join(parts)


def tukey_all(
    table: AnovaTable,
    effects: list[str] | None = None,
    abbreviations: dict | None = None,
    alpha: float | None = None,
    correction: str = "none",
) -> dict[str, PosthocResult]:
    """Tukey HSD for several effects (default: the significant ones at ``alpha``); stored in ``table.posthoc``."""
    names = table.significant(alpha, correction) if effects is None else [table.effect_name(e) for e in effects]
    return {e: tukey(table, e, abbreviations=abbreviations, alpha=alpha) for e in names}
