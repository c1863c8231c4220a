"""p-value adjustment and confidence limits for a family of pairwise comparisons, as emmeans does them.

The family is all m = k(k−1)/2 pairs of an effect's k cells (last axis of every array). Per pair,
t = estimate / SE on its own df (Satterthwaite df differ between pairs):

* ``tukey``: p = P(Q_{k, df} > √2·|t|) with each pair's df (Tukey–Kramer when SEs differ); confidence
  limits estimate ± q_{k, df; 1−α}/√2 · SE;
* ``bonferroni``: p = min(1, m·p); limits with t_{df; 1−α/(2m)};
* ``holm``: Holm's step-down p (R's ``p.adjust``); its limits are Bonferroni's (emmeans: Holm "is only
  appropriate for P values, not CIs");
* ``none``: p = 2·P(T_df > |t|); limits with t_{df; 1−α/2}.

With a single pair (k = 2) every adjustment is the plain t test, as in emmeans.
"""

from __future__ import annotations

import numpy as np
from scipy import special

from analysis.errors import AnalysisError
from analysis.studentized_range import studentized_range_isf, studentized_range_sf

ADJUSTMENTS = ("tukey", "holm", "bonferroni", "none")


def check_adjust(adjust: str) -> str:
    adjust = str(adjust).lower()
    if adjust not in ADJUSTMENTS:
        raise AnalysisError(f"unknown p adjustment {adjust!r}; use one of {', '.join(ADJUSTMENTS)}")
    return adjust


def emmeans_df(df: np.ndarray) -> np.ndarray:
    """The df emmeans hands to ``ptukey``: R's ``zapsmall`` of the family's df (7 significant digits of
    the largest), so that Tukey p-values match it to the last digit."""
    df = np.asarray(df, dtype=float)
    finite = np.isfinite(df)
    if not finite.any():
        return df
    top = np.max(np.abs(df[finite]), axis=None)
    digits = max(0, 7 - int(np.ceil(np.log10(top)))) if top > 0 else 7
    return np.round(df, digits)


def holm(p: np.ndarray) -> np.ndarray:
    """Holm's step-down adjustment along the last axis (R's ``p.adjust(p, "holm")``).

    >>> holm(np.array([0.01, 0.04, 0.03])).tolist()
    [0.03, 0.06, 0.06]
    """
    p = np.asarray(p, dtype=float)
    m = p.shape[-1]
    order = np.argsort(p, axis=-1, kind="stable")
    ranked = np.take_along_axis(p, order, axis=-1) * (m - np.arange(m))
    stepped = np.minimum(np.maximum.accumulate(ranked, axis=-1), 1.0)
    out = np.empty_like(stepped)
    np.put_along_axis(out, order, stepped, axis=-1)
    return out


def adjust_p(t: np.ndarray, df: np.ndarray, adjust: str, k: int) -> tuple[np.ndarray, np.ndarray]:
    """(unadjusted two-sided p, adjusted p) of t statistics (…, pairs) on ``df`` for a family of ``k`` means.

    >>> p, adj = adjust_p(np.array([2.5, 0.3, 1.0]), np.array([20.0, 20.0, 20.0]), "bonferroni", 3)
    >>> bool(np.allclose(adj, np.minimum(1, 3 * p)))
    True
    """
    adjust = check_adjust(adjust)
    t, df = np.broadcast_arrays(np.asarray(t, dtype=float), np.asarray(df, dtype=float))
    with np.errstate(invalid="ignore"):
        p = 2.0 * special.stdtr(df, -np.abs(t))
    m = t.shape[-1]
    if adjust == "none" or m == 1:
        return p, p.copy()
    if adjust == "bonferroni":
        return p, np.minimum(1.0, m * p)
    if adjust == "holm":
        return p, holm(p)
    adj = np.full(t.shape, np.nan)
    ok = np.isfinite(t) & np.isfinite(df) & (df > 0)
    if ok.any():
        dfz = np.stack([emmeans_df(row) for row in df.reshape(-1, m)]).reshape(df.shape)
        adj[ok] = studentized_range_sf(np.sqrt(2.0) * np.abs(t[ok]), k, dfz[ok])
    return p, adj


def critical_value(df: np.ndarray, adjust: str, k: int, level: float = 0.95) -> np.ndarray:
    """Half-width multiplier of the (simultaneous) confidence interval of each pair, as emmeans' ``confint``.

    >>> round(float(critical_value(np.array([20.0]), "none", 2)[0]), 6)
    2.085963
    """
    adjust = check_adjust(adjust)
    df = np.asarray(df, dtype=float)
    m = df.shape[-1]
    alpha = 1.0 - level
    out = np.full(df.shape, np.nan)
    ok = np.isfinite(df) & (df > 0)
    if adjust == "none" or m == 1:
        out[ok] = special.stdtrit(df[ok], 1.0 - alpha / 2)
    elif adjust in ("bonferroni", "holm"):
        out[ok] = special.stdtrit(df[ok], 1.0 - alpha / (2 * m))
    else:
        values, where = np.unique(df[ok], return_inverse=True)   # one quantile per distinct df
        out[ok] = (studentized_range_isf(alpha, k, values) / np.sqrt(2.0))[where.ravel()]
    return out
