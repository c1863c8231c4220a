"""The vectorised path (anova_many) equals the single analysis, and the test is calibrated under the null."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from analysis.anova import Design, anova, anova_many
from analysis.errors import AnalysisError

FIXTURES = Path(__file__).parent / "fixtures" / "anova"
EXP1 = Design.make(within={"GAIT": ["J", "W"], "BODY": 4, "MOTION": 4}, between={"SEX": ["F", "M"]}, n_per_group=8)
# obk.long's between cells (treatment x gender): 2/3, 2/2, 4/3 subjects — unequal, two between factors
OBK = Design.make(within={"phase": 3, "hour": 5}, between={"treatment": 3, "gender": 2}, n_per_group=[2, 3, 2, 2, 4, 3])


def to_long(Y: np.ndarray, design: Design) -> pd.DataFrame:
    """One data set (subjects × cells) as long data for anova()."""
    rows = []
    wnames, bnames = list(design.within), list(design.between)
    for s in range(design.n_subjects):
        groups = {f: design.between[f][design.groups[s, i]] for i, f in enumerate(bnames)}
        for c, cell in enumerate(design.cells):
            rows.append({"subject": f"s{s:03d}", **groups, **dict(zip(wnames, cell)), "y": Y[s, c]})
    return pd.DataFrame(rows)


@pytest.mark.parametrize("design", [EXP1, OBK], ids=["exp1", "obk"])
def test_many_equals_single(design):
    rng = np.random.default_rng(7)
    Y = rng.normal(size=(3, design.n_subjects, design.n_cells)) + rng.normal(size=(3, design.n_subjects, 1))
    many = anova_many(Y, design, power=True)
    for k in range(3):
        table = anova(to_long(Y[k], design), "y", "subject", list(design.within), list(design.between))
        assert list(table.effects.index) == many.effects
        for stat in ("ss", "F", "p", "eta2_partial", "eta2_generalized", "power", "eps_gg", "p_gg", "eps_hf", "p_hf",
                     "mauchly_w", "mauchly_p"):
            np.testing.assert_allclose(many.arrays[stat][k], table.effects[stat].to_numpy(float), rtol=1e-10,
                                       atol=1e-14, equal_nan=True, err_msg=stat)


def test_many_matches_fixture_data():
    d = pd.read_csv(FIXTURES / "obk.csv")
    table = anova(d, "value", "id", ["phase", "hour"], ["treatment", "gender"])
    many = anova_many(table.Y[None], table.design.compile())
    np.testing.assert_allclose(many.F[0], table.effects["F"], rtol=1e-12)
    assert many.frame("F").shape == (1, len(table.effects))


def test_design_make_and_errors():
    d = Design.make(within={"A": 3}, n_subjects=5)
    assert d.n_subjects == 5 and d.n_cells == 3 and d.cells == [("1",), ("2",), ("3",)]
    d = Design.make(within={"A": ["x", "y"]}, between={"G": 2}, groups=[0, 1, 1, 0])
    assert d.groups.tolist() == [[0], [1], [1], [0]]
    with pytest.raises(AnalysisError):
        Design.make(within={"A": 2}, between={"G": 2})
    with pytest.raises(AnalysisError, match="entries"):
        Design.make(within={"A": 2}, between={"G": 2}, n_per_group=[3, 3, 3])
    with pytest.raises(AnalysisError, match="shape"):
        anova_many(np.zeros((2, 5, 4)), Design.make(within={"A": 3}, n_subjects=5))


def _null_data(design: Design, sims: int, rng, cov=None) -> np.ndarray:
    n, K = design.n_subjects, design.n_cells
    subject = rng.normal(0, 1.0, size=(sims, n, 1))
    if cov is None:
        noise = rng.normal(size=(sims, n, K))
    else:
        noise = rng.multivariate_normal(np.zeros(K), cov, size=(sims, n))
    return 3.0 + subject + noise


def _within_error(rate: np.ndarray, sims: int, alpha: float, z: float = 4.0) -> np.ndarray:
    return np.abs(rate - alpha) <= z * np.sqrt(alpha * (1 - alpha) / sims)


@pytest.mark.parametrize("design", [EXP1, OBK], ids=["exp1", "obk-unequal"])
def test_null_rejection_rate_is_alpha(design):
    """Under H0 (sphericity holds) every effect rejects at rate α, within 4 binomial SDs; the p are uniform."""
    sims, alpha = 10_000, 0.05
    rng = np.random.default_rng(12345)
    res = anova_many(_null_data(design, sims, rng), design, alpha=alpha)
    rate = res.rejection_rate(alpha)
    assert _within_error(rate.to_numpy(), sims, alpha).all(), rate.to_dict()
    # with sphericity true the GG correction can only make the test (slightly) conservative
    assert (res.rejection_rate(alpha, "gg") <= alpha + 4 * np.sqrt(alpha * (1 - alpha) / sims)).all()
    # uniformity of the pooled p (KS): a sharper check than one rejection rate
    pooled = res.p.ravel()[:: max(1, res.p.size // 20000)]
    assert stats.kstest(pooled, "uniform").pvalue > 1e-3


def test_sphericity_violation_gg_and_hf_restore_alpha():
    """A 5-level within factor with strongly unequal variances/correlations: the uncorrected F is liberal,
    Greenhouse–Geisser and Huynh–Feldt bring the rejection rate back to (or below) α."""
    design = Design.make(within={"hour": 5}, n_subjects=12)
    sims, alpha = 4000, 0.05
    sd = np.array([0.3, 0.5, 1.0, 2.0, 4.0])
    rho = 0.8 ** np.abs(np.subtract.outer(np.arange(5), np.arange(5)))
    cov = rho * np.outer(sd, sd)
    res = anova_many(_null_data(design, sims, np.random.default_rng(99), cov), design, alpha=alpha)
    se = np.sqrt(alpha * (1 - alpha) / sims)
    assert res.rejection_rate(alpha)["hour"] > alpha + 4 * se  # the violation matters
    assert res.rejection_rate(alpha, "gg")["hour"] <= alpha + 4 * se
    assert res.rejection_rate(alpha, "hf")["hour"] <= alpha + 4 * se
    assert np.nanmean(res.eps_gg) < 0.7


def test_rejections_count_what_rejection_rate_shares():
    """power counts rejections through ManyResult.rejections; rejection_rate is the same count per data set.
    A 1-df effect keeps its uncorrected p under gg/hf; a NaN p is no rejection."""
    design = Design.make(within={"A": 2, "B": 3}, n_subjects=10)
    Y = np.random.default_rng(3).normal(size=(200, 10, 6)) + np.array([0, 0, 0, 0.8, 0.8, 0.8])
    res = anova_many(Y, design)
    for correction in ("none", "gg", "hf"):
        key = "p" if correction == "none" else f"p_{correction}"
        p = np.where(np.isnan(res.arrays[key]), res.p, res.arrays[key])
        counts = res.rejections(0.05, correction)
        assert counts.tolist() == (p < 0.05).sum(axis=0).tolist() and counts["A"] > 0
        assert np.allclose(res.rejection_rate(0.05, correction), counts / 200)
    res.arrays["p"][:5] = np.nan
    assert (res.rejections(1.0) == 195).all()
