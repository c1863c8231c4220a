"""Tukey HSD (Statistica convention) against R fixtures, the studentized range against scipy, summaries."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from analysis.anova import anova
from analysis.errors import AnalysisError
from analysis.posthoc import abbreviate, summarize, tukey, tukey_all
from analysis.studentized_range import studentized_range_sf

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


def test_tukey_matches_r(case):
    """Means, n, differences, SE and q to 1e-10; p to R's ptukey accuracy (~1e-7 absolute, see below)."""
    fx, table = case
    for tk in fx["tukey"]:
        eff = ":".join(as_list(tk["effect"]))
        res = tukey(table, eff)
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
            assert se == pytest.approx(r["se"], rel=1e-10)
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
    assert res.records()[0].keys() == {"a", "b", "diff", "q", "p"}
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
    res = tukey(table, "G")
    assert list(res.means["n"]) == [9.0, 21.0]
    mse = table.effect("G")["mse"]
    assert res.pairs["se"].iloc[0] == pytest.approx(np.sqrt(mse / 2 * (1 / 9 + 1 / 21)))


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
