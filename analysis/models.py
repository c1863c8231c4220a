"""Modern alternatives to the classic ANOVA — reported next to it, clearly labelled as additional.

- :func:`mixed_model`: linear mixed model (statsmodels ``MixedLM``) of the trial-level ratings, full
  factorial fixed effects (sum-to-zero coding), participant random intercept; Wald χ² per term;
- :func:`ordinal_model`: cumulative-logit (proportional-odds) model of the Likert ratings
  (statsmodels ``OrderedModel``), full factorial fixed effects; participants enter only through the
  factors (statsmodels has no random effects for ordinal models), so it is a fixed-effects check;
- :func:`choice_mixed`: logistic mixed model of 2AFC choices with a participant random intercept
  (statsmodels ``BinomialBayesMixedGLM``, variational Bayes; Wald tests from the mean-field posterior,
  so approximate) — the random intercept is each participant's own preference between the alternatives;
- :func:`choice_gee`: logistic GEE (exchangeable working correlation within participant, robust SEs)
  of 2AFC choices. The outcome is "chose the first alternatives level" (e.g. NoCOM): the intercept tests
  the alternatives main effect (METHOD) and each term X tests X × METHOD.

Every function returns a DataFrame with columns ``model, term, df, chi2, p, note``.
"""

from __future__ import annotations

import re
import warnings

import numpy as np
import pandas as pd

from analysis.io_design import DesignInfo

FACTOR_IN_PARAM = re.compile(r"C\((\w+), Sum\)")


def _formula_rhs(factors: list[str]) -> str:
    return " * ".join(f"C({f}, Sum)" for f in factors) if factors else "1"


def _trial_data(data: pd.DataFrame, design: DesignInfo, columns: list[str]) -> pd.DataFrame:
    """Test answers with plain object columns (statsmodels and patsy want numpy dtypes)."""
    frame = data[~data["practice"].astype(bool)]
    frame = frame[["participant", *design.between, *design.within, *columns]].copy()
    for c in ["participant", *design.between, *design.within]:
        frame[c] = frame[c].astype(str).astype(object)
    return frame.reset_index(drop=True)


def wald_terms(params: pd.Series, cov: pd.DataFrame, model: str, label=None) -> pd.DataFrame:
    """Joint Wald χ² test of all coefficients of each model term (parameters grouped by their factors)."""
    groups: dict[tuple, list[str]] = {}
    for name in params.index:
        factors = tuple(FACTOR_IN_PARAM.findall(name))
        if factors:
            groups.setdefault(factors, []).append(name)
    rows = []
    from scipy import stats
    for factors, names in groups.items():
        b = params[names].to_numpy()
        v = cov.loc[names, names].to_numpy()
        chi2 = float(b @ np.linalg.pinv(v) @ b)
        rows.append({"model": model, "term": label(factors) if label else ":".join(factors), "df": len(names),
                     "chi2": chi2, "p": float(stats.chi2.sf(chi2, len(names)))})
    return pd.DataFrame(rows)


def mixed_model(data: pd.DataFrame, design: DesignInfo) -> pd.DataFrame:
    """Linear mixed model of the ratings: full factorial fixed effects, random intercept per participant."""
    import statsmodels.formula.api as smf

    frame = _trial_data(data, design, ["rating"]).astype({"rating": float})
    factors = design.between + design.within
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # convergence chatter; convergence is reported in the note
        fit = smf.mixedlm(f"rating ~ {_formula_rhs(factors)}", frame, groups=frame["participant"]).fit(
            reml=True, method=["bfgs", "powell"])
    fe = fit.fe_params
    table = wald_terms(fe, fit.cov_params().loc[fe.index, fe.index], "linear mixed model (MixedLM, REML)")
    table["note"] = (f"random intercept SD {np.sqrt(float(fit.cov_re.iloc[0, 0])):.3f}, residual SD "
                     f"{np.sqrt(fit.scale):.3f}, converged {bool(fit.converged)}, n = {len(frame)} answers")
    return table


def ordinal_model(data: pd.DataFrame, design: DesignInfo) -> pd.DataFrame:
    """Cumulative-logit model of the Likert ratings (fixed effects only)."""
    import patsy
    from statsmodels.miscmodels.ordinal_model import OrderedModel

    frame = _trial_data(data, design, ["rating"])
    factors = design.between + design.within
    X = patsy.dmatrix(f"{_formula_rhs(factors)}", frame, return_type="dataframe").drop(columns="Intercept")
    y = pd.Series(pd.Categorical(frame["rating"].astype(int), categories=range(1, design.k + 1), ordered=True))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = OrderedModel(y, X, distr="logit").fit(method="bfgs", disp=False, maxiter=5000)
    params = fit.params[X.columns]
    cov = fit.cov_params().loc[X.columns, X.columns]
    table = wald_terms(params, cov, "ordinal (cumulative logit) model")
    table["note"] = (f"fixed effects only (no participant random effect); converged "
                     f"{bool(fit.mle_retvals.get('converged', False))}, n = {len(frame)} answers")
    return table


def _choice_frame(data: pd.DataFrame, design: DesignInfo) -> tuple[pd.DataFrame, str]:
    """Test answers with ``first`` = 1 when the first alternatives level (e.g. NoCOM) was chosen."""
    first = design.alternatives.levels[0]
    frame = _trial_data(data, design, ["chosen"])
    frame["first"] = (frame["chosen"].astype(str) == first).astype(float)
    return frame, f"first ~ {_formula_rhs(design.between + design.within)}"


def _choice_terms(params: pd.Series, cov: pd.DataFrame, model: str, design: DesignInfo) -> pd.DataFrame:
    """Wald tests of a choice model: the intercept is the alternatives main effect, term X is X × alternatives."""
    from scipy import stats
    alt = design.alternatives.name
    table = wald_terms(params, cov, model, label=lambda fs: ":".join([*fs, alt]))
    z2 = float(params["Intercept"] ** 2 / cov.loc["Intercept", "Intercept"])
    intercept = pd.DataFrame([{"model": model, "term": alt, "df": 1, "chi2": z2, "p": float(stats.chi2.sf(z2, 1))}])
    return pd.concat([intercept, table], ignore_index=True)


def choice_gee(data: pd.DataFrame, design: DesignInfo) -> pd.DataFrame:
    """Logistic GEE of 2AFC choices; terms are reported as their interaction with the alternatives factor."""
    import statsmodels.api as sm
    import statsmodels.formula.api as smf

    frame, formula = _choice_frame(data, design)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = smf.gee(formula, "participant", frame, family=sm.families.Binomial(),
                      cov_struct=sm.cov_struct.Exchangeable()).fit()
    table = _choice_terms(fit.params, fit.cov_params(), "logistic GEE (exchangeable, robust SE)", design)
    odds = float(np.exp(fit.params["Intercept"]))
    table["note"] = (f"outcome: chose {design.alternatives.levels[0]}; odds {odds:.2f} at the grand mean "
                     f"(P = {odds / (1 + odds):.3f}); n = {len(frame)} answers")
    return table


def choice_mixed(data: pd.DataFrame, design: DesignInfo) -> pd.DataFrame:
    """Logistic mixed model of 2AFC choices (participant random intercept), variational Bayes."""
    from statsmodels.genmod.bayes_mixed_glm import BinomialBayesMixedGLM

    frame, formula = _choice_frame(data, design)
    model = BinomialBayesMixedGLM.from_formula(formula, {"participant": "0 + C(participant)"}, frame)
    n = model.k_fep + model.k_vcp + model.k_vc
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # fixed start (statsmodels draws random starting SDs otherwise): same data → same numbers
        fit = model.fit_vb(mean=np.zeros(n), sd=np.full(n, np.exp(-0.5)))
    names = model.exog_names
    cov = pd.DataFrame(np.diag(np.asarray(fit.fe_sd) ** 2), index=names, columns=names)
    table = _choice_terms(pd.Series(fit.fe_mean, index=names), cov,
                          "logistic mixed model (variational Bayes, approximate)", design)
    table["note"] = (f"outcome: chose {design.alternatives.levels[0]}; participant random-intercept SD "
                     f"{float(np.exp(fit.vcp_mean[0])):.3f} (log-odds); n = {len(frame)} answers")
    return table


def additional_models(data: pd.DataFrame, design: DesignInfo) -> pd.DataFrame:
    """All additional models that fit the design's response type (empty for rankings/k-AFC votes)."""
    if design.response_type == "likert":
        return pd.concat([mixed_model(data, design), ordinal_model(data, design)], ignore_index=True)
    if design.response_type == "afc" and len(design.alternatives.levels) == 2:
        return pd.concat([choice_mixed(data, design), choice_gee(data, design)], ignore_index=True)
    return pd.DataFrame(columns=["model", "term", "df", "chi2", "p", "note"])
