"""Family-wise error of the post-hoc follow-ups under the null, by simulation.

Null data sets of a split-plot design (a random intercept per subject plus independent noise, optionally
with unequal variances across within cells, so that sphericity fails) go through
:meth:`analysis.posthoc.pairs.PairPlan.evaluate` all at once; for every effect × follow-up × adjustment,
the FWER of a family is the share of data sets in which at least one of its pairs has an adjusted
p < alpha. Families: the pairs of each kind (``within``, ``between``, ``mixed``) and ``all`` pairs of the
effect. Each rate comes with its Clopper–Pearson interval; ``per_pair_rate`` is the share of single pairs
found (the per-comparison error, which is all that ``adjust="none"`` controls).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from analysis.anova_core import Design
from analysis.posthoc.adjust import ADJUSTMENTS, adjust_p
from analysis.posthoc.api import default_means
from analysis.posthoc.pairs import FOLLOWUPS, plan_pairs
from analysis.power import clopper_pearson


def null_data(design: Design, n_sims: int, seed: int = 0, subject_sd: float = 1.0,
              cell_sd: np.ndarray | float = 1.0) -> np.ndarray:
    """``n_sims`` null data sets (n_sims × subjects × cells): subject intercept + noise with SD ``cell_sd``
    (one number, or one per within cell)."""
    rng = np.random.default_rng(seed)
    n, K = design.n_subjects, design.n_cells
    return (rng.normal(0.0, subject_sd, (n_sims, n, 1))
            + rng.normal(0.0, 1.0, (n_sims, n, K)) * np.broadcast_to(np.asarray(cell_sd, dtype=float), (K,)))


def null_fwer(design: Design, effects: list[list[str]], Y: np.ndarray, followups=FOLLOWUPS,
              adjustments=ADJUSTMENTS, alpha: float = 0.05, means: str | None = None) -> pd.DataFrame:
    """FWER per effect × follow-up × adjustment × family for the null data sets ``Y`` (see module notes).

    >>> d = Design.make(within={"A": 3}, between={"G": 2}, n_per_group=[4, 6])
    >>> out = null_fwer(d, [["A", "G"]], null_data(d, 200, seed=1), followups=["univariate"], adjustments=["tukey"])
    >>> sorted(out["family"]), bool((out["fwer"] < 0.15).all())
    (['all', 'between', 'mixed', 'within'], True)
    """
    rows = []
    n_sims = Y.shape[0]
    for factors in effects:
        for followup in followups:
            plan = plan_pairs(design, factors, followup, means or default_means(followup))
            ev = plan.evaluate(Y)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = ev["diff"] / ev["se"]
            df = np.broadcast_to(ev["df"], t.shape)
            for adjust in adjustments:
                _, p = adjust_p(t, df, adjust, plan.k)
                sig = p < alpha
                for family in ("within", "between", "mixed", "all"):
                    cols = np.ones(len(plan.kind), bool) if family == "all" else plan.kind == family
                    if not cols.any():
                        continue
                    hits = int(sig[:, cols].any(axis=1).sum())
                    lo, hi = clopper_pearson(hits, n_sims)
                    rows.append({"effect": ":".join(factors), "followup": followup, "adjust": adjust,
                                 "family": family, "pairs": int(cols.sum()), "rejections": hits, "sims": n_sims,
                                 "fwer": hits / n_sims, "ci_low": lo, "ci_high": hi,
                                 "per_pair_rate": float(sig[:, cols].mean())})
    return pd.DataFrame(rows)
