"""All pairwise comparisons of an effect's cells under one follow-up model, for one or many data sets.

:func:`plan_pairs` compiles what does not depend on the data (cell weights, pair contrasts, how each pair
projects on the error strata); :meth:`PairPlan.evaluate` then gives differences, SEs and df for a stack of
data sets at once (the FWER benchmark runs 1,000 of them in one call).

Follow-ups (``followup``):

* ``"univariate"`` — emmeans on afex's ``aov`` (``model = "univariate"``): each pair's variance from the
  error strata it touches, Satterthwaite df (:mod:`analysis.posthoc.univariate`).
* ``"multivariate"`` — emmeans on afex's ``mlm`` (``model = "multivariate"``, afex's default): unstructured
  covariance, df = n − groups (:mod:`analysis.posthoc.multivariate`).
* ``"statistica"`` — every pair against the effect's own error term and df (the paper's tables); pairs
  of a mixed effect that differ in a between factor are not protected under this rule.

Pair kinds: ``within`` (same between levels: a repeated-measures comparison), ``between`` (same within
levels, different between levels) and ``mixed`` (both differ).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis.anova_core import Design
from analysis.errors import AnalysisError
from analysis.posthoc.means import EffectCells, effect_cells, group_codes, group_means, pooled_covariance
from analysis.posthoc.multivariate import multivariate_se, multivariate_weights
from analysis.posthoc.univariate import stratum_mse, stratum_weights, statistica_se_df, univariate_se_df

FOLLOWUPS = ("univariate", "multivariate", "statistica")


def check_followup(followup: str) -> str:
    followup = str(followup).lower()
    if followup not in FOLLOWUPS:
        raise AnalysisError(f"unknown post-hoc follow-up {followup!r}; use one of {', '.join(FOLLOWUPS)}")
    return followup


@dataclass(frozen=True)
class PairPlan:
    """The data-free part of an effect's pairwise comparisons (see :func:`plan_pairs`).

    Attributes:
        cells: the effect's :class:`EffectCells`.
        followup: ``univariate``, ``multivariate`` or ``statistica``.
        i, j: cell indices of each pair (i < j, level order).
        kind: per pair ``within``, ``between`` or ``mixed``.
        weights: per pair, ``a[p, S]`` (univariate, statistica) or ``B[p]`` (multivariate).
        code, n_g: between group of every subject; subjects per group.
        wk: levels per within factor; stratum: the effect's own stratum (bit mask of its within factors).
        df_error: n − groups; df_strata: ``d_S · df_error`` per stratum.
    """

    cells: EffectCells
    followup: str
    i: np.ndarray
    j: np.ndarray
    kind: np.ndarray
    weights: np.ndarray
    code: np.ndarray
    n_g: np.ndarray
    wk: tuple[int, ...]
    stratum: int
    df_error: int
    df_strata: np.ndarray

    @property
    def k(self) -> int:
        return len(self.cells.cells)

    def evaluate(self, Y: np.ndarray) -> dict[str, np.ndarray]:
        """Means (…, k), and per pair diff (mean_i − mean_j), se and df (…, pairs); ``cov`` the pooled
        covariance (…, cells, cells). ``Y``: subjects × cells, or data sets × subjects × cells."""
        Y = np.asarray(Y, dtype=float)
        M = group_means(Y, self.code, self.n_g)
        W = self.cells.weights
        means = M.reshape(M.shape[:-2] + (-1,)) @ W.reshape(len(W), -1).T
        diff = means[..., self.i] - means[..., self.j]
        cov = pooled_covariance(Y, self.code, self.n_g)
        if self.followup == "multivariate":
            se = multivariate_se(self.weights, cov)
            df = np.broadcast_to(float(self.df_error), se.shape)
        else:
            mse = stratum_mse(cov, self.wk)
            if self.followup == "univariate":
                se, df = univariate_se_df(self.weights, mse, self.df_strata)
            else:
                se, df = statistica_se_df(self.weights, mse, self.stratum, self.df_strata)
        return {"means": means, "diff": diff, "se": se, "df": df, "cov": cov}


def plan_pairs(design: Design, factors, followup: str = "univariate", means: str = "emmeans") -> PairPlan:
    """Compile the pairwise comparisons of the effect made of ``factors`` under ``followup``.

    >>> d = Design.make(within={"A": 3}, between={"G": 2}, n_per_group=[4, 6])
    >>> plan = plan_pairs(d, ["A", "G"])
    >>> plan.k, len(plan.i), sorted(set(plan.kind))
    (6, 15, ['between', 'mixed', 'within'])
    """
    followup = check_followup(followup)
    cells = effect_cells(design, factors, means)
    k = len(cells.cells)
    i, j = np.triu_indices(k, 1)
    arr = np.array(cells.cells, dtype=object).reshape(k, len(cells.factors))
    nb = cells.n_between
    same_b = np.all(arr[i, :nb] == arr[j, :nb], axis=1)
    same_w = np.all(arr[i, nb:] == arr[j, nb:], axis=1)
    kind = np.where(same_b, "within", np.where(same_w, "between", "mixed")).astype(object)
    code, n_g = group_codes(design)
    wnames = list(design.within)
    wk = tuple(len(design.within[f]) for f in wnames)
    L = cells.weights[i] - cells.weights[j]
    weights = multivariate_weights(L, n_g) if followup == "multivariate" else stratum_weights(L, n_g, wk)
    stratum = sum(1 << wnames.index(f) for f in cells.factors[nb:])
    df_error = design.n_subjects - len(n_g)
    d = np.array([int(np.prod([k_ - 1 for b, k_ in enumerate(wk) if s >> b & 1])) for s in range(1 << len(wk))])
    return PairPlan(cells=cells, followup=followup, i=i, j=j, kind=kind, weights=weights, code=code, n_g=n_g,
                    wk=wk, stratum=stratum, df_error=df_error, df_strata=(d * df_error).astype(float))


def effect_sizes(plan: PairPlan, diff: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(effect size, its type) of every pair of one data set; ``cov`` the pooled within-group covariance Σ.

    * within pairs: ``d_z = diff / sqrt(δ' Σ δ)``, δ = the difference of the two cells' within weights — the
      mean difference over the (pooled within-group) SD of the subjects' difference scores;
    * between and mixed pairs: Hedges' ``g = J · diff / sqrt((ω_a' Σ ω_a + ω_b' Σ ω_b) / 2)``, ω = a cell's
      within weights (so ω' Σ ω is the pooled within-group variance of the subjects' scores for that cell;
      for a between pair both are the same score), J = 1 − 3 / (4·df − 1), df = n − groups.
    """
    w = plan.cells.within_weights
    var_cell = ((w @ cov) * w).sum(axis=1)
    delta = w[plan.i] - w[plan.j]
    var_diff = ((delta @ cov) * delta).sum(axis=1)
    j_corr = 1.0 - 3.0 / (4.0 * plan.df_error - 1.0)
    within = plan.kind == "within"
    with np.errstate(divide="ignore", invalid="ignore"):
        dz = diff / np.sqrt(var_diff)
        g = j_corr * diff / np.sqrt((var_cell[plan.i] + var_cell[plan.j]) / 2.0)
    return np.where(within, dz, g), np.where(within, "d_z", "g").astype(object)
