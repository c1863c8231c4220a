"""Marginal means of an effect's cells as linear combinations of the between-group × within-cell means.

Every post-hoc quantity starts from the group means ``M[g, c]`` (g: a cell of *all* between factors, c: a
within cell) and the weights ``W[e, g, c]`` that make cell e of the effect: ``mean_e = Σ W[e] · M``. Within
cells are always weighted equally (every subject has every cell). Over the between groups that the effect
averages over, two weightings:

* ``"emmeans"`` — equal weights (emmeans' default; the "unweighted" or least-squares means);
* ``"observed"`` — weights proportional to the groups' sizes (emmeans' ``weights = "cells"``), i.e. the plain
  average over the subjects of the matching groups (Statistica's and the paper's means).

Both coincide when the effect contains every between factor, or the groups are equal in size.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import product

import numpy as np

from analysis.anova_core import Design
from analysis.errors import AnalysisError

MEANS_TYPES = ("emmeans", "observed")


def group_codes(design: Design) -> tuple[np.ndarray, np.ndarray]:
    """Per subject, the index of its cell of all between factors (C order); and the subjects per cell.

    >>> d = Design.make(within={"A": 2}, between={"G": 2}, n_per_group=[2, 3])
    >>> group_codes(d)
    (array([0, 0, 1, 1, 1]), array([2, 3]))
    """
    bk = [len(v) for v in design.between.values()]
    if not bk:
        return np.zeros(design.n_subjects, dtype=int), np.array([design.n_subjects])
    code = np.ravel_multi_index(tuple(design.groups.T), bk)
    return code, np.bincount(code, minlength=int(np.prod(bk)))


def group_means(Y: np.ndarray, code: np.ndarray, n_g: np.ndarray) -> np.ndarray:
    """Means of the subjects' cell values per between group: Y (…, subjects, cells) → (…, groups, cells)."""
    onehot = (code[None, :] == np.arange(len(n_g))[:, None]) / n_g[:, None]
    return np.matmul(onehot, Y)


def pooled_covariance(Y: np.ndarray, code: np.ndarray, n_g: np.ndarray) -> np.ndarray:
    """Pooled within-group covariance of the cell values, (…, cells, cells), on n − groups df (the
    residual covariance of afex's multivariate model; its stratum traces are the ANOVA's error MS)."""
    resid = Y - group_means(Y, code, n_g)[..., code, :]
    return np.matmul(np.swapaxes(resid, -1, -2), resid) / (len(code) - len(n_g))


@dataclass(frozen=True)
class EffectCells:
    """The cells of one effect and how each is made from the group × within-cell means.

    Attributes:
        factors: the effect's factors in label order (between first, then within, design order).
        n_between: how many of ``factors`` are between factors.
        cells: the level tuples of the cells, in label order (first factor slowest).
        weights: k × groups × within cells, ``mean_e = Σ weights[e] · M``.
        within_weights: k × within cells, the within part of each cell (equal weights over the within
            cells the effect averages over): a subject's score for cell e is ``within_weights[e] · y_i``.
        n: per cell, the number of subject-level values averaged (subjects of the matching groups × the
            within cells averaged over).
        means_type: ``"emmeans"`` or ``"observed"``.
    """

    factors: tuple[str, ...]
    n_between: int
    cells: list[tuple[str, ...]]
    weights: np.ndarray
    within_weights: np.ndarray
    n: np.ndarray
    means_type: str


def effect_cells(design: Design, factors, means: str = "emmeans") -> EffectCells:
    """The :class:`EffectCells` of the effect made of ``factors`` (any order).

    >>> d = Design.make(within={"A": ["a1", "a2"]}, between={"G": ["g1", "g2"]}, n_per_group=[1, 3])
    >>> ec = effect_cells(d, ["A"], means="observed")
    >>> ec.cells, ec.weights[0].round(2).tolist()
    ([('a1',), ('a2',)], [[0.25, 0.0], [0.75, 0.0]])
    """
    if means not in MEANS_TYPES:
        raise AnalysisError(f"unknown means type {means!r}; use {' or '.join(MEANS_TYPES)}")
    wnames, bnames = list(design.within), list(design.between)
    b_e = [f for f in bnames if f in factors]
    w_e = [f for f in wnames if f in factors]
    _, n_g = group_codes(design)
    groups = list(product(*(range(len(design.between[f])) for f in bnames)))
    wcells = list(product(*(range(len(design.within[f])) for f in wnames)))
    bsel = [bnames.index(f) for f in b_e]
    wsel = [wnames.index(f) for f in w_e]
    b_cells = list(product(*(range(len(design.between[f])) for f in b_e)))
    w_cells = list(product(*(range(len(design.within[f])) for f in w_e)))
    # membership: does group g / within cell c belong to the effect's between / within level combination?
    gmember = np.array([[tuple(g[i] for i in bsel) == bc for g in groups] for bc in b_cells], dtype=float)
    cmember = np.array([[tuple(c[i] for i in wsel) == wc for c in wcells] for wc in w_cells], dtype=float)
    gw = gmember * (n_g[None, :] if means == "observed" else 1.0)
    gw /= gw.sum(axis=1, keepdims=True)
    cw = cmember / cmember.sum(axis=1, keepdims=True)
    weights = (gw[:, None, :, None] * cw[None, :, None, :]).reshape(len(b_cells) * len(w_cells), len(groups),
                                                                     len(wcells))
    within_weights = np.tile(cw, (len(b_cells), 1))
    n = np.repeat(gmember @ n_g, len(w_cells)) * cmember.sum(axis=1)[0]
    levels = [design.between[f] for f in b_e] + [design.within[f] for f in w_e]
    return EffectCells(factors=tuple(b_e + w_e), n_between=len(b_e), cells=list(product(*levels)),
                       weights=weights, within_weights=within_weights, n=n.astype(float), means_type=means)
