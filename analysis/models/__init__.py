"""Mixed models that R users fit to these data — reported next to the classic ANOVA, labelled as additional.

- :func:`mixed_model`: linear mixed model of the trial-level ratings, REML, participant random intercept,
  full factorial with sum-to-zero contrasts; F tests with Satterthwaite df as ``anova()`` of ``lmerTest::lmer``
  (type III) — :mod:`analysis.models.lmm`;
- :func:`ordinal_model`: cumulative link mixed model of the Likert ratings with a participant random intercept,
  as ``ordinal::clmm`` (logit, flexible thresholds, Laplace); Wald χ² per term — :mod:`analysis.models.ordinal`;
- :func:`choice_mixed`: logistic mixed model of 2AFC choices with a participant random intercept, as
  ``lme4::glmer(family = binomial)`` (Laplace); Wald χ² per term from ``vcov`` — :mod:`analysis.models.choice`;
- :func:`choice_gee`: logistic GEE (exchangeable working correlation within participant, robust SEs).
  For choices the outcome is "chose the first alternatives level" (e.g. NoCOM): the intercept tests the
  alternatives main effect (METHOD) and each term X tests X × METHOD.

Every function returns a DataFrame with columns ``model, term, df, chi2, p, note, F, df_den`` (``chi2`` for
the Wald tests, ``F`` and ``df_den`` for the F tests; ``df`` is the numerator df). A model that cannot be
estimated from the data (e.g. every answer of a design cell in the lowest or highest category, so its
estimate is infinite) is not an error: :func:`additional_models` gives it one row with term ``not computed``,
empty df/chi2/p and the reason in ``note`` (``not computed: …``), so the report is still written and says why
— as the ANOVA section does when the measure has no variance.

>>> sorted(MODEL_NAMES)
['choice_gee', 'choice_mixed', 'mixed_model', 'ordinal_model']
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from analysis.io_design import DesignInfo
from analysis.models.choice import choice_gee, choice_mixed, glmer_binomial
from analysis.models.common import (COLUMNS, MODEL_NAMES, NOT_COMPUTED, ModelNotComputed, not_computed_models,
                                    not_computed_row, separation_hint, wald_terms)
from analysis.models.lmm import lmer_anova, mixed_model
from analysis.models.ordinal import clmm, ordinal_model

__all__ = ["MODEL_NAMES", "NOT_COMPUTED", "ModelNotComputed", "additional_models", "choice_gee", "choice_mixed",
           "clmm", "glmer_binomial", "lmer_anova", "mixed_model", "not_computed_models", "not_computed_row",
           "ordinal_model", "wald_terms"]


def _guarded(function, data: pd.DataFrame, design: DesignInfo, column: str) -> pd.DataFrame:
    """Run one model; if the data do not allow it to be estimated, its not-computed row with the reason."""
    from statsmodels.tools.sm_exceptions import PerfectSeparationError
    try:
        table = function(data, design)
    # statsmodels (the GEE) reports data it cannot fit as ValueError ("endog values must be 0 and 1, and not
    # all identical"); ModelNotComputed and LinAlgError are ValueErrors too
    except (PerfectSeparationError, ValueError) as exc:
        reason = str(exc) if isinstance(exc, ModelNotComputed) else \
            f"it could not be estimated ({type(exc).__name__}: {exc})"
        return not_computed_row(MODEL_NAMES[function.__name__], reason + separation_hint(data, design, column))
    statistic = table["F"] if "F" in table else table["chi2"]
    if not np.isfinite(statistic.to_numpy(dtype=float)).all():
        return not_computed_row(MODEL_NAMES[function.__name__], "a test statistic is not finite (a zero or "
                                "undefined standard error)" + separation_hint(data, design, column))
    return table.reindex(columns=COLUMNS)


def additional_models(data: pd.DataFrame, design: DesignInfo) -> pd.DataFrame:
    """All additional models that fit the design's response type (empty for rankings/k-AFC votes); a model
    the data do not allow to estimate gets one ``not computed`` row with the reason (see the module docstring)."""
    if design.response_type == "likert":
        parts = [_guarded(mixed_model, data, design, "rating"), _guarded(ordinal_model, data, design, "rating")]
    elif design.response_type == "afc" and len(design.alternatives.levels) == 2:
        parts = [_guarded(choice_mixed, data, design, "chosen"), _guarded(choice_gee, data, design, "chosen")]
    else:
        return pd.DataFrame(columns=COLUMNS)
    table = pd.concat(parts, ignore_index=True)
    return table.astype({"df": "Int64"})   # whole degrees of freedom, blank where not computed
