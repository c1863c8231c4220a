"""Post-hoc comparisons: the statistica convention against R formulas, the studentized range against scipy,
summaries. The emmeans follow-ups (univariate, multivariate) are checked in tests/test_posthoc_emmeans.py."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from analysis.anova import anova
from analysis.errors import AnalysisError
from analysis.posthoc import abbreviate, posthoc, summarize, tukey, tukey_all
from analysis.studentized_range import studentized_range_isf, studentized_range_sf

FIXTURES = Path(__file__).parent / "fixtures" / "anova"
NAMES = ["exp1", "exp2", "obk", "onewithin", "between2", "mixed11"]


def as_list(v):
    return [] if v is None else [v] if isinstance(v, str) else list(v)


@pytest.fixture(scope="module", params=NAMES)
def case(request):
    fx = json.loads((FIXTURES / f"{request.param}.json").read_text())
    d = fx["design"]
    data = pd.read_csv(FIXTURES / f"{request.param}.csv")
    return fx, anova(data, d["dv"], d["subject"], as_list(d["within"]), as_list(d["between"]))


def test_tukey_statistica_matches_r(case):
    """Statistica convention (observed means, each effect's own error term): means, n, differences, SE and q
    to 1e-10; p to R's ptukey accuracy (~1e-7 absolute, see below). The fixture's SE is on the q scale
    (SE of the difference / √2)."""
    fx, table = case
    for tk in fx["tukey"]:
        eff = ":".join(as_list(tk["effect"]))
        res = tukey(table, eff, followup="statistica")
        assert res.means_type == "observed" and res.followup == "statistica"
        assert res.k == tk["k"]
        assert res.df == pytest.approx(tk["df"], rel=1e-12)
        assert res.mse == pytest.approx(tk["mse"], rel=1e-10)
        # R labels cells between-first then within, like we do; match as unordered level sets
        means = {frozenset(lab.split("/")): (m, n) for lab, m, n in zip(res.means.index, res.means["mean"], res.means["n"])}
        for m in tk["means"]:
            got_mean, got_n = means[frozenset(m["label"].split("/"))]
            assert got_mean == pytest.approx(m["mean"], rel=1e-10, abs=1e-12)
            assert got_n == m["n"]
        ref = {frozenset((frozenset(p["a"].split("/")), frozenset(p["b"].split("/")))): p for p in tk["pairs"]}
        assert len(ref) == len(res.pairs)
        for a, b, diff, se, q, p in res.pairs[["a", "b", "diff", "se", "q", "p"]].itertuples(index=False):
            r = ref[frozenset((frozenset(a.split("/")), frozenset(b.split("/"))))]
            sign = 1.0 if frozenset(r["a"].split("/")) == frozenset(a.split("/")) else -1.0
            assert sign * diff == pytest.approx(r["diff"], rel=1e-10, abs=1e-12)
            assert se / np.sqrt(2) == pytest.approx(r["se"], rel=1e-10)
            assert q == pytest.approx(r["q"], rel=1e-10, abs=1e-12)
            # R's ptukey (Copenhaver & Holland quadrature) is good to ~4e-7 absolute for k = 32; ours agrees
            # with scipy's adaptive integration to ~1e-14 (test below)
            assert p == pytest.approx(r["p"], abs=1e-6)


@pytest.mark.parametrize("k,df", [(2, 14), (3, 2), (4, 42), (8, 14), (16, 3), (32, 126), (64, 1000), (5, 2000)])
def test_studentized_range_against_scipy(k, df):
    q = np.array([0.2, 1.0, 2.5, 3.5, 4.5, 6.0])
    ours = studentized_range_sf(q, k, df)
    ref = stats.studentized_range.sf(q, k, df)
    assert np.allclose(ours, ref, rtol=1e-6, atol=1e-10)
    big = ref > 1e-4
    assert np.allclose(ours[big], ref[big], rtol=5e-9, atol=1e-12)


@pytest.mark.parametrize("df", [2, 5, 14, 126, 10_000, np.inf])
def test_studentized_range_k2_is_t_test(df):
    q = np.linspace(0.05, 9, 40)
    exact = 2 * stats.t.sf(q / np.sqrt(2), df)
    assert np.allclose(studentized_range_sf(q, 2, df), exact, rtol=1e-10, atol=1e-15)


def test_studentized_range_edges():
    assert studentized_range_sf(0.0, 4, 10) == 1.0
    assert studentized_range_sf(-1.0, 4, 10) == 1.0
    assert studentized_range_sf(50.0, 4, 10) == pytest.approx(stats.studentized_range.sf(50.0, 4, 10), rel=1e-3)
    assert studentized_range_sf(np.array([50.0]), 4, np.inf)[0] < 1e-100
    with pytest.raises(ValueError):
        studentized_range_sf(1.0, 1, 10)


def _two_group_within(n=10, seed=0):
    rng = np.random.default_rng(seed)
    rows = []
    for s in range(n):
        for g in ("Walk", "Jog"):
            rows.append((f"s{s}", g, rng.normal() + (1.5 if g == "Walk" else 0.0)))
    return pd.DataFrame(rows, columns=["subject", "GAIT", "y"])


def test_tukey_two_levels_equals_anova_f():
    """With two levels, q² = 2F and the Tukey p equals the ANOVA p (same error term)."""
    data = _two_group_within()
    table = anova(data, "y", "subject", within=["GAIT"])
    res = tukey(table, "GAIT")
    row = table.effect("GAIT")
    assert res.pairs["q"].iloc[0] ** 2 == pytest.approx(2 * row["F"], rel=1e-12)
    assert res.pairs["p"].iloc[0] == pytest.approx(row["p"], rel=1e-9)


def test_summary_format_and_abbreviations():
    data = _two_group_within(n=12, seed=3)
    table = anova(data, "y", "subject", within=["GAIT"])
    res = tukey(table, "GAIT", abbreviations={"GAIT": {"Walk": "W", "Jog": "J"}})
    assert res.summary == "W > J"
    assert res.records()[0].keys() >= {"a", "b", "diff", "q", "p", "se", "df", "t", "p_unadjusted", "lower",
                                       "upper", "effect_size", "effect_size_type", "kind", "followup", "adjust",
                                       "means"}
    assert table.posthoc["GAIT"] is res
    flat = tukey(table, "GAIT", abbreviations={"Walk": "W", "Jog": "J"})
    assert flat.summary == "W > J"


def test_summarize_paper_style():
    labels = ["F/H1b", "F/L1b", "F/L2b", "M/H2b"]
    means = np.array([1.0, 3.0, 2.9, 1.2])
    i, j = np.triu_indices(4, 1)
    # significant: L1b > H1b, L1b > M/H2b, L2b > H1b
    sig = {(0, 1), (1, 3), (0, 2)}
    p = np.array([0.01 if (a, b) in sig else 0.5 for a, b in zip(i, j)])
    assert summarize(labels, means, i, j, p, 0.05) == "F/L1b > F/H1b, M/H2b; F/L2b > F/H1b"
    assert summarize(labels, means, i, j, np.ones_like(p), 0.05) == ""


def test_interaction_labels_between_first():
    rng = np.random.default_rng(5)
    rows = []
    for s in range(12):
        sex = "F" if s < 6 else "M"
        for g in ("W", "J"):
            rows.append((s, sex, g, rng.normal() + (2.5 if (sex, g) == ("F", "W") else 0)))
    data = pd.DataFrame(rows, columns=["p", "SEX", "GAIT", "y"])
    table = anova(data, "y", "p", within=["GAIT"], between=["SEX"])
    res = tukey(table, "GAIT*SEX")
    assert res.effect == "GAIT:SEX"
    assert list(res.means.index) == ["F/J", "F/W", "M/J", "M/W"]
    assert res.summary.startswith("F/W > ")


def test_tukey_kramer_unequal_groups():
    """Between effect with 3 vs 7 subjects: n_i differ and the SE is the Tukey–Kramer one."""
    rng = np.random.default_rng(2)
    rows = [(s, "a" if s < 3 else "b", c, rng.normal()) for s in range(10) for c in ("x", "y", "z")]
    data = pd.DataFrame(rows, columns=["s", "G", "C", "y"])
    table = anova(data, "y", "s", within=["C"], between=["G"])
    mse = table.effect("G")["mse"]
    for followup in ("statistica", "univariate"):   # a between main effect: the same error in both
        res = tukey(table, "G", followup=followup)
        assert list(res.means["n"]) == [9.0, 21.0]
        assert res.pairs["se"].iloc[0] == pytest.approx(np.sqrt(mse * (1 / 9 + 1 / 21)))
        assert res.pairs["df"].iloc[0] == table.effect("G")["df2"]


def test_tukey_from_dataframe_and_errors():
    data = _two_group_within()
    res = tukey(data, "GAIT", dv="y", subject="subject", within=["GAIT"])
    assert res.k == 2
    table = anova(data, "y", "subject", within=["GAIT"])
    with pytest.raises(AnalysisError, match="no effect"):
        tukey(table, "BODY")
    with pytest.raises(AnalysisError, match="distinct"):
        tukey(table, "GAIT", abbreviations={"Walk": "X", "Jog": "X"})
    with pytest.raises(AnalysisError):
        tukey([1, 2], "GAIT")


def test_tukey_all_defaults_to_significant():
    data = _two_group_within(n=14, seed=1)
    table = anova(data, "y", "subject", within=["GAIT"])
    out = tukey_all(table)
    assert list(out) == table.significant()


def test_abbreviate():
    assert abbreviate("GAIT", "Walk", None) == "Walk"
    assert abbreviate("GAIT", "Walk", {"Walk": "W"}) == "W"
    assert abbreviate("GAIT", "Walk", {"GAIT": {"Walk": "Wk"}, "Walk": "W"}) == "Wk"
    assert abbreviate("BODY", "Walk", {"GAIT": {"Walk": "Wk"}}) == "Walk"


# -- array df, quantiles ------------------------------------------------------------------------------------

def test_studentized_range_with_one_df_per_value():
    """Many distinct df (Satterthwaite df of simulated data sets) take the per-octave grid; few take one grid
    each; both agree with scipy's adaptive integration."""
    rng = np.random.default_rng(4)
    q = rng.uniform(0.2, 7.0, 400)
    df = rng.uniform(2.5, 300.0, 400)
    ours = studentized_range_sf(q, 6, df)
    sub = np.arange(0, 400, 20)
    ref = np.array([stats.studentized_range.sf(q[i], 6, df[i]) for i in sub])
    assert np.allclose(ours[sub], ref, rtol=1e-7, atol=1e-12)
    few = studentized_range_sf(q[:5], 6, df[:5])
    assert np.allclose(few, ours[:5], rtol=1e-9, atol=1e-13)
    with pytest.raises(ValueError):
        studentized_range_sf(1.0, 3, -2.0)


@pytest.mark.parametrize("p,k,df", [(0.05, 3, 20.0), (0.05, 9, 12.0), (0.01, 4, 21.8), (0.5, 2, 3.0)])
def test_studentized_range_quantile(p, k, df):
    q = studentized_range_isf(p, k, df)
    assert q == pytest.approx(stats.studentized_range.isf(p, k, df), rel=1e-9)
    assert studentized_range_sf(q, k, df) == pytest.approx(p, rel=1e-10)


# -- follow-ups, kinds, effect sizes, notes -----------------------------------------------------------------

def _split_plot(n=(4, 7), seed=8):
    rng = np.random.default_rng(seed)
    rows, s = [], 0
    for g, size in zip(("g1", "g2"), n):
        for _ in range(size):
            u = rng.normal(0, 2)
            for c in ("a", "b", "c"):
                rows.append((f"s{s}", g, c, u + rng.normal() + (c == "c") * 1.5))
            s += 1
    return pd.DataFrame(rows, columns=["id", "G", "C", "y"])


def test_pair_kinds_and_between_pairs_use_the_pooled_error():
    table = anova(_split_plot(), "y", "id", within=["C"], between=["G"])
    uni = posthoc(table, "C:G")
    sta = posthoc(table, "C:G", followup="statistica", means="emmeans")
    kinds = dict(zip(zip(uni.pairs["a"], uni.pairs["b"]), uni.pairs["kind"]))
    assert kinds[("g1/a", "g1/b")] == "within" and kinds[("g1/a", "g2/a")] == "between"
    assert kinds[("g1/a", "g2/b")] == "mixed"
    within = uni.pairs["kind"] == "within"
    # pairs inside a group: the effect's own error (Statistica's numbers), pairs across groups: more error
    assert np.allclose(uni.pairs.loc[within, "se"], sta.pairs.loc[within, "se"], rtol=1e-12)
    assert (uni.pairs.loc[within, "df"] == table.effect("C:G")["df2"]).all()
    assert (uni.pairs.loc[~within, "se"] > sta.pairs.loc[~within, "se"]).all()
    assert (uni.pairs.loc[~within, "df"] < table.effect("C:G")["df2"]).all()
    assert sta.unprotected and "not protected" in sta.method and not uni.unprotected
    assert uni.method == "Tukey, univariate follow-up, emmeans means"
    assert not posthoc(table, "G", followup="statistica").unprotected      # between error: protected


def test_effect_sizes_dz_and_hedges_g():
    data = _split_plot()
    table = anova(data, "y", "id", within=["C"], between=["G"])
    res = posthoc(table, "C:G")
    wide = data.pivot(index="id", columns="C", values="y")
    grp = data.groupby("id")["G"].first()
    row = res.pairs.set_index(["a", "b"])
    # d_z: mean difference over the pooled within-group SD of the difference scores
    d = (wide["a"] - wide["b"])
    resid = d - d.groupby(grp).transform("mean")
    sd = np.sqrt((resid**2).sum() / (len(d) - 2))
    assert row.loc[("g1/a", "g1/b"), "effect_size"] == pytest.approx(d[grp == "g1"].mean() / sd, rel=1e-12)
    assert row.loc[("g1/a", "g1/b"), "effect_size_type"] == "d_z"
    # Hedges' g of a between pair: pooled within-group SD of the cell, J = 1 − 3 / (4·df − 1), df = n − 2
    x = wide["a"]
    resid = x - x.groupby(grp).transform("mean")
    sd = np.sqrt((resid**2).sum() / (len(x) - 2))
    g = (1 - 3 / (4 * (len(x) - 2) - 1)) * (x[grp == "g1"].mean() - x[grp == "g2"].mean()) / sd
    assert row.loc[("g1/a", "g2/a"), "effect_size"] == pytest.approx(g, rel=1e-12)
    assert row.loc[("g1/a", "g2/a"), "effect_size_type"] == "g"


def test_observed_and_emmeans_means_differ_only_when_averaging_unequal_groups():
    table = anova(_split_plot(n=(3, 9)), "y", "id", within=["C"], between=["G"])
    obs = posthoc(table, "C", means="observed").means["mean"]
    emm = posthoc(table, "C", means="emmeans").means["mean"]
    wide, g = table.Y, table.design.groups[:, 0]
    assert np.allclose(obs, wide.mean(axis=0))                      # the plain average over subjects
    assert np.allclose(emm, (wide[g == 0].mean(axis=0) + wide[g == 1].mean(axis=0)) / 2)
    assert np.allclose(posthoc(table, "C:G", means="observed").means["mean"],
                       posthoc(table, "C:G").means["mean"])


def test_confidence_limits_and_adjustments_are_consistent():
    table = anova(_split_plot(), "y", "id", within=["C"], between=["G"])
    for adjust in ("tukey", "holm", "bonferroni", "none"):
        res = posthoc(table, "C:G", adjust=adjust)
        pr = res.pairs
        assert (pr["p"] >= pr["p_unadjusted"] - 1e-15).all()
        # a pair is significant exactly when its (Tukey / Bonferroni / unadjusted) interval excludes 0
        if adjust != "holm":
            excludes = (pr["lower"] > 0) | (pr["upper"] < 0)
            assert (excludes == pr["significant"]).all()
    none = posthoc(table, "C", adjust="none").pairs
    assert np.allclose(none["p"], 2 * stats.t.sf(np.abs(none["t"]), none["df"]))


def test_bad_followup_adjust_means_are_refused():
    table = anova(_split_plot(), "y", "id", within=["C"], between=["G"])
    with pytest.raises(AnalysisError, match="follow-up"):
        posthoc(table, "C", followup="spss")
    with pytest.raises(AnalysisError, match="adjustment"):
        posthoc(table, "C", adjust="sidak")
    with pytest.raises(AnalysisError, match="means"):
        posthoc(table, "C", means="weighted")


def test_exp1_between_sex_pairs_rest_on_the_pooled_error_by_default():
    """The issue's case: Exp. 1 BODY:SEX. Pairs inside one SEX are the same under both rules (same means,
    SE, df, p); pairs across SEX are tested against Error(BODY) (df 42) by the statistica convention and
    against the pooled error (Satterthwaite df between 14 and 42) by the univariate follow-up, which finds
    fewer of them."""
    d = pd.read_csv(FIXTURES / "exp1.csv")
    table = anova(d, "rating", "participant", ["GAIT", "BODY", "MOTION"], ["SEX"])
    sta = tukey(table, "BODY:SEX", followup="statistica").pairs
    uni = tukey(table, "BODY:SEX").pairs
    within = uni["kind"] == "within"
    assert np.allclose(uni.loc[within, "p"], sta.loc[within, "p"], rtol=1e-9, atol=1e-15)
    assert (sta.loc[~within, "df"] == 42).all()
    assert ((uni.loc[~within, "df"] > 14) & (uni.loc[~within, "df"] < 42)).all()
    sig_sta = set(sta.index[~within & sta["significant"]])
    sig_uni = set(uni.index[~within & uni["significant"]])
    assert sig_uni < sig_sta
