"""Linear mixed model with a random intercept per participant, REML, and lmerTest's Satterthwaite F tests.

The model is lme4's ``lmer(y ~ X + (1 | participant), REML = TRUE)``: ``y = Xβ + b_i + e`` with
``b_i ~ N(0, σ²θ²)``, ``e ~ N(0, σ²)``. For one random intercept the REML criterion profiled over β and σ is
a closed-form function of θ = SD(b)/σ (per-participant sums), so it is minimised in one dimension to full
precision.

Tests are lmerTest's ``anova(fit)`` (type III, Satterthwaite): for a term with coefficient rows L the F
statistic is ``β'L'(LCL')⁻¹Lβ / q``; its denominator df comes from Satterthwaite's approximation with
lmerTest's ingredients — the covariance C(θ, σ) = σ²(X'V⁻¹X)⁻¹ differentiated with respect to the variance
parameters (θ, σ) (analytic here, numerical in lmerTest), and their asymptotic covariance ``2 H⁻¹`` from the
Hessian H of the REML deviance in (θ, σ); several numerator df are combined as lmerTest's ``contestMD`` does
(one Satterthwaite df per eigen-direction of LCL', then ``2E / (E − q)``).

>>> import numpy as np
>>> rng = np.random.default_rng(0)
>>> groups = np.repeat(np.arange(6), 4)
>>> x = np.tile([-1.0, -1.0, 1.0, 1.0], 6)
>>> y = 0.5 * x + rng.normal(size=6)[groups] + rng.normal(scale=0.5, size=24)
>>> fit = fit_lmm(np.column_stack([np.ones(24), x]), y, groups)
>>> test = satterthwaite_test(fit, [1])
>>> round(test["df_den"], 6)      # a within-participant slope: df = 24 − 6 − 1 (balanced)
17.0
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import optimize, stats

from analysis.io_design import DesignInfo
from analysis.models.common import MODEL_NAMES, ModelNotComputed, design_matrix, trial_data


@dataclass
class LmmFit:
    """REML estimates: β, its covariance, θ = SD(b)/σ, σ, and the pieces Satterthwaite's df need."""
    beta: np.ndarray
    cov: np.ndarray
    theta: float
    sigma: float
    jacobian: list            # ∂C/∂θ, ∂C/∂σ
    varpar_cov: np.ndarray    # asymptotic covariance of (θ, σ): 2 H⁻¹
    reml_deviance: float


class _Sums:
    """Per-participant sums that make the REML criterion O(q p²) for any θ."""

    def __init__(self, X, y, groups):
        groups = np.unique(groups, return_inverse=True)[1]
        q = groups.max() + 1
        self.n, self.p = X.shape
        self.counts = np.bincount(groups, minlength=q).astype(float)
        self.Sx = np.zeros((q, self.p))
        np.add.at(self.Sx, groups, X)
        self.Sy = np.bincount(groups, weights=y, minlength=q)
        self.XtX, self.Xty, self.yty = X.T @ X, X.T @ y, float(y @ y)
        self.total_ss = float(np.sum((y - y.mean()) ** 2))

    def solve(self, theta):
        """(M = X'V⁻¹X, β̂, r² = residual quadratic form, log|V|, c_i, ∂c_i/∂θ) with V = I + θ²ZZ'."""
        t2 = theta ** 2
        c = t2 / (1 + self.counts * t2)
        dc = 2 * theta / (1 + self.counts * t2) ** 2
        M = self.XtX - (self.Sx * c[:, None]).T @ self.Sx
        m = self.Xty - self.Sx.T @ (c * self.Sy)
        beta = np.linalg.solve(M, m)
        r2 = self.yty - float(np.sum(c * self.Sy ** 2)) - float(m @ beta)
        return M, beta, r2, float(np.sum(np.log1p(self.counts * t2))), c, dc

    def profiled(self, theta):
        """lme4's profiled REML criterion at θ."""
        M, _, r2, logdet_v, _, _ = self.solve(theta)
        df = self.n - self.p
        if r2 <= 1e-12 * self.total_ss:   # no residual variance (up to rounding): no REML criterion
            return np.inf
        return logdet_v + np.linalg.slogdet(M)[1] + df * (1 + np.log(2 * np.pi * r2 / df))

    def gradient(self, varpar):
        """Gradient of the REML deviance in (θ, σ) (lmerTest's ``devfun_vp``), analytic."""
        theta, sigma = varpar
        M, beta, r2, _, _, dc = self.solve(theta)
        dM = -(self.Sx * dc[:, None]).T @ self.Sx
        resid_sums = self.Sy - self.Sx @ beta
        d_theta = (np.sum(2 * self.counts * theta / (1 + self.counts * theta ** 2))
                   + np.trace(np.linalg.solve(M, dM)) - np.sum(dc * resid_sums ** 2) / sigma ** 2)
        d_sigma = -2 * r2 / sigma ** 3 + 2 * (self.n - self.p) / sigma
        return np.array([d_theta, d_sigma])


def _minimise_theta(sums: _Sums) -> float:
    """θ̂ ≥ 0: a log-spaced scan brackets the minimum, bounded Brent refines it; θ = 0 if the boundary wins."""
    grid = np.concatenate([[0.0], np.logspace(-4, 3, 57)])
    values = np.array([sums.profiled(t) for t in grid])
    best = int(np.argmin(values))
    lo, hi = grid[max(best - 1, 0)], grid[min(best + 1, len(grid) - 1)]
    res = optimize.minimize_scalar(sums.profiled, bounds=(lo, hi), method="bounded",
                                   options={"xatol": 1e-12, "maxiter": 500})
    return float(res.x) if res.fun <= values[best] else float(grid[best])


def fit_lmm(X: np.ndarray, y: np.ndarray, groups: np.ndarray) -> LmmFit:
    """REML fit of ``y ~ X + (1 | groups)`` (X includes the intercept and must have full column rank)."""
    X, y = np.asarray(X, float), np.asarray(y, float)
    sums = _Sums(X, y, np.asarray(groups))
    if np.linalg.matrix_rank(sums.XtX) < X.shape[1]:
        raise ValueError("the fixed-effects design is rank deficient (a design cell without answers?)")
    if sums.n <= sums.p or not np.isfinite(sums.profiled(1.0)):
        raise ValueError("the residual variance is 0: the factors and participants account for every rating "
                         "exactly, so the F tests would divide by a zero standard error")
    theta = _minimise_theta(sums)
    M, beta, r2, _, c, dc = sums.solve(theta)
    sigma = float(np.sqrt(r2 / (sums.n - sums.p)))
    Minv = np.linalg.inv(M)
    cov = sigma ** 2 * Minv
    dM = -(sums.Sx * dc[:, None]).T @ sums.Sx
    jacobian = [-sigma ** 2 * Minv @ dM @ Minv, 2 * sigma * Minv]
    varpar = np.array([theta, sigma])
    H = np.zeros((2, 2))
    for j in range(2):   # central differences of the analytic gradient
        h = 1e-5 * max(abs(varpar[j]), 1e-3)
        up, down = varpar.copy(), varpar.copy()
        up[j] += h
        down[j] -= h
        H[:, j] = (sums.gradient(up) - sums.gradient(down)) / (2 * h)
    H = (H + H.T) / 2
    return LmmFit(beta, cov, theta, sigma, jacobian, 2 * np.linalg.inv(H), float(sums.profiled(theta)))


def _satterthwaite_df(fit: LmmFit, contrast: np.ndarray, variance: float) -> float:
    grad = np.array([contrast @ J @ contrast for J in fit.jacobian])
    return float(2 * variance ** 2 / (grad @ fit.varpar_cov @ grad))


def satterthwaite_test(fit: LmmFit, columns) -> dict:
    """lmerTest's F test of ``β[columns] = 0`` (``contest1D``/``contestMD``): F, numerator df, Satterthwaite
    denominator df, p."""
    L = np.zeros((len(columns), len(fit.beta)))
    L[np.arange(len(columns)), list(columns)] = 1.0
    VL = L @ fit.cov @ L.T
    d, P = np.linalg.eigh(VL)
    d, P = d[::-1], P[:, ::-1]                     # decreasing, as R's eigen
    keep = d > max(np.sqrt(np.finfo(float).eps) * d[0], 0)
    q = int(keep.sum())
    PtL = (P.T @ L)[:q]
    t2 = (PtL @ fit.beta) ** 2 / d[:q]
    F = float(t2.sum() / q)
    nu = np.array([_satterthwaite_df(fit, PtL[m], d[m]) for m in range(q)])
    if q == 1 or np.all(np.abs(np.diff(nu)) < 1e-8):
        df_den = float(nu.mean())
    elif np.any(nu <= 2):
        df_den = 2.0
    else:
        E = float(np.sum(nu / (nu - 2)))
        df_den = 2 * E / (E - q)
    return {"F": F, "df": q, "df_den": df_den, "p": float(stats.f.sf(F, q, df_den))}


@dataclass
class LmerAnova:
    """The fit and lmerTest's type III table (term, F, df, df_den, p)."""
    fit: LmmFit
    tests: pd.DataFrame


def lmer_anova(frame: pd.DataFrame, response: str, factors: list[str], participant: str = "participant",
               model: str = MODEL_NAMES["mixed_model"]) -> LmerAnova:
    """``anova(lmerTest::lmer(response ~ A * B * … + (1 | participant)))`` with sum-to-zero contrasts."""
    X, terms = design_matrix(frame, factors)
    y = frame[response].astype(float).to_numpy()
    try:
        fit = fit_lmm(X, y, frame[participant].to_numpy())
    except ValueError as exc:
        raise ModelNotComputed(str(exc)) from None
    spread = float(np.var(y)) if len(y) > 1 else 0.0
    if not np.isfinite(fit.sigma) or fit.sigma ** 2 <= 1e-10 * max(spread, 1e-300):
        raise ModelNotComputed(f"the residual variance is {fit.sigma ** 2:.3g}: the factors and participants account "
                               f"for every rating exactly, so the F tests would divide by a zero standard error")
    rows = [{"model": model, "term": term, **satterthwaite_test(fit, range(s.start, s.stop))}
            for term, s in terms.items()]
    return LmerAnova(fit, pd.DataFrame(rows))


def mixed_model(data: pd.DataFrame, design: DesignInfo) -> pd.DataFrame:
    """The report's linear mixed model of the test ratings: one Satterthwaite F row per term."""
    frame = trial_data(data, design, ["rating"])
    result = lmer_anova(frame, "rating", design.between + design.within)
    fit, table = result.fit, result.tests
    table["chi2"] = np.nan
    table["note"] = (f"F tests, type III, Satterthwaite df (lmerTest's anova); random intercept SD "
                     f"{fit.theta * fit.sigma:.3f}, residual SD {fit.sigma:.3f}; n = {len(frame)} answers")
    return table
