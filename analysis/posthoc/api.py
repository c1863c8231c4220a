"""Post-hoc pairwise comparisons of an ANOVA effect: :func:`posthoc`, :func:`tukey`, :func:`tukey_all`.

    res = posthoc(table, "BODY:SEX")                                   # univariate, Tukey, emmeans means
    res = posthoc(table, "BODY:SEX", followup="multivariate", adjust="holm")
    res = tukey(table, "BODY:SEX", followup="statistica")              # the paper's tables
    res.summary            # "F/L1b > F/H1b, M/H2b; …" from the chosen follow-up's adjusted p
    res.pairs              # a, b, kind, diff, se, df, t, q, p_unadjusted, p, lower, upper, effect_size, …

See :mod:`analysis.posthoc.pairs` for the follow-ups, :mod:`analysis.posthoc.adjust` for the adjustments and
:mod:`analysis.posthoc.means` for the two kinds of marginal means.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from analysis.anova import AnovaTable, anova
from analysis.errors import AnalysisError
from analysis.posthoc.adjust import adjust_p, check_adjust, critical_value
from analysis.posthoc.pairs import check_followup, effect_sizes, plan_pairs
from analysis.posthoc.summary import cell_labels, summarize

ADJUST_NAMES = {"tukey": "Tukey", "holm": "Holm", "bonferroni": "Bonferroni", "none": "unadjusted"}
MULTIVARIATE_TUKEY_NOTE = ("Tukey on the multivariate model gives each pair its own variance estimate, which the "
                           "studentized range does not allow for: liberal for larger repeated-measures families "
                           "(FWER ~.08 for 12 within cells, benchmarks/posthoc_fwer.py); holm or bonferroni keep it")
STATISTICA_NOTE = ("statistica convention: pairs that differ in a between-subjects factor are tested against the "
                   "effect's within-subject error, so they are not protected (anti-conservative)")


@dataclass
class PosthocResult:
    """All pairwise comparisons of one effect's cells.

    Attributes:
        effect: canonical effect name (``GAIT:SEX``).
        factors: the factors in label order (between first, then within).
        means: DataFrame indexed by cell label: one column per factor (full level names), ``mean``, ``n``
            (subject-level values averaged: subjects of the matching groups × within cells averaged over).
        pairs: DataFrame, one row per pair (i < j in level order): ``a``, ``b`` (labels), ``kind`` (within /
            between / mixed), ``diff`` (mean a − mean b), ``se`` (of the difference), ``df``, ``t``,
            ``q`` (= √2·|t|, the studentized range statistic), ``p_unadjusted``, ``p`` (adjusted), ``lower``,
            ``upper`` (confidence limits of the difference at ``1 − alpha``, with the same adjustment; Holm's
            are Bonferroni's), ``effect_size`` and ``effect_size_type`` (``d_z`` for within pairs, Hedges'
            ``g`` otherwise: :func:`analysis.posthoc.pairs.effect_sizes`), ``significant`` (p < alpha).
        k, df, mse: number of means; df2 and MSE of the effect's own error term (the ANOVA's).
        alpha: the level of ``significant`` and of the summary (confidence level 1 − alpha).
        summary: the paper's compact string ("" when no pair differs, or when nothing was tested).
        untestable: "" when the pairs were tested, else why not (the effect's error term has no variance):
            t, q, p, limits NaN, nothing significant.
        followup, adjust, means_type: how the pairs were tested (``univariate``/``multivariate``/
            ``statistica``; ``tukey``/``holm``/``bonferroni``/``none``; ``emmeans``/``observed``).
        mixed: the effect has both between and within factors.
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
    followup: str = "univariate"
    adjust: str = "tukey"
    means_type: str = "emmeans"

    mixed: bool = False

    @property
    def unprotected(self) -> bool:
        """True where the statistica convention tested pairs across between groups against a within error."""
        return self.followup == "statistica" and self.mixed

    @property
    def label(self) -> str:
        """Short: ``"Tukey, univariate, emmeans means"`` (table headers)."""
        return f"{ADJUST_NAMES[self.adjust]}, {self.followup}, {self.means_type} means"

    @property
    def method(self) -> str:
        """``"Tukey, univariate follow-up, emmeans means"`` (with the statistica warning where it applies)."""
        text = f"{ADJUST_NAMES[self.adjust]}, {self.followup} follow-up, {self.means_type} means"
        if self.followup == "multivariate" and self.adjust == "tukey" and self.k > 2:
            text += f"; {MULTIVARIATE_TUKEY_NOTE}"
        return text + (f"; {STATISTICA_NOTE}" if self.unprotected else "")

    def records(self) -> list[dict]:
        """The JSON list of pairs (DESIGN.md's ``{a, b, diff, q, p}`` extended): kind, se, df, t,
        p_unadjusted, lower, upper, effect_size, effect_size_type, and how they were tested (followup,
        adjust, means); numbers None where nothing was tested."""
        def num(x):
            return float(x) if np.isfinite(x) else None

        cols = ["a", "b", "kind", "diff", "se", "df", "t", "q", "p_unadjusted", "p", "lower", "upper",
                "effect_size", "effect_size_type"]
        how = {"followup": self.followup, "adjust": self.adjust, "means": self.means_type}
        return [{**{c: (num(v) if isinstance(v, (float, np.floating)) else v) for c, v in zip(cols, row)}, **how}
                for row in self.pairs[cols].itertuples(index=False)]


def _table(table_or_data, anova_kwargs) -> AnovaTable:
    if isinstance(table_or_data, pd.DataFrame):
        return anova(table_or_data, **anova_kwargs)
    if isinstance(table_or_data, AnovaTable):
        return table_or_data
    raise AnalysisError(f"posthoc() needs an AnovaTable or a DataFrame, got {type(table_or_data).__name__}")


def default_means(followup: str) -> str:
    """Observed means for the statistica convention (the paper's tables), emmeans' otherwise."""
    return "observed" if followup == "statistica" else "emmeans"


def posthoc(
    table_or_data: AnovaTable | pd.DataFrame,
    effect: str,
    followup: str = "univariate",
    adjust: str = "tukey",
    means: str | None = None,
    abbreviations: dict | None = None,
    alpha: float | None = None,
    sep: str = "/",
    **anova_kwargs,
) -> PosthocResult:
    """All pairwise comparisons of ``effect``'s cells (any factor order; main, interaction, within, between or
    mixed). ``table_or_data`` is an :class:`AnovaTable`, or long data with ``anova``'s keyword arguments.
    ``means``: ``"emmeans"`` (equal weights over groups) or ``"observed"``; None = observed for the
    statistica follow-up, emmeans otherwise. The result is also stored in ``table.posthoc[effect]``.

    >>> rng = np.random.default_rng(1)
    >>> data = pd.DataFrame([(s, "F" if s < 5 else "M", c, rng.normal() + (c == "b") * 2)
    ...                      for s in range(12) for c in "abc"], columns=["id", "SEX", "C", "y"])
    >>> res = posthoc(data, "C", dv="y", subject="id", within=["C"], between=["SEX"])
    >>> res.summary, res.method
    ('b > a, c', 'Tukey, univariate follow-up, emmeans means')
    """
    table = _table(table_or_data, anova_kwargs)
    followup = check_followup(followup)
    adjust = check_adjust(adjust)
    means = default_means(followup) if means is None else str(means).lower()   # checked by effect_cells
    name = table.effect_name(effect)
    a = table.alpha if alpha is None else float(alpha)
    row = table.effects.loc[name]
    plan = plan_pairs(table.design, row["factors"], followup, means)
    cells = plan.cells
    labels = cell_labels(cells.factors, cells.cells, abbreviations, sep, name)
    ev = plan.evaluate(table.Y)
    diff, se, df = ev["diff"], ev["se"], np.asarray(ev["df"], dtype=float)
    untestable = ""
    if not np.isfinite(float(row["F"])):   # the engine's verdict: error SS 0 up to rounding (F = 0/0 or ∞)
        untestable = (f"the error term {row['error']} has no variance (SS 0 up to rounding), so no pair of "
                      f"{name} can be tested against it")
        t = np.full(len(diff), np.nan)
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(se > 0, diff / se, np.nan)
    p_raw, p = adjust_p(t, df, adjust, plan.k)
    half = critical_value(np.where(np.isfinite(t), df, np.nan), adjust, plan.k, 1.0 - a) * se
    size, size_type = effect_sizes(plan, diff, ev["cov"])
    pairs = pd.DataFrame({
        "a": [labels[x] for x in plan.i], "b": [labels[x] for x in plan.j], "kind": plan.kind,
        "diff": diff, "se": se, "df": df, "t": t, "q": np.sqrt(2.0) * np.abs(t), "p_unadjusted": p_raw, "p": p,
        "lower": diff - half, "upper": diff + half, "effect_size": size, "effect_size_type": size_type,
        "significant": p < a,
    })
    mdf = pd.DataFrame([dict(zip(cells.factors, c)) for c in cells.cells], index=pd.Index(labels, name="cell"))
    mdf["mean"] = ev["means"]
    mdf["n"] = cells.n
    result = PosthocResult(
        effect=name, factors=cells.factors, means=mdf, pairs=pairs, k=plan.k, df=float(row["df2"]),
        mse=float(row["mse"]), alpha=a, summary=summarize(labels, ev["means"], plan.i, plan.j, p, a),
        untestable=untestable, followup=followup, adjust=adjust, means_type=means,
        mixed=0 < cells.n_between < len(cells.factors),
    )
    table.posthoc[name] = result
    return result


def tukey(table_or_data: AnovaTable | pd.DataFrame, effect: str, abbreviations: dict | None = None,
          alpha: float | None = None, sep: str = "/", followup: str = "univariate", means: str | None = None,
          **anova_kwargs) -> PosthocResult:
    """Tukey-adjusted pairwise comparisons: :func:`posthoc` with ``adjust="tukey"``."""
    return posthoc(table_or_data, effect, followup=followup, adjust="tukey", means=means,
                   abbreviations=abbreviations, alpha=alpha, sep=sep, **anova_kwargs)


def tukey_all(
    table: AnovaTable,
    effects: list[str] | None = None,
    abbreviations: dict | None = None,
    alpha: float | None = None,
    correction: str = "none",
    followup: str = "univariate",
    adjust: str = "tukey",
    means: str | None = None,
) -> dict[str, PosthocResult]:
    """:func:`posthoc` for several effects (default: the significant ones at ``alpha`` after ``correction``);
    stored in ``table.posthoc``. ``adjust`` defaults to Tukey (hence the name)."""
    names = table.significant(alpha, correction) if effects is None else [table.effect_name(e) for e in effects]
    return {e: posthoc(table, e, followup=followup, adjust=adjust, means=means, abbreviations=abbreviations,
                       alpha=alpha) for e in names}
