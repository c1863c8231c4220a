"""Maximum likelihood for GLMMs with one random intercept per participant: Laplace or adaptive Gauss–Hermite.

The likelihood of participant i is the one-dimensional integral ``∫ Π_j p(y_ij | φ, τu) φ(u) du`` over the
standardised random intercept u ~ N(0, 1) (τ is its SD). With ``n_agq = 1`` it is approximated as lme4's
``glmer(nAGQ = 1)`` and ordinal's ``clmm(nAGQ = 1)`` do (Laplace): ``g(û) − ½ log D`` with
``g(u) = Σ_j log p(y_ij | τu) − u²/2``, û its maximum (the conditional mode) and ``D = −g''(û)`` (the observed
curvature). With ``n_agq = K > 1`` it is clmm's adaptive Gauss–Hermite rule: K nodes ``û + x_k √(2/D)``.

The gradient is analytic (total derivative through û and D, which needs the third derivative of the
observation log-likelihood); the Hessian that gives the standard errors is a central difference of it, as
R computes its Hessian by finite differences (lme4's ``deriv12`` of the deviance, ordinal's ``deriv12``).

A *family* gives, for every observation, the linear predictors ``η_c = B_c φ + o_c + sign·s`` (s = τu is the
participant's shift) and the derivatives of its log-likelihood with respect to them; see
:class:`CumulativeLogit` and :class:`BernoulliLogit`.

>>> import numpy as np
>>> X = np.ones((6, 1)); y = np.array([1., 0, 1, 1, 0, 1]); groups = np.array([0, 0, 0, 1, 1, 1])
>>> fit = fit_random_intercept(BernoulliLogit(X, y), groups)
>>> round(float(fit.params[0]), 4), round(fit.tau, 4)   # no participant differences: τ at its boundary 0
(0.6931, 0.0)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import optimize, sparse, special

_NEWTON_TOL = 1e-11       # |g'(û)|: far below the effect of û on the Laplace value that tests compare


@dataclass
class Derivatives:
    """Per-observation log-likelihood and its derivatives with respect to each linear predictor ``η_c``:
    ``a_c = ∂ℓ/∂η_c``, ``b_c = Σ_d ∂²ℓ/∂η_c∂η_d``, ``c_c = Σ_de ∂³ℓ/∂η_c∂η_d∂η_e`` (arrays shaped like η)."""
    ll: np.ndarray
    a: list
    b: list
    c: list


class BernoulliLogit:
    """``y ∈ {0, 1}``, ``logit P(y = 1) = Xβ + s`` (lme4's ``glmer(family = binomial)``)."""

    sign = 1.0

    def __init__(self, X: np.ndarray, y: np.ndarray):
        self.B = [np.asarray(X, float)]
        self.offsets = [np.zeros(len(y))]
        self.y = np.asarray(y, float)
        self.n_params = self.B[0].shape[1]

    def start(self) -> np.ndarray:
        mean = min(max(self.y.mean(), 1e-3), 1 - 1e-3)
        params = np.zeros(self.n_params)
        params[0] = np.log(mean / (1 - mean))   # first column is the intercept
        return params

    def derivatives(self, eta: list) -> Derivatives:
        e = eta[0]
        mu = special.expit(e)
        y = self.y.reshape(self.y.shape + (1,) * (e.ndim - 1))
        ll = y * special.log_expit(e) + (1 - y) * special.log_expit(-e)
        w = mu * (1 - mu)
        return Derivatives(ll, [y - mu], [-w], [-w * (1 - 2 * mu)])


class CumulativeLogit:
    """Ordinal ``y ∈ {1..K}``: ``logit P(Y ≤ j) = θ_j − Xβ − s`` (ordinal's ``clmm``, flexible thresholds).

    Parameters are ``(θ_1..θ_{K−1}, β)``; X has no intercept column. As in ordinal, each observation has the
    two predictors η1 (upper threshold of its category) and η2 (lower), ±∞ at the ends."""

    sign = -1.0

    def __init__(self, X: np.ndarray, y: np.ndarray, n_categories: int):
        X = np.asarray(X, float)
        y = np.asarray(y, int)
        n, k = len(y), n_categories - 1
        upper, lower = np.zeros((n, k)), np.zeros((n, k))
        rows = np.arange(n)
        has_upper, has_lower = y <= k, y >= 2
        upper[rows[has_upper], y[has_upper] - 1] = 1.0
        lower[rows[has_lower], y[has_lower] - 2] = 1.0
        self.B = [np.hstack([upper, -X * has_upper[:, None]]), np.hstack([lower, -X * has_lower[:, None]])]
        self.offsets = [np.where(has_upper, 0.0, np.inf), np.where(has_lower, 0.0, -np.inf)]
        self.y, self.k = y, k
        self.n_params = k + X.shape[1]

    def start(self) -> np.ndarray:
        """Thresholds at the observed cumulative logits, β = 0 (as ordinal's fe.start for a null model)."""
        counts = np.bincount(self.y, minlength=self.k + 2)[1:self.k + 2].astype(float) + 0.5
        cumulative = np.cumsum(counts)[:-1] / counts.sum()
        return np.concatenate([np.log(cumulative / (1 - cumulative)), np.zeros(self.n_params - self.k)])

    def derivatives(self, eta: list) -> Derivatives:
        e1, e2 = eta
        # P = F(η1) − F(η2), computed on the side that keeps precision (as ordinal's getFitted does)
        upper_side = e2 > 0
        P = np.where(upper_side, special.expit(-e2) - special.expit(-e1), special.expit(e1) - special.expit(e2))
        with np.errstate(divide="ignore", invalid="ignore"):
            ll = np.log(P)
        F1, F2 = special.expit(e1), special.expit(e2)
        f1, f2 = F1 * (1 - F1), F2 * (1 - F2)
        d1, d2 = f1 * (1 - 2 * F1), f2 * (1 - 2 * F2)          # f'
        s1, s2 = f1 * (1 - 6 * f1), f2 * (1 - 6 * f2)          # f''
        r = (f1 - f2) / P
        a = [f1 / P, -f2 / P]
        b = [d1 / P - f1 * r / P, -d2 / P + f2 * r / P]
        c = [s1 / P - (d1 - d2) * f1 / P ** 2 - 2 * r * d1 / P + 2 * r ** 2 * f1 / P,
             -s2 / P + (d1 - d2) * f2 / P ** 2 + 2 * r * d2 / P - 2 * r ** 2 * f2 / P]
        return Derivatives(ll, a, b, c)


@dataclass
class RandomInterceptFit:
    """Estimates (family parameters, then τ), their covariance (inverse observed information of the
    approximated likelihood), τ, the log-likelihood, the conditional modes and whether the optimiser converged."""
    params: np.ndarray
    cov: np.ndarray
    tau: float
    loglik: float
    modes: np.ndarray
    converged: bool


class _Objective:
    """The approximated log-likelihood and its analytic gradient at ψ = (φ, τ)."""

    def __init__(self, family, groups: np.ndarray, n_agq: int):
        self.family = family
        self.groups = np.asarray(groups)
        self.q = int(self.groups.max()) + 1
        # Gauss–Hermite nodes and weights × e^{x²}; one node at 0 with weight √π is Laplace's approximation
        nodes, weights = (np.polynomial.hermite.hermgauss(n_agq) if n_agq > 1
                          else (np.zeros(1), np.full(1, np.sqrt(np.pi))))
        self.nodes, self.log_weights = nodes, np.log(weights) + nodes ** 2
        self.modes = np.zeros(self.q)
        # per-participant sums as one sparse product: the q × n indicator matrix
        n = len(self.groups)
        self.G = sparse.csr_matrix((np.ones(n), (self.groups, np.arange(n))), shape=(self.q, n))

    def _eta(self, phi: np.ndarray, shift: np.ndarray) -> list:
        """Linear predictors for per-observation shifts ``shift`` (n,) or (n, K)."""
        base = [B @ phi + o for B, o in zip(self.family.B, self.family.offsets)]
        if shift.ndim == 2:
            base = [b[:, None] for b in base]
        return [b + self.family.sign * shift for b in base]

    def _sum(self, values: np.ndarray) -> np.ndarray:
        return np.asarray(self.G @ values)

    def _shift_derivatives(self, d: Derivatives):
        sg = self.family.sign
        return sg * sum(d.a), sum(d.b), sg * sum(d.c)

    def _g(self, phi, tau, u):
        d = self.family.derivatives(self._eta(phi, tau * u[self.groups]))
        return self._sum(d.ll) - u ** 2 / 2, d

    def conditional_modes(self, phi: np.ndarray, tau: float):
        """û by Newton per participant (g is concave: halve a step while it lowers g), and D = −g''(û)."""
        u = self.modes.copy()
        g, d = self._g(phi, tau, u)
        for _ in range(100):
            ls, lss, _ = self._shift_derivatives(d)
            grad, D = tau * self._sum(ls) - u, 1 - tau ** 2 * self._sum(lss)
            if not np.all(np.isfinite(grad)) or np.abs(grad).max() < _NEWTON_TOL:
                break
            step = grad / D
            for _ in range(60):
                g_try, d_try = self._g(phi, tau, u + step)
                worse = ~(g_try >= g - 1e-13 * np.abs(g))
                if not worse.any():
                    break
                step = np.where(worse, step / 2, step)
            u, g, d = u + step, g_try, d_try
        if np.all(np.isfinite(u)):   # the next call starts here (warm start); never from a failed point
            self.modes = u
        return u, D, d

    def value_and_gradient(self, psi: np.ndarray):
        """log L(ψ) and its gradient; −inf where the predictors are invalid (e.g. thresholds out of order)."""
        phi, tau = psi[:-1], psi[-1]
        fam, groups, G = self.family, self.groups, self.G
        u, D, d = self.conditional_modes(phi, tau)
        if not np.all(np.isfinite(D)) or np.any(D <= 0) or not np.all(np.isfinite(d.ll)):
            return -np.inf, np.zeros_like(psi)
        ls, lss, lsss = self._shift_derivatives(d)
        S_ls, S_lss, S_lsss = self._sum(ls), self._sum(lss), self._sum(lsss)
        sg = fam.sign
        # dû/dψ = ∂g'/∂ψ / D; D's total derivative dD/dψ = ∂D/∂ψ + ∂D/∂u · dû/dψ  (q × p, then τ)
        dgp_phi = tau * sg * sum(G @ (B * b[:, None]) for B, b in zip(fam.B, d.b))
        dgp_tau = S_ls + tau * u * S_lss
        du = np.column_stack([dgp_phi, dgp_tau]) / D[:, None]
        dD_phi = -tau ** 2 * sum(G @ (B * c[:, None]) for B, c in zip(fam.B, d.c))
        dD_tau = -2 * tau * S_lss - tau ** 2 * u * S_lsss
        dD = np.column_stack([dD_phi, dD_tau]) + (-tau ** 3 * S_lsss)[:, None] * du
        r = np.sqrt(2 / D)
        nodes = u[:, None] + r[:, None] * self.nodes[None, :]                       # q × K
        dk = self.family.derivatives(self._eta(phi, tau * nodes[groups]))           # n × K
        g_nodes = self._sum(dk.ll) - nodes ** 2 / 2                                 # q × K
        terms = self.log_weights[None, :] + g_nodes
        top = terms.max(axis=1, keepdims=True)
        weights = np.exp(terms - top)
        total = weights.sum(axis=1, keepdims=True)
        pi = weights / total                                                         # q × K
        loglik = float(np.sum(top[:, 0] + np.log(total[:, 0]) + np.log(r) - 0.5 * np.log(2 * np.pi)))
        # gradient: −½ dD/D + Σ_k π_k [∂g/∂ψ(u_k) + g'(u_k) du_k/dψ], du_k = dû − x_k r ½ dD/D
        ls_k = sg * sum(dk.a)                                                        # n × K
        pi_obs = pi[groups]
        dg_phi = sum(G @ (B * (a * pi_obs).sum(axis=1)[:, None]) for B, a in zip(fam.B, dk.a))
        dg_tau = (pi * nodes * self._sum(ls_k)).sum(axis=1)
        gprime = tau * self._sum(ls_k) - nodes                                       # q × K
        half = 0.5 * dD / D[:, None]
        mean_gp = (pi * gprime).sum(axis=1)
        mean_gpx = (pi * gprime * self.nodes[None, :]).sum(axis=1)
        grad = (-half + np.column_stack([dg_phi, dg_tau]) + mean_gp[:, None] * du
                - (mean_gpx * r)[:, None] * half)
        return loglik, grad.sum(axis=0)


def _hessian(objective: _Objective, psi: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Observed information (Hessian of −log L) of the free parameters: central differences of the analytic
    gradient, symmetrised."""
    idx = np.flatnonzero(free)
    H = np.zeros((len(idx), len(idx)))
    for col, j in enumerate(idx):
        h = 1e-5 * max(1.0, abs(psi[j]))
        up, down = psi.copy(), psi.copy()
        up[j] += h
        down[j] -= h
        H[:, col] = -(objective.value_and_gradient(up)[1][idx] - objective.value_and_gradient(down)[1][idx]) / (2 * h)
    return (H + H.T) / 2


def fit_random_intercept(family, groups: np.ndarray, n_agq: int = 1) -> RandomInterceptFit:
    """Maximise the Laplace (``n_agq = 1``) or adaptive Gauss–Hermite likelihood; τ ≥ 0 (0 allowed, as in
    lme4). Quasi-Newton with the analytic gradient, then Newton steps on the finite-difference Hessian so the
    estimates are accurate well beyond the 1e-4 to which they are compared with R."""
    if n_agq < 1:
        raise ValueError(f"n_agq must be 1 (Laplace) or more (adaptive Gauss-Hermite nodes), got {n_agq}")
    groups = np.unique(np.asarray(groups), return_inverse=True)[1]
    objective = _Objective(family, groups, n_agq)
    psi0 = np.concatenate([family.start(), [1.0]])

    def negative(psi):
        value, grad = objective.value_and_gradient(psi)
        return -value, -grad

    bounds = [(None, None)] * family.n_params + [(0.0, None)]
    result = optimize.minimize(negative, psi0, jac=True, method="L-BFGS-B", bounds=bounds,
                               options={"maxiter": 5000, "ftol": 1e-15, "gtol": 1e-9, "maxcor": 30})
    psi = result.x
    on_boundary = psi[-1] < 1e-6
    if on_boundary:
        psi[-1] = 0.0
    free = np.ones(len(psi), bool)
    free[-1] = not on_boundary
    converged = True
    for _ in range(20):   # Newton polish: the quasi-Newton stop is loose in the flat directions
        H = _hessian(objective, psi, free)
        grad = -objective.value_and_gradient(psi)[1][free]
        try:
            step = np.linalg.solve(H, grad)
        except np.linalg.LinAlgError:
            converged = False
            break
        trial = psi.copy()
        trial[free] -= step
        if (free[-1] and trial[-1] < 0) or negative(trial)[0] > negative(psi)[0] + 1e-9:
            break   # no gain left: the quasi-Newton point is the optimum to rounding
        psi = trial
        if np.abs(step).max() < 1e-10:
            break
    loglik, grad = objective.value_and_gradient(psi)
    H = _hessian(objective, psi, free)
    cov = np.full((len(psi), len(psi)), np.nan)
    try:
        cov[np.ix_(free, free)] = np.linalg.inv(H)
    except np.linalg.LinAlgError:
        converged = False
    converged = converged and np.abs(grad[free]).max() < 1e-4
    return RandomInterceptFit(psi[:-1], cov, float(psi[-1]), float(loglik), objective.modes.copy(), converged)
