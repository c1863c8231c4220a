"""The split-plot ANOVA engine: a design compiled once, then applied to one or many data sets.

Multivariate-contrast formulation (the one car::Anova / afex use):

* every within effect ``S`` (a subset of the within factors, the empty set being the between-subjects
  stratum) gets an orthonormal contrast matrix ``C_S`` (cells × d_S): normalised Helmert contrasts for
  the factors in ``S``, the normalised mean ``1/sqrt(k)`` for the others. Stacked, the ``C_S`` form an
  orthonormal basis of the cell space, so the sums of squares are those of the univariate split-plot
  ANOVA on the cell means;
* the transformed scores ``Z_S = Y C_S`` (subjects × d_S) go through one between-subjects linear model
  (intercept + all between terms, sum-to-zero coding, full factorial). The Type III hypothesis SS of
  between term ``T`` is ``trace(B_T' (L (X'X)^-1 L')^-1 B_T)``, the error SS is the residual SSCP's
  trace; ``df1 = d_S · df_T``, ``df2 = d_S · (n − cells_between)``;
* sphericity (Mauchly, Greenhouse–Geisser, Huynh–Feldt) comes from the residual SSCP of ``Z_S``.

Everything linear is folded into two matrices, ``M`` (rows: hypothesis rows of every between term, then
an orthonormal basis of the residual space; columns: subjects) and ``C`` (all contrasts side by side),
so ``M @ Y @ C`` followed by block sums of squares gives every SS of every data set at once.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from itertools import product
from math import prod

import numpy as np
from scipy import special

from analysis.errors import AnalysisError


NO_VARIANCE = 1e-12  # relative to the total sum of squares: below it, a stratum is rounding noise


def helmert_orthonormal(k: int) -> np.ndarray:
    """k × (k−1) orthonormal contrasts (normalised Helmert): columns sum to zero, unit length, orthogonal."""
    h = np.zeros((k, k - 1))
    for j in range(1, k):
        h[:j, j - 1] = 1.0
        h[j, j - 1] = -float(j)
        h[:, j - 1] /= np.sqrt(j * (j + 1.0))
    return h


def _kron_all(mats: list[np.ndarray]) -> np.ndarray:
    out = np.ones((1, 1))
    for m in mats:
        out = np.kron(out, m)
    return out


def _members(mask: int, names: tuple[str, ...]) -> tuple[str, ...]:
    return tuple(n for i, n in enumerate(names) if mask >> i & 1)


def _mask_order(n_factors: int) -> list[int]:
    """Subsets of n factors as bit masks, in Yates (standard) order: ∅, A, B, AB, C, AC, BC, ABC, …"""
    return list(range(1 << n_factors))


@lru_cache(maxsize=64)
def within_contrasts(wk: tuple[int, ...]) -> tuple[np.ndarray, tuple[slice, ...]]:
    """All within contrasts side by side (cells × cells, orthogonal) and the column block of each stratum.

    Stratum S (a bit mask over the within factors, Yates order) gets kron over factors of: normalised Helmert
    contrasts for a factor in S, the normalised mean 1/sqrt(k) for a factor not in S.
    """
    blocks, slices, start = [], [], 0
    for s in _mask_order(len(wk)):
        mats = [helmert_orthonormal(k) if s >> i & 1 else np.full((k, 1), 1 / np.sqrt(k)) for i, k in enumerate(wk)]
        c = _kron_all(mats)
        blocks.append(c)
        slices.append(slice(start, start + c.shape[1]))
        start += c.shape[1]
    C = np.hstack(blocks)
    C.setflags(write=False)
    return C, tuple(slices)


@dataclass(frozen=True)
class Design:
    """The shape of a split-plot experiment: within factors (levels, cell order), between factors and
    the between-group membership of each subject.

    ``within`` and ``between`` map factor → tuple of level labels (the order used everywhere).
    Cells are the Cartesian product of the within levels in C order (first factor slowest), so the
    data matrix of one data set is ``subjects × prod(len(levels))``. ``groups`` holds, per subject, the
    integer level code (0-based index into ``between[f]``) of each between factor, shape
    ``(n_subjects, n_between)``.
    """

    within: dict[str, tuple[str, ...]]
    between: dict[str, tuple[str, ...]] = field(default_factory=dict)
    groups: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=int))

    @classmethod
    def make(
        cls,
        within: dict[str, int | list | tuple] | None = None,
        between: dict[str, int | list | tuple] | None = None,
        n_per_group: int | list[int] | None = None,
        groups: np.ndarray | list | None = None,
        n_subjects: int | None = None,
    ) -> Design:
        """Convenience constructor.

        Levels may be given as a count (labels ``"1".."k"``) or as a list of labels. Subjects are given
        either by ``groups`` (per subject, the level code of each between factor), by ``n_per_group``
        (one int for every between cell, or one per between cell in C order), or — with no between
        factors — by ``n_subjects``.
        """

        def levels(spec):
            out = {}
            for f, v in (spec or {}).items():
                out[str(f)] = tuple(str(i + 1) for i in range(v)) if isinstance(v, (int, np.integer)) else tuple(map(str, v))
            return out

        w, b = levels(within), levels(between)
        if groups is not None:
            g = np.asarray(groups, dtype=int).reshape(-1, len(b)) if b else np.zeros((len(groups), 0), dtype=int)
        else:
            cells = list(product(*(range(len(v)) for v in b.values())))
            if n_per_group is None:
                if b or n_subjects is None:
                    raise AnalysisError("Design.make needs groups=, n_per_group= or (without between factors) n_subjects=")
                counts = [int(n_subjects)]
            elif isinstance(n_per_group, (int, np.integer)):
                counts = [int(n_per_group)] * len(cells)
            else:
                counts = [int(c) for c in n_per_group]
                if len(counts) != len(cells):
                    raise AnalysisError(f"n_per_group has {len(counts)} entries, the design has {len(cells)} between cells")
            rows = [cell for cell, c in zip(cells, counts) for _ in range(c)]
            g = np.array(rows, dtype=int).reshape(len(rows), len(b))
        return cls(within=w, between=b, groups=g)

    @property
    def n_subjects(self) -> int:
        return int(self.groups.shape[0])

    @property
    def n_cells(self) -> int:
        return prod(len(v) for v in self.within.values()) if self.within else 1

    @property
    def cells(self) -> list[tuple[str, ...]]:
        """Within cells in data-column order (C order of the within levels)."""
        return list(product(*self.within.values()))

    def compile(self) -> CompiledDesign:
        return CompiledDesign(self)


@dataclass(frozen=True)
class Effect:
    """One tested effect: the within part ``S`` and the between part ``T`` (bit masks), and its name."""

    within_mask: int
    between_mask: int
    within: tuple[str, ...]
    between: tuple[str, ...]

    @property
    def factors(self) -> tuple[str, ...]:
        """Within factors first, then between (Statistica / the paper's naming, e.g. GAIT:SEX)."""
        return self.within + self.between

    @property
    def name(self) -> str:
        return ":".join(self.factors)

    @property
    def order(self) -> int:
        return len(self.factors)


class CompiledDesign:
    """Precomputed matrices of a Design; apply with :meth:`fit` to an array of data sets."""

    def __init__(self, design: Design):
        self.design = design
        wnames = tuple(design.within)
        bnames = tuple(design.between)
        self.within_names = wnames
        wk = [len(design.within[f]) for f in wnames]
        bk = [len(design.between[f]) for f in bnames]
        n = design.n_subjects

        # ---- within: orthonormal contrasts per within subset (stratum), in Yates order
        self.strata_masks = _mask_order(len(wnames))
        self.C, self.col_slices = within_contrasts(tuple(wk))  # K × K orthogonal, one column block per stratum
        self.d = np.array([sl.stop - sl.start for sl in self.col_slices])

        # ---- between: full-factorial sum-to-zero (orthonormal Helmert) coding
        g = design.groups
        coded = [helmert_orthonormal(k)[g[:, i]] for i, k in enumerate(bk)]
        self.between_masks = _mask_order(len(bnames))
        cols, self.term_cols, start = [], [], 0
        for t in self.between_masks:
            x = np.ones((n, 1))
            for i in range(len(bnames)):
                if t >> i & 1:
                    x = (x[:, :, None] * coded[i][:, None, :]).reshape(n, -1)
            cols.append(x)
            self.term_cols.append(slice(start, start + x.shape[1]))
            start += x.shape[1]
        X = np.hstack(cols)
        p = X.shape[1]
        self.df_between = np.array([sl.stop - sl.start for sl in self.term_cols])
        n_bcells = prod(bk) if bk else 1
        if bk:
            present = {tuple(r) for r in g.tolist()}
            missing = [c for c in product(*(range(k) for k in bk)) if c not in present]
            if missing:
                lab = ", ".join(f"{f}={design.between[f][missing[0][i]]}" for i, f in enumerate(bnames))
                raise AnalysisError(
                    f"between-subjects cell {lab} has no subjects ({len(missing)} of {n_bcells} between cells empty); "
                    "every combination of the between factors needs at least one subject"
                )
        self.df_error = n - p
        if self.df_error < 1:
            raise AnalysisError(
                f"{n} subjects for {n_bcells} between-subjects cell(s): the error term has {self.df_error} degrees of "
                "freedom; at least one more subject than between cells is needed"
            )
        q, r = np.linalg.qr(X, mode="complete")
        if np.min(np.abs(np.diag(r[:p]))) < 1e-10 * np.max(np.abs(np.diag(r[:p]))):
            raise AnalysisError("the between-subjects design matrix is singular")
        xtx_inv = np.linalg.inv(X.T @ X)
        rows, self.row_slices, start = [], [], 0
        for sl in self.term_cols:
            w = xtx_inv[sl, sl]
            # R'R = W^-1  ->  SS_T = || R (X'X)^-1_{T,:} X' Z ||²
            lc = np.linalg.cholesky(np.linalg.inv(w))
            a = lc.T @ xtx_inv[sl, :] @ X.T
            rows.append(a)
            self.row_slices.append(slice(start, start + a.shape[0]))
            start += a.shape[0]
        rows.append(q[:, p:].T)  # orthonormal basis of the residual space
        self.res_slice = slice(start, start + self.df_error)
        self.M = np.vstack(rows)

        # ---- effects (S, T) except the intercept (0, 0): by order, then stratum (Yates), then between term
        effs = [
            Effect(s, t, _members(s, wnames), _members(t, bnames))
            for s in self.strata_masks
            for t in self.between_masks
            if (s, t) != (0, 0)
        ]
        self.effects = sorted(effs, key=lambda e: (e.order, e.within_mask, e.between_mask))
        self.eff_s = np.array([self.strata_masks.index(e.within_mask) for e in self.effects], dtype=int)
        self.eff_t = np.array([self.between_masks.index(e.between_mask) for e in self.effects], dtype=int)
        self.df1 = (self.d[self.eff_s] * self.df_between[self.eff_t]).astype(float)
        self.df2 = (self.d[self.eff_s] * self.df_error).astype(float)
        # row / column block boundaries for np.add.reduceat
        self._row_starts = np.array([sl.start for sl in self.row_slices] + [self.res_slice.start])
        self._col_starts = np.array([sl.start for sl in self.col_slices])

    @cached_property
    def stratum_names(self) -> list[str]:
        return [":".join(_members(s, self.within_names)) for s in self.strata_masks]

    def block_ss(self, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Transform and reduce: returns (SS[D, between terms + residual, strata], transformed T[D, n, K])."""
        Y = np.asarray(Y, dtype=float)
        T = np.matmul(np.matmul(self.M, Y), self.C)
        sq = T * T
        ss = np.add.reduceat(np.add.reduceat(sq, self._row_starts, axis=1), self._col_starts, axis=2)
        return ss, T

    def fit(self, Y: np.ndarray, alpha: float = 0.05, sphericity: bool = True, power: bool = True) -> dict:
        """Analyse data sets ``Y`` (D × subjects × cells, or subjects × cells). Returns a dict of arrays
        (shape D × effects, or D × strata for the error strata) — see ``analysis.anova.ManyResult``."""
        Y = np.asarray(Y, dtype=float)
        single = Y.ndim == 2
        if single:
            Y = Y[None]
        n, K = self.design.n_subjects, self.design.n_cells
        if Y.shape[1:] != (n, K):
            raise AnalysisError(f"data array has shape {Y.shape[1:]} per data set, the design needs ({n}, {K})")
        ss_all, T = self.block_ss(Y)
        res_row = len(self.row_slices)
        sse_strata = ss_all[:, res_row, :]  # D × strata
        ss = ss_all[:, self.eff_t, self.eff_s]  # D × E
        sse = sse_strata[:, self.eff_s]
        df1, df2 = self.df1, self.df2
        with np.errstate(divide="ignore", invalid="ignore"):
            ms = ss / df1
            mse = sse / df2
            F = ms / mse
            # A stratum with no variance at all (e.g. % NoCOM + % COM = 100 in every cell, so every
            # effect without METHOD is 0/0) holds only rounding noise: its F is undefined, not huge.
            centred = Y - Y.mean(axis=(1, 2), keepdims=True)
            scale = np.einsum("dnk,dnk->d", centred, centred)[:, None]
            tol = NO_VARIANCE * scale
            degenerate = ss + sse <= tol
            F = np.where(degenerate, np.nan, F)
            ss, ms = np.where(degenerate, 0.0, ss), np.where(degenerate, 0.0, ms)
            # An effect that is real over an error term that is rounding noise (SS, MSE kept as computed):
            # F = ∞ (so p = 0, power = 1), the rule the tables print — not F = 1e31 made of noise.
            F = np.where((sse <= tol) & ~degenerate, np.inf, F)
            p = special.fdtrc(df1, df2, F)
            pes = np.where(degenerate, np.nan, ss / (ss + sse))
            ges = ss / (ss + sse_strata.sum(axis=1, keepdims=True))
        out = dict(ss=ss, df1=np.broadcast_to(df1, ss.shape), df2=np.broadcast_to(df2, ss.shape), ms=ms, mse=mse,
                   F=F, p=p, eta2_partial=pes, eta2_generalized=ges, noncentrality=F * df1,
                   stratum_ss=sse_strata,
                   stratum_df=np.broadcast_to((self.d * self.df_error).astype(float), sse_strata.shape))
        if power:
            out["power"] = observed_power(F, df1, df2, alpha)
        if sphericity:
            sph = self.sphericity(T, tol[:, 0])
            gg = sph["eps_gg"][:, self.eff_s]
            hf = sph["eps_hf"][:, self.eff_s]
            with np.errstate(invalid="ignore"):
                out["eps_gg"] = gg
                out["p_gg"] = special.fdtrc(gg * df1, gg * df2, F)
                out["eps_hf"] = hf
                hfc = np.minimum(hf, 1.0)
                out["p_hf"] = special.fdtrc(hfc * df1, hfc * df2, F)
            out["mauchly_w"] = sph["mauchly_w"][:, self.eff_s]
            out["mauchly_p"] = sph["mauchly_p"][:, self.eff_s]
            out["eps_hf_raw"] = sph["eps_hf_raw"][:, self.eff_s]
        if single:
            out = {k: v[0] for k, v in out.items()}
        return out

    def sphericity(self, T: np.ndarray, tol: np.ndarray | float = 0.0) -> dict:
        """Mauchly W and p, GG and HF ε per stratum (NaN where d = 1). HF is capped at 1 in ``eps_hf``
        (SPSS/Statistica, and what car/afex use for the corrected p); ``eps_hf_raw`` is uncapped.

        All NaN, too, where the stratum's error SSCP is singular beyond what its df allow: fewer than
        min(d, error df) eigenvalues above ``tol`` (per data set; ``fit`` passes NO_VARIANCE × the data
        set's total SS). ε and Mauchly of such a matrix are ratios of rounding noise (car: "error SSP
        matrix singular … corrections not available"). With fewer error df than contrasts (n < d) the
        SSCP is singular by construction; ε is still reported there (Mauchly is not), as before.
        """
        D = T.shape[0]
        S = len(self.strata_masks)
        res = {k: np.full((D, S), np.nan) for k in ("eps_gg", "eps_hf", "eps_hf_raw", "mauchly_w", "mauchly_p")}
        n = self.df_error
        tol = np.broadcast_to(np.asarray(tol, dtype=float), (D,))
        for j, sl in enumerate(self.col_slices):
            d = sl.stop - sl.start
            if d < 2:
                continue
            E = T[:, self.res_slice, sl]
            sscp = np.matmul(E.transpose(0, 2, 1), E)
            tr = np.trace(sscp, axis1=1, axis2=2)
            tr2 = np.einsum("nij,nij->n", sscp, sscp)
            with np.errstate(divide="ignore", invalid="ignore"):
                gg = tr * tr / (d * tr2)
                hf = ((n + 1) * d * gg - 2) / (d * (n - d * gg))
                w, pw = mauchly(sscp, tr, n, cells=self.design.n_cells)
                logdet = np.log(w) + d * np.log(tr / d)   # NaN where det ≤ 0 or n < d
            singular = self._singular(sscp, tr, logdet, tol, min(d, n))
            for key, v in (("eps_gg", gg), ("eps_hf_raw", hf), ("eps_hf", np.minimum(hf, 1.0)),
                           ("mauchly_w", w), ("mauchly_p", pw)):
                res[key][:, j] = np.where(singular, np.nan, v)
        return res

    @staticmethod
    def _singular(sscp: np.ndarray, tr: np.ndarray, logdet: np.ndarray, tol: np.ndarray, rank: int) -> np.ndarray:
        """Per data set: has the (D × d × d, positive semi-definite) SSCP fewer than ``rank`` eigenvalues
        above ``tol``? Cheap screen first: the smallest eigenvalue is at least det / tr^(d−1), so a
        matrix passing that bound (``logdet`` from Mauchly's W) needs no eigen-decomposition; ordinary data
        never reach ``eigvalsh``."""
        d = sscp.shape[-1]
        out = tr <= tol  # the whole stratum is rounding noise
        with np.errstate(divide="ignore", invalid="ignore"):
            safe = logdet - (d - 1) * np.log(tr) > np.log(tol)   # False where logdet is NaN
        todo = ~out & ~safe
        if todo.any():
            ev = np.linalg.eigvalsh(sscp[todo])
            out[todo] = (ev > tol[todo, None]).sum(axis=1) < rank
        return out


def mauchly(sscp: np.ndarray, tr: np.ndarray, n: int, cells: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Mauchly's sphericity test of orthonormal-contrast SSCP matrices (D × d × d), ``n`` error df.

    W = det(S) / (tr(S)/d)^d; p from Anderson's chi-square approximation with its second-order term
    w2 ∝ (2d³ + 6d² + 3·c + 2). The textbook has c = d (``cells=None``). R writes c = the number of
    response columns of the model — ``stats::mauchly.test`` on the multivariate model of all within cells
    (``ncol(SSD)``) and car's ``summary.Anova.mlm`` (``nrow(P)``), hence afex's ``sphericity.tests`` —
    so ``fit`` passes ``cells`` = the number of within cells and p equals R's. The two agree for d = 2
    (w2 = 0 there) and differ by up to a few per cent for d ≥ 3. NaN where the SSCP is singular (n < d).

    >>> s = np.array([[[4.0, 1.0, 0.5], [1.0, 3.0, 0.2], [0.5, 0.2, 1.0]]])   # d = 3, e.g. of 16 within cells
    >>> w, p_r = mauchly(s, np.trace(s, axis1=1, axis2=2), n=5, cells=16)
    >>> _, p_textbook = mauchly(s, np.trace(s, axis1=1, axis2=2), n=5)
    >>> round(float(w[0]), 4), round(float(p_r[0]), 4), round(float(p_textbook[0]), 4)
    (0.5426, 0.8176, 0.8157)
    """
    d = sscp.shape[-1]
    c = d if cells is None else cells
    sign, logdet = np.linalg.slogdet(sscp)
    logw = np.where(sign > 0, logdet - d * np.log(tr / d), np.nan)
    if n < d:
        logw = np.full_like(logw, np.nan)
    rho = 1 - (2 * d * d + d + 2) / (6 * d * n)
    w2 = (d + 2) * (d - 1) * (d - 2) * (2 * d**3 + 6 * d * d + 3 * c + 2) / (288 * (n * d * rho) ** 2)
    z = -n * rho * logw
    f = d * (d + 1) / 2 - 1
    pr1 = special.chdtrc(f, z)
    pr2 = special.chdtrc(f + 4, z)
    return np.exp(logw), pr1 + w2 * (pr2 - pr1)


def observed_power(F, df1, df2, alpha: float = 0.05):
    """Observed (post-hoc) power, SPSS/Statistica convention: λ = F·df1,
    power = 1 − ncf.cdf(f.ppf(1 − α, df1, df2), df1, df2, λ)."""
    F = np.asarray(F, dtype=float)
    df1 = np.broadcast_to(np.asarray(df1, dtype=float), F.shape)
    df2 = np.broadcast_to(np.asarray(df2, dtype=float), F.shape)
    crit = special.fdtri(df1, df2, 1.0 - alpha)
    lam = np.where(np.isfinite(F), F * df1, np.nan)
    with np.errstate(invalid="ignore"):
        pw = 1.0 - special.ncfdtr(df1, df2, lam, crit)
    return np.where(np.isinf(F), 1.0, np.clip(pw, 0.0, 1.0))
