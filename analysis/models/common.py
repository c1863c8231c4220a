"""What the additional models share: the trial-level data, the sum-to-zero design matrix, term tests, and the
``not computed`` row of a model the data do not allow.

>>> import pandas as pd
>>> frame = pd.DataFrame({"A": ["a1", "a2", "a1", "a2"], "B": ["b1", "b1", "b2", "b2"]})
>>> X, terms = design_matrix(frame, ["A", "B"])
>>> X.shape, list(terms)
((4, 4), ['A', 'B', 'A:B'])
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from analysis.io_design import DesignInfo

NOT_COMPUTED = "not computed"
MODEL_NAMES = {"mixed_model": "linear mixed model (REML, Satterthwaite F tests, as lmerTest)",
               "ordinal_model": "cumulative link mixed model (Laplace, as ordinal::clmm)",
               "choice_mixed": "logistic mixed model (Laplace, as lme4::glmer)",
               "choice_gee": "logistic GEE (exchangeable, robust SE)"}
COLUMNS = ["model", "term", "df", "chi2", "p", "note", "F", "df_den"]
FACTOR_IN_TERM = re.compile(r"C\((\w+), Sum\)")


@dataclass
class MixedFit:
    """A GLMM fit: β (sum-to-zero columns), standard errors, the participant random-intercept SD τ, the
    approximate log-likelihood, whether the optimiser converged, and the per-term Wald tests."""
    beta: np.ndarray
    beta_se: np.ndarray
    tau: float
    loglik: float
    converged: bool
    tests: pd.DataFrame


class ModelNotComputed(ValueError):
    """The data do not allow the model to be estimated; the message says why (shown in the report)."""


def formula_rhs(factors: list[str]) -> str:
    """Full factorial with sum-to-zero contrasts, as ``contrasts = contr.sum`` in R."""
    return " * ".join(f"C({f}, Sum)" for f in factors) if factors else "1"


def trial_data(data: pd.DataFrame, design: DesignInfo, columns: list[str]) -> pd.DataFrame:
    """Test answers with plain object columns (patsy wants numpy dtypes)."""
    frame = data[~data["practice"].astype(bool)]
    frame = frame[["participant", *design.between, *design.within, *columns]].copy()
    for c in ["participant", *design.between, *design.within]:
        frame[c] = frame[c].astype(str).astype(object)
    return frame.reset_index(drop=True)


def design_matrix(frame: pd.DataFrame, factors: list[str]) -> tuple[np.ndarray, dict[str, slice]]:
    """Full-factorial model matrix with intercept and sum-to-zero contrasts (levels sorted, the last coded −1,
    as R's ``contr.sum`` on a default factor), and each term's columns (``A``, ``A:B``…) in R's order."""
    import patsy
    frame = frame[factors].astype(str) if factors else pd.DataFrame(index=frame.index)
    X = patsy.dmatrix(formula_rhs(factors), frame, return_type="matrix")
    if np.linalg.matrix_rank(np.asarray(X).T @ np.asarray(X)) < X.shape[1]:   # p × p: cheaper than X's SVD
        raise ModelNotComputed(f"the full-factorial model is not identified: {_empty_cells(frame, factors)}")
    terms = {}
    for term, columns in X.design_info.term_slices.items():
        names = [FACTOR_IN_TERM.fullmatch(f.name()).group(1) for f in term.factors]
        if names:
            terms[":".join(names)] = columns
    return np.asarray(X), terms


def _empty_cells(frame: pd.DataFrame, factors: list[str]) -> str:
    """Which combinations of the factors' levels have no answers (R would drop the aliased columns)."""
    grid = pd.MultiIndex.from_product([sorted(frame[f].unique()) for f in factors])
    seen = pd.MultiIndex.from_frame(frame[factors].drop_duplicates())
    missing = ["/".join(cell) for cell in grid.difference(seen)]
    if not missing:
        return "its columns are linearly dependent"
    return (f"{len(missing)} design cell(s) ({' × '.join(factors)}) have no answers (e.g. "
            f"{', '.join(missing[:3])}), so their coefficients cannot be estimated")


def wald_terms(params: np.ndarray, cov: np.ndarray, terms: dict[str, slice], model: str) -> pd.DataFrame:
    """Joint Wald χ² of each term's coefficients (``β'V⁻¹β`` on the term's sum-to-zero columns: type III, as
    ``car::Anova(fit, type = 3)`` computes it from ``vcov(fit)``)."""
    rows = []
    for term, columns in terms.items():
        b, v = params[columns], cov[columns, columns]
        chi2 = float(b @ np.linalg.solve(v, b))
        rows.append({"model": model, "term": term, "df": len(b), "chi2": chi2, "p": float(stats.chi2.sf(chi2, len(b)))})
    return pd.DataFrame(rows)


def check_covariance(cov: np.ndarray) -> None:
    """:class:`ModelNotComputed` unless the estimates' covariance is finite and positive definite."""
    if not np.isfinite(cov).all():
        raise ModelNotComputed("the fit has no covariance matrix of its estimates (the information matrix has no "
                               "inverse), so there are no standard errors for Wald tests")
    eig = np.linalg.eigvalsh((cov + cov.T) / 2)
    if eig.min() <= -1e-8 * max(abs(eig).max(), 1e-300):
        raise ModelNotComputed("the covariance matrix of the estimates is not positive semi-definite "
                               f"(eigenvalues {eig.min():.3g} to {eig.max():.3g}), so its Wald tests are meaningless")


def extreme_cells(frame: pd.DataFrame, factors: list[str], response: str, lowest, highest) -> list[str]:
    """Design cells whose every answer is ``lowest`` or every answer is ``highest``: the full-factorial model's
    estimate for such a cell is infinite (complete separation), whatever the random intercepts do."""
    if not factors:
        return []
    values = frame.groupby(factors, observed=True)[response]
    stuck = (values.max() == lowest) | (values.min() == highest)
    return ["/".join(map(str, np.atleast_1d(cell))) for cell in stuck[stuck].index]


def separation_reason(cells: list[str], what: str) -> str:
    """The reason given when :func:`extreme_cells` found cells."""
    return (f"the fit has no covariance matrix of its estimates: {len(cells)} design cell(s) have every answer in "
            f"the {what} (e.g. {', '.join(cells[:3])}), so their estimates are infinite")


def separation_hint(data: pd.DataFrame, design: DesignInfo, column: str) -> str:
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
                          "note": f"{NOT_COMPUTED}: {reason}", "F": np.nan, "df_den": np.nan}])


def not_computed_models(table: pd.DataFrame) -> dict[str, str]:
    """Model → reason, for the models of an :func:`additional_models` table that were not computed."""
    rows = table[table["term"] == NOT_COMPUTED]
    return {m: n.removeprefix(f"{NOT_COMPUTED}: ") for m, n in zip(rows["model"], rows["note"])}
