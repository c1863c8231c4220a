"""Standard errors and df of pair contrasts from the ANOVA's error strata (univariate and Statistica rules).

A contrast of cell means is ``L = Σ_g Σ_c L[g, c] · M[g, c]`` over the between groups g (n_g subjects) and
within cells c. With the orthonormal within contrasts ``C_S`` of each stratum S (``anova_core``; S = ∅ is
the between-subjects stratum, MSE = the ``Error`` row), the univariate (sphericity) model of afex's ``aov``
says the subjects' scores ``y_i C_S`` are independent with variance ``MSE_S`` in every direction, so

    Var(L) = Σ_S MSE_S · a_S,       a_S = Σ_g ‖L[g] C_S‖² / n_g,
    df     = (Σ_S MSE_S a_S)² / Σ_S (MSE_S a_S)² / df_S          (Satterthwaite; df_S = d_S · (n − groups))

— emmeans' ``.aovlist.dffun`` on ``emmeans(afex_fit, …, model = "univariate")``. A pair inside one between
group of an effect with one within factor lies in that factor's stratum alone: its SE and df are the
effect's own error term's (Statistica's numbers). A pair across groups mixes the between-subjects stratum
in (the textbook split-plot rule).

The Statistica rule tests every pair of effect E against E's own stratum: ``Var(L) = MSE_E · Σ_S a_S``
(= MSE_E Σ_g ‖L[g]‖² / n_g, Tukey–Kramer), ``df = df_E`` — right for pairs inside one group, blind to the
between-subject variance of pairs across groups.
"""

from __future__ import annotations

import numpy as np

from analysis.anova_core import within_contrasts


def stratum_weights(L: np.ndarray, n_g: np.ndarray, wk: tuple[int, ...]) -> np.ndarray:
    """``a[p, S] = Σ_g ‖L[p, g] C_S‖² / n_g`` for contrasts L (pairs × groups × within cells).

    >>> L = np.array([[[0.5, -0.5]]])              # one group of 4, a two-level within factor
    >>> stratum_weights(L, np.array([4]), (2,))    # all of it in the factor's stratum
    array([[0.   , 0.125]])
    """
    C, slices = within_contrasts(tuple(wk))
    sq = np.matmul(L, C) ** 2 / n_g[None, :, None]
    per_col = sq.sum(axis=1)
    return np.stack([per_col[:, sl].sum(axis=1) for sl in slices], axis=1)


def stratum_mse(cov: np.ndarray, wk: tuple[int, ...]) -> np.ndarray:
    """Error mean square of every stratum from the pooled within-group covariance (…, cells, cells):
    ``MSE_S = trace(C_S' Σ C_S) / d_S`` — the ANOVA's ``strata.ms``."""
    C, slices = within_contrasts(tuple(wk))
    diag = (np.matmul(cov, C) * C).sum(axis=-2)       # diag(C' Σ C)
    return np.stack([diag[..., sl].mean(axis=-1) for sl in slices], axis=-1)


def univariate_se_df(a: np.ndarray, mse: np.ndarray, df_strata: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """SE and Satterthwaite df of every pair: ``a`` pairs × strata, ``mse`` (…, strata) → (…, pairs) each."""
    parts = mse[..., None, :] * a                     # (…, pairs, strata)
    var = np.maximum(parts.sum(axis=-1), 0.0)         # a stratum without variance can round to −1e-33
    with np.errstate(divide="ignore", invalid="ignore"):
        df = var**2 / (parts**2 / df_strata).sum(axis=-1)
    return np.sqrt(var), df


def statistica_se_df(a: np.ndarray, mse: np.ndarray, stratum: int, df_strata: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """SE and df of every pair against the effect's own stratum ``stratum`` (the Statistica convention)."""
    var = np.maximum(mse[..., stratum, None] * a.sum(axis=-1), 0.0)
    return np.sqrt(var), np.broadcast_to(df_strata[stratum], var.shape).astype(float)
