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

Every function returns a DataFrame with columns ``model, term, df, chi2, p, note``. A model that cannot be
estimated from the data (e.g. ratings perfectly separated by the factors, so the information matrix has no
inverse and there are no standard errors) is not an error: :func:`additional_models` gives it one row with
term ``not computed``, empty df/chi2/p and the reason in ``note`` (``not computed: …``), so the report is still
written and says why — as the ANOVA section does when the measure has no variance.
"""

from __future__ import annotations

import re
import warnings

import numpy as np
import pandas as pd

from analysis.io_design import DesignInfo

FACTOR_IN_PARAM = re.compile(r"C\((\w+), Sum\)")
NOT_COMPUTED = "not computed"
MODEL_NAMES = {"mixed_model": "linear mixed model (MixedLM, REML)",
               "ordinal_model": "ordinal (cumulative logit) model",
               "choice_mixed": "logistic mixed model (variational Bayes, approximate)",
               "choice_gee": "logistic GEE (exchangeable, robust SE)"}


class ModelNotComputed(ValueError):
    """The data do not allow the model to be estimated; the message says why (shown in the report)."""


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
    spread = float(frame["rating"].var()) if len(frame) > 1 else 0.0
    if not np.isfinite(fit.scale) or fit.scale <= 1e-10 * max(spread, 1e-300):
        raise ModelNotComputed(f"the residual variance is {fit.scale:.3g}: the factors and participants account for "
                               f"every rating exactly, so the Wald tests would divide by a zero standard error")
    fe = fit.fe_params
    table = wald_terms(fe, _covariance(fit, fe.index), MODEL_NAMES["mixed_model"])
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
    cov = _covariance(fit, X.columns)
    table = wald_terms(params, cov, MODEL_NAMES["ordinal_model"])
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
    table = _choice_terms(fit.params, _covariance(fit, fit.params.index), MODEL_NAMES["choice_gee"], design)
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
                          MODEL_NAMES["choice_mixed"], design)
    table["note"] = (f"outcome: chose {design.alternatives.levels[0]}; participant random-intercept SD "
                     f"{float(np.exp(fit.vcp_mean[0])):.3f} (log-odds); n = {len(frame)} answers")
    return table


def _covariance(fit, names) -> pd.DataFrame:
    """The estimates' covariance, or :class:`ModelNotComputed` when the fit has none (a singular information
    matrix: the factors separate the responses perfectly, or a parameter is not identified)."""
    try:
        cov = fit.cov_params()
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise ModelNotComputed(f"the fit has no covariance matrix of its estimates ({exc}), so there are no "
                               f"standard errors for Wald tests") from None
    cov = cov.loc[list(names), list(names)]
    if not np.isfinite(cov.to_numpy()).all():
        raise ModelNotComputed("the covariance matrix of the estimates is not finite, so there are no standard "
                               "errors for Wald tests")
    # A covariance matrix has no negative eigenvalue. Under separation (a cell whose answers all go one
    # way) the robust sandwich of a GEE can have large ones, and its Wald χ² come out negative (p = 1).
    eig = np.linalg.eigvalsh((cov.to_numpy() + cov.to_numpy().T) / 2)
    if eig.min() < -1e-8 * max(abs(eig).max(), 1e-300):
        raise ModelNotComputed("the covariance matrix of the estimates is not positive semi-definite "
                               f"(eigenvalues {eig.min():.3g} to {eig.max():.3g}), so its Wald tests are meaningless")
    return cov


def _separation_hint(data: pd.DataFrame, design: DesignInfo, column: str) -> str:
    """``; every design cell has a single rating …`` when each cell's answers are all the same (perfect separation)."""
    frame = data[~data["practice"].astype(bool)]
    factors = [f for f in design.between + design.within if f in frame]
    if column not in frame or not factors or frame.empty:
        return ""
    single = frame.groupby(factors, observed=True)[column].nunique() == 1
    if single.all():
        return (f"; every design cell ({' × '.join(factors)}) has a single {column} across all participants: the "
                f"factors predict every answer exactly")
    if single.any():
        cells = ["/".join(map(str, np.atleast_1d(cell))) for cell in single[single].index[:3]]
        return (f"; {int(single.sum())} design cell(s) ({' × '.join(factors)}) have a single {column} across all "
                f"participants (e.g. {', '.join(cells)}): their estimates do not exist")
    return ""


def not_computed_row(model: str, reason: str) -> pd.DataFrame:
    """The one row of a model that could not be estimated: term ``not computed``, reason in ``note``."""
    return pd.DataFrame([{"model": model, "term": NOT_COMPUTED, "df": np.nan, "chi2": np.nan, "p": np.nan,
                          "note": f"{NOT_COMPUTED}: {reason}"}])


def not_computed_models(table: pd.DataFrame) -> dict[str, str]:
    """Model → reason, for the models of an :func:`additional_models` table that were not computed."""
    rows = table[table["term"] == NOT_COMPUTED]
    return {m: n.removeprefix(f"{NOT_COMPUTED}: ") for m, n in zip(rows["model"], rows["note"])}


def _guarded(function, data: pd.DataFrame, design: DesignInfo, column: str) -> pd.DataFrame:
    """Run one model; if the data do not allow it to be estimated, its not-computed row with the reason."""
    from statsmodels.tools.sm_exceptions import PerfectSeparationError
    try:
        table = function(data, design)
    # statsmodels reports data it cannot fit as ValueError ("endog values must be 0 and 1, and not all
    # identical", "need covariance of parameters"); ModelNotComputed and LinAlgError are ValueErrors too
    except (PerfectSeparationError, ValueError) as exc:
        reason = str(exc) if isinstance(exc, ModelNotComputed) else \
            f"statsmodels could not estimate it ({type(exc).__name__}: {exc})"
        return not_computed_row(MODEL_NAMES[function.__name__], reason + _separation_hint(data, design, column))
    if not np.isfinite(table["chi2"].to_numpy(dtype=float)).all():
        return not_computed_row(MODEL_NAMES[function.__name__], "a Wald statistic is not finite (a zero or "
                                "undefined standard error)" + _separation_hint(data, design, column))
    return table


def additional_models(data: pd.DataFrame, design: DesignInfo) -> pd.DataFrame:
    """All additional models that fit the design's response type (empty for rankings/k-AFC votes); a model
    the data do not allow to estimate gets one ``not computed`` row with the reason (see the module docstring)."""
    if design.response_type == "likert":
        parts = [_guarded(mixed_model, data, design, "rating"), _guarded(ordinal_model, data, design, "rating")]
    elif design.response_type == "afc" and len(design.alternatives.levels) == 2:
        parts = [_guarded(choice_mixed, data, design, "chosen"), _guarded(choice_gee, data, design, "chosen")]
    else:
        return pd.DataFrame(columns=["model", "term", "df", "chi2", "p", "note"])
    table = pd.concat(parts, ignore_index=True)
    return table.astype({"df": "Int64"})   # whole degrees of freedom, blank where not computed
