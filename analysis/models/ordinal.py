"""Cumulative link mixed model of Likert ratings, as R's ``ordinal::clmm``.

``clmm(ordered(rating) ~ A * B * … + (1 | participant), link = "logit", threshold = "flexible",
contrasts = contr.sum, nAGQ = 1)``: ``logit P(Y ≤ j) = θ_j − x'β − b_i``, ``b_i ~ N(0, τ²)``, estimated by
Laplace's approximation (``n_agq = 1``, clmm's default) or adaptive Gauss–Hermite (``n_agq > 1``). Categories
nobody used are left out, as R's factor of the observed ratings does. Each term is tested by its joint Wald χ²
from the covariance of the estimates (the inverse Hessian, as ``vcov(fit)``).

>>> import numpy as np, pandas as pd
>>> rng = np.random.default_rng(3)
>>> frame = pd.DataFrame({"participant": np.repeat(np.arange(8), 12).astype(str),
...                       "A": np.tile(["a1", "a2"], 48)})
>>> latent = np.where(frame["A"] == "a2", 1.0, 0.0) + rng.normal(size=8)[np.repeat(np.arange(8), 12)]
>>> frame["rating"] = np.digitize(latent + rng.logistic(size=96), [-1, 0, 1, 2]) + 1
>>> fit = clmm(frame, "rating", ["A"])
>>> fit.tests["term"].tolist(), fit.tests["df"].tolist()
(['A'], [1])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from analysis.io_design import DesignInfo
from analysis.models.common import (MODEL_NAMES, MixedFit, ModelNotComputed, check_covariance, design_matrix,
                                    extreme_cells, separation_reason, trial_data, wald_terms)
from analysis.models.random_intercept import CumulativeLogit, fit_random_intercept


@dataclass
class ClmmFit(MixedFit):
    """A :class:`MixedFit` (β without intercept) with the observed categories and the thresholds θ (one per
    boundary between them) and their standard errors."""
    categories: list
    thresholds: np.ndarray
    threshold_se: np.ndarray


def clmm(frame: pd.DataFrame, response: str, factors: list[str], participant: str = "participant",
         n_agq: int = 1, model: str = MODEL_NAMES["ordinal_model"]) -> ClmmFit:
    """Fit the cumulative link mixed model of ``frame[response]`` (integer ratings) on the full factorial of
    ``factors`` with a random intercept per ``participant``."""
    ratings = frame[response].astype(int).to_numpy()
    categories = sorted(set(ratings.tolist()))
    if len(categories) < 2:
        raise ModelNotComputed(f"every answer is {categories[0]}: a cumulative link model needs two categories")
    cells = extreme_cells(frame, factors, response, categories[0], categories[-1])
    if cells:
        raise ModelNotComputed(separation_reason(cells, "lowest or highest category"))
    y = np.searchsorted(categories, ratings) + 1
    X, terms = design_matrix(frame, factors)
    family = CumulativeLogit(X[:, 1:], y, len(categories))
    fit = fit_random_intercept(family, frame[participant].to_numpy(), n_agq)
    k = len(categories) - 1
    cov = fit.cov[:-1, :-1]
    check_covariance(cov)
    beta_terms = {term: slice(s.start - 1 + k, s.stop - 1 + k) for term, s in terms.items()}
    tests = wald_terms(fit.params, cov, beta_terms, model)
    se = np.sqrt(np.diag(cov))
    return ClmmFit(beta=fit.params[k:], beta_se=se[k:], tau=fit.tau, loglik=fit.loglik, converged=fit.converged,
                   tests=tests, categories=categories, thresholds=fit.params[:k], threshold_se=se[:k])


def ordinal_model(data: pd.DataFrame, design: DesignInfo, n_agq: int = 1) -> pd.DataFrame:
    """The report's ordinal model: :func:`clmm` of the test ratings, one Wald χ² row per term."""
    frame = trial_data(data, design, ["rating"])
    fit = clmm(frame, "rating", design.between + design.within, n_agq=n_agq)
    unused = sorted(set(range(1, design.k + 1)) - set(fit.categories))
    method = "Laplace" if n_agq == 1 else f"adaptive Gauss-Hermite, {n_agq} nodes"
    table = fit.tests
    table["note"] = (f"Wald χ² per term (type III, sum-to-zero contrasts); participant random-intercept SD "
                     f"{fit.tau:.3f} (logit scale); thresholds {', '.join(f'{t:.3f}' for t in fit.thresholds)}; "
                     f"{method}; converged {fit.converged}; n = {len(frame)} answers"
                     + (f"; categories never used: {', '.join(map(str, unused))}" if unused else ""))
    return table
