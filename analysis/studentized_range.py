"""Upper tail of the studentized range distribution, vectorised (Tukey HSD p-values).

scipy.stats.studentized_range is accurate but takes milliseconds per value (adaptive quadrature), too
slow for the hundreds of pairs of an interaction's post-hoc table. This module evaluates the same
double integral on fixed grids:

    P(Q > q) = ∫ f_s(s) · P(R_k > q·s) ds,          s = sqrt(χ²_ν / ν)
    P(R_k > w) = k ∫ φ(z) [Φ(z)^(k−1) − (Φ(z) − Φ(z−w))^(k−1)] dz

The inner bracket is written as Φ(z)^(k−1) · (−expm1((k−1)·log1p(−Φ(z−w)/Φ(z)))) with log-CDFs, so
there is no cancellation for large w; both integrals are trapezoidal sums over the real line (x = log s
for the outer one), which converge geometrically for these smooth, fast-decaying integrands. Agrees
with scipy.stats.studentized_range.sf to ~1e-12 absolute (see tests/test_posthoc.py).
"""

from __future__ import annotations

import numpy as np
from scipy import special

_HZ = 0.2  # inner grid step (trapezoid rule; error ~ exp(-2π²σ²/h²) for a peak of width σ ≥ 0.3)
_Z_ALL = np.arange(-9.0, 9.0 + 1e-9, _HZ)


def _z_grid(k: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes where k·φ(z)·Φ(z)^(k−1) (the density of the maximum) is not negligible, and that density."""
    logdens = np.log(k) - 0.5 * _Z_ALL**2 - 0.5 * np.log(2 * np.pi) + (k - 1) * special.log_ndtr(_Z_ALL)
    keep = logdens > -42.0
    return _Z_ALL[keep], np.exp(logdens[keep])


def _range_sf(w: np.ndarray, k: int) -> np.ndarray:
    """P(range of k iid standard normals > w), for an array of w ≥ 0."""
    w = np.asarray(w, dtype=float)
    shape = w.shape
    z, dens = _z_grid(k)
    w = w.reshape(-1, 1)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        ratio = np.exp(special.log_ndtr(z[None, :] - w) - special.log_ndtr(z)[None, :])
        bracket = -np.expm1((k - 1) * np.log1p(-np.minimum(ratio, 1.0)))
    out = np.nan_to_num(bracket, nan=0.0) @ dens * _HZ
    return np.clip(out, 0.0, 1.0).reshape(shape)


def _log_s_density(df: float):
    """For x = log s, s = sqrt(χ²_df/df): the log density relative to its mode (x = 0), the grid step and the
    interval [lo, hi] outside which the density is below e^-45 of its peak."""
    sd = 1.0 / np.sqrt(2.0 * df)  # curvature of the log density at the mode is 2·df
    h = min(0.1, sd / 3.0)

    def drop(x):
        with np.errstate(over="ignore"):
            return df * (x - np.expm1(2 * x) / 2)

    lo = hi = 0.0
    while drop(lo) > -45.0:
        lo -= sd
    while drop(hi) > -45.0:
        hi += sd
    return drop, h, lo, hi


def studentized_range_sf(q, k: int, df, chunk: int = 1024) -> np.ndarray:
    """P(Q > q) for the studentized range with ``k`` means and ``df`` error degrees of freedom.

    ``df`` is a number or an array broadcast against ``q`` (one df per value: emmeans' Tukey adjustment of
    contrasts with Satterthwaite df). In t = log(q·s) the outer integral is a convolution of
    log P(R_k > e^t) with the density of log s, so P(R_k > ·) is evaluated once on one uniform t grid
    covering every q, and each q needs only a weighted sum (trapezoid rule on a shifted grid, weights
    normalised to sum to one).

    >>> round(float(studentized_range_sf(3.5, 3, 20)), 6)
    0.055892
    """
    if k < 2:
        raise ValueError("the studentized range needs k >= 2 means")
    q, df = np.broadcast_arrays(np.asarray(q, dtype=float), np.asarray(df, dtype=float))
    out = np.ones(q.shape)
    pos = q > 0
    if not pos.any():
        return out
    if np.any(df[pos] <= 0) or np.any(np.isnan(df[pos])):
        raise ValueError("the studentized range needs df > 0")
    qp, dfp = q[pos], df[pos]
    res = np.empty(qp.shape)
    values = np.unique(dfp)
    if len(values) <= _MANY_DF:
        for v in values:
            sel = dfp == v
            res[sel] = _sf_one_df(qp[sel], k, float(v), chunk)
    else:   # many distinct df (Satterthwaite df of simulated data sets): one grid per octave of df
        inf = ~np.isfinite(dfp)
        res[inf] = _range_sf(qp[inf], k)
        octave = np.floor(np.log2(np.where(inf, 1.0, dfp)))
        for o in np.unique(octave[~inf]):
            sel = ~inf & (octave == o)
            res[sel] = _sf_df_array(qp[sel], k, dfp[sel], chunk)
    out[pos] = np.clip(res, 0.0, 1.0)
    return out


_MANY_DF = 2   # up to this many distinct df, each gets its own grid; more share one grid per octave


def _sf_one_df(qp: np.ndarray, k: int, df: float, chunk: int) -> np.ndarray:
    """P(Q > q) for q > 0 sharing one df (see :func:`studentized_range_sf`)."""
    if not np.isfinite(df):
        return _range_sf(qp, k)
    drop, h, lo, hi = _log_s_density(df)
    finite = np.isfinite(qp)
    res = np.zeros(qp.shape)
    if finite.any():
        lq = np.log(qp[finite])
        t = np.arange(lq.min() + lo, lq.max() + hi + h, h)
        r = _range_sf(np.exp(t), k)
        vals = np.empty(lq.shape)
        for a in range(0, len(lq), chunk):
            u = t[None, :] - lq[a:a + chunk, None]
            w = np.exp(drop(u))
            vals[a:a + chunk] = (w @ r) / w.sum(axis=1)
        res[finite] = vals
    return res


def _sf_df_array(qp: np.ndarray, k: int, df: np.ndarray, chunk: int) -> np.ndarray:
    """P(Q > q) for q > 0 with one finite df per value, all df within a factor of two: one t grid, fine
    enough for the largest df and wide enough for the smallest, and each value's own density of log s."""
    _, h, lo, hi = _log_s_density(float(df.min()))
    h = min(h, _log_s_density(float(df.max()))[1])
    finite = np.isfinite(qp)
    res = np.zeros(qp.shape)
    if finite.any():
        lq, d = np.log(qp[finite]), df[finite]
        t = np.arange(lq.min() + lo, lq.max() + hi + h, h)
        r = _range_sf(np.exp(t), k)
        vals = np.empty(lq.shape)
        for a in range(0, len(lq), chunk):
            u = t[None, :] - lq[a:a + chunk, None]
            with np.errstate(over="ignore"):
                w = np.exp(d[a:a + chunk, None] * (u - np.expm1(2 * u) / 2))
            vals[a:a + chunk] = (w @ r) / w.sum(axis=1)
        res[finite] = vals
    return res


def studentized_range_isf(p, k: int, df, tol: float = 1e-12) -> np.ndarray:
    """The q with P(Q > q) = p (the upper-p quantile; R's ``qtukey(1 - p, k, df)``), ``df`` as in
    :func:`studentized_range_sf`. Solved in log q by the Illinois (regula falsi) method to ``tol``.

    >>> round(float(studentized_range_isf(0.05, 3, 20)), 4)
    3.5779
    """
    p, df = np.broadcast_arrays(np.asarray(p, dtype=float), np.asarray(df, dtype=float))
    if np.any((p <= 0) | (p >= 1)):
        raise ValueError("studentized_range_isf needs 0 < p < 1")
    shape = p.shape
    p, df = p.ravel(), df.ravel()
    lp = np.log(p)

    def f(x):
        with np.errstate(divide="ignore"):
            return np.log(studentized_range_sf(np.exp(x), k, df)) - lp

    a, b = np.full(p.shape, -3.0), np.full(p.shape, 2.0)
    fa, fb = f(a), f(b)
    while np.any(fb > 0):      # widen until P(Q > e^b) < p
        b = np.where(fb > 0, b + 1.0, b)
        fb = f(b)
    for _ in range(200):
        x = b - fb * (b - a) / (fb - fa)
        fx = f(x)
        same = np.sign(fx) == np.sign(fb)
        fa = np.where(same, fa / 2, fb)   # Illinois: halve the stale end's value
        a = np.where(same, a, b)
        step = np.abs(x - b)
        b, fb = x, fx
        if np.all((step < tol) | (fb == 0)):   # the bracket need not shrink; the iterates do
            break
    return np.exp(b).reshape(shape)
