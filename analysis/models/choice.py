"""Models of 2AFC choices: logistic mixed model (as ``lme4::glmer``) and logistic GEE.

The outcome is "chose the first alternatives level" (e.g. NoCOM): the intercept tests the alternatives main
effect (METHOD) and each term X tests X × METHOD.

- :func:`glmer_binomial`: ``glmer(first ~ A * B * … + (1 | participant), family = binomial, nAGQ = 1)`` with
  sum-to-zero contrasts, by Laplace's approximation; each term's Wald χ² uses the covariance lme4's
  ``vcov(fit)`` gives by default — the fixed-effects block of the inverse Hessian of the deviance in (θ, β)
  (``use.hessian = TRUE``), so it allows for the uncertainty of the random-intercept SD. That is
  ``car::Anova(fit, type = 3)``.
- :func:`choice_gee`: logistic GEE (statsmodels; exchangeable working correlation within participant,
  robust SEs).

>>> import numpy as np, pandas as pd
>>> rng = np.random.default_rng(5)
>>> frame = pd.DataFrame({"participant": np.repeat(np.arange(10), 8).astype(str),
...                       "A": np.tile(["a1", "a2"], 40)})
>>> frame["first"] = (rng.random(80) < np.where(frame["A"] == "a1", 0.3, 0.7)).astype(float)
>>> fit = glmer_binomial(frame, "first", ["A"])
>>> fit.tests["term"].tolist()
['(Intercept)', 'A']
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd

from analysis.io_design import DesignInfo
from analysis.models.common import (MODEL_NAMES, MixedFit, ModelNotComputed, check_covariance, design_matrix,
                                    extreme_cells, separation_reason, trial_data, wald_terms)
from analysis.models.random_intercept import BernoulliLogit, fit_random_intercept


def glmer_binomial(frame: pd.DataFrame, response: str, factors: list[str], participant: str = "participant",
                   model: str = MODEL_NAMES["choice_mixed"]) -> MixedFit:
    """Fit the logistic mixed model of the 0/1 ``frame[response]``; see the module docstring. β starts with the
    intercept, τ is lme4's θ, the tests start with ``(Intercept)``."""
    y = frame[response].astype(float).to_numpy()
    if y.min() == y.max():
        raise ModelNotComputed(f"every answer is {y[0]:g}: there is nothing to model")
    cells = extreme_cells(frame, factors, response, 0.0, 1.0)
    if cells:
        raise ModelNotComputed(separation_reason(cells, "same alternative"))
    X, terms = design_matrix(frame, factors)
    fit = fit_random_intercept(BernoulliLogit(X, y), frame[participant].to_numpy())
    cov = fit.cov[:-1, :-1]
    check_covariance(cov)
    tests = wald_terms(fit.params, cov, {"(Intercept)": slice(0, 1), **terms}, model)
    return MixedFit(fit.params, np.sqrt(np.diag(cov)), fit.tau, fit.loglik, fit.converged, tests)


def _choice_frame(data: pd.DataFrame, design: DesignInfo) -> pd.DataFrame:
    """Test answers with ``first`` = 1 when the first alternatives level (e.g. NoCOM) was chosen."""
    frame = trial_data(data, design, ["chosen"])
    frame["first"] = (frame["chosen"].astype(str) == design.alternatives.levels[0]).astype(float)
    return frame


def _label_with_alternatives(tests: pd.DataFrame, design: DesignInfo) -> pd.DataFrame:
    """Intercept → the alternatives factor, term X → X:alternatives (what each one tests)."""
    alt = design.alternatives.name
    tests["term"] = [alt if t == "(Intercept)" else f"{t}:{alt}" for t in tests["term"]]
    return tests


def choice_mixed(data: pd.DataFrame, design: DesignInfo) -> pd.DataFrame:
    """The report's logistic mixed model of 2AFC choices."""
    frame = _choice_frame(data, design)
    fit = glmer_binomial(frame, "first", design.between + design.within)
    table = _label_with_alternatives(fit.tests, design)
    table["note"] = (f"Wald χ² per term from vcov (type III, as car::Anova); outcome: chose "
                     f"{design.alternatives.levels[0]}; participant random-intercept SD {fit.tau:.3f} (log-odds); "
                     f"Laplace; converged {fit.converged}; n = {len(frame)} answers")
    return table


def _robust_covariance(fit) -> np.ndarray:
    """The GEE's robust covariance, or :class:`ModelNotComputed` when there is none."""
    try:
        cov = np.asarray(fit.cov_params())
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise ModelNotComputed(f"the fit has no covariance matrix of its estimates ({exc}), so there are no "
                               f"standard errors for Wald tests") from None
    # A covariance matrix has no negative eigenvalue. Under separation (a cell whose answers all go one
    # way) the robust sandwich of a GEE can have large ones, and its Wald χ² come out negative (p = 1).
    check_covariance(cov)
    return cov


def choice_gee(data: pd.DataFrame, design: DesignInfo) -> pd.DataFrame:
    """Logistic GEE of 2AFC choices; terms are reported as their interaction with the alternatives factor."""
    import statsmodels.api as sm

    frame = _choice_frame(data, design)
    X, terms = design_matrix(frame, design.between + design.within)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = sm.GEE(frame["first"].to_numpy(), X, groups=frame["participant"].to_numpy(),
                     family=sm.families.Binomial(), cov_struct=sm.cov_struct.Exchangeable()).fit()
    params = np.asarray(fit.params)
    tests = wald_terms(params, _robust_covariance(fit), {"(Intercept)": slice(0, 1), **terms},
                       MODEL_NAMES["choice_gee"])
    table = _label_with_alternatives(tests, design)
    odds = float(np.exp(params[0]))
    table["note"] = (f"outcome: chose {design.alternatives.levels[0]}; odds {odds:.2f} at the grand mean "
                     f"(P = {odds / (1 + odds):.3f}); n = {len(frame)} answers")
    return table

