"""analysis.anova against the Python libraries where their designs overlap: pingouin (rm_anova: up to two
within factors; mixed_anova: one within + one between) and statsmodels AnovaRM (within only, no
sphericity correction)."""

from __future__ import annotations

import warnings
from pathlib import Path

import pandas as pd
import pytest

from analysis.anova import anova

pg = pytest.importorskip("pingouin")
AnovaRM = pytest.importorskip("statsmodels.stats.anova").AnovaRM

FIXTURES = Path(__file__).parent / "fixtures" / "anova"
RTOL = 1e-8


@pytest.fixture(autouse=True)
def _quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def close(a, b, rtol=RTOL):
    return float(a) == pytest.approx(float(b), rel=rtol, abs=1e-12)


def _pingouin_mixed(d):
    ref = pg.mixed_anova(d, dv="score", within="time", subject="subject", between="group", correction=True,
                         effsize="np2").set_index("Source")
    cols = {c.lower().replace("-", "_"): c for c in ref.columns}
    return ref, cols


def test_pingouin_mixed_anova_balanced():
    d = pd.read_csv(FIXTURES / "mixed11.csv")
    d = d[~d["subject"].isin(["m19", "m20"])]  # 9 + 9 subjects
    ours = anova(d, "score", "subject", within=["time"], between=["group"])
    ref, cols = _pingouin_mixed(d)
    for src, eff in (("group", "group"), ("time", "time"), ("Interaction", "time:group")):
        r, o = ref.loc[src], ours.effect(eff)
        assert close(o["ss"], r["SS"])
        assert close(o["df1"], r["DF1"]) and close(o["df2"], r["DF2"])
        assert close(o["F"], r["F"])
        assert close(o["p"], r[cols["p_unc"]])
        assert close(o["eta2_partial"], r["np2"])
        if src != "group":
            assert close(o["eps_gg"], r["eps"])


def test_pingouin_mixed_anova_unequal_groups():
    """9 vs 11 subjects: the between effect and the interaction agree; pingouin's within main effect uses
    group-size-weighted means (not Type III), so there we rely on the R fixtures (test_anova_fixtures)."""
    d = pd.read_csv(FIXTURES / "mixed11.csv")
    ours = anova(d, "score", "subject", within=["time"], between=["group"])
    ref, cols = _pingouin_mixed(d)
    for src, eff in (("group", "group"), ("Interaction", "time:group")):
        r, o = ref.loc[src], ours.effect(eff)
        assert close(o["ss"], r["SS"]) and close(o["F"], r["F"]) and close(o["p"], r[cols["p_unc"]])
    assert not close(ours.effect("time")["ss"], ref.loc["time", "SS"], rtol=1e-3)


def test_pingouin_rm_anova_one_way_with_sphericity():
    d = pd.read_csv(FIXTURES / "onewithin.csv")
    ours = anova(d, "rt", "subject", within=["cond"]).effect("cond")
    agg = d.groupby(["subject", "cond"], as_index=False)["rt"].mean()
    ref = pg.rm_anova(agg, dv="rt", within="cond", subject="subject", correction=True, detailed=True,
                      effsize="ng2").iloc[0]
    cols = {c.lower().replace("-", "_"): c for c in ref.index}
    assert close(ours["ss"], ref["SS"]) and close(ours["F"], ref["F"]) and close(ours["p"], ref[cols["p_unc"]])
    assert close(ours["eta2_generalized"], ref["ng2"])
    assert close(ours["eps_gg"], ref["eps"])
    assert close(ours["p_gg"], ref[cols["p_gg_corr"]])
    assert close(ours["mauchly_w"], ref[cols["w_spher"]])
    # pingouin drops the second-order term of Mauchly's chi-square approximation (R keeps it; so do we)
    assert close(ours["mauchly_p"], ref[cols["p_spher"]], rtol=5e-3)


def test_pingouin_rm_anova_two_way():
    """Two of Experiment 2's four within factors, on data averaged over the other two: same F/p/η²p/ε; our SS
    are on the full cell grid, i.e. 4× those of the averaged data."""
    d = pd.read_csv(FIXTURES / "exp2.csv")
    ours = anova(d, "score", "participant", within=["BODY", "METHOD"])
    agg = d.groupby(["participant", "BODY", "METHOD"], as_index=False)["score"].mean()
    ref = pg.rm_anova(agg, dv="score", within=["BODY", "METHOD"], subject="participant", correction=True,
                      detailed=True, effsize="np2").set_index("Source")
    cols = {c.lower().replace("-", "_"): c for c in ref.columns}
    for src, eff in (("BODY", "BODY"), ("METHOD", "METHOD"), ("BODY * METHOD", "BODY:METHOD")):
        r, o = ref.loc[src], ours.effect(eff)
        assert close(o["F"], r["F"]) and close(o["p"], r[cols["p_unc"]]) and close(o["eta2_partial"], r["np2"])
        assert close(o["ss"], r["SS"])  # 4 cells of GAIT x SEX are averaged by anova itself here: same SS
        if r["ddof1"] > 1:
            assert close(o["eps_gg"], r["eps"])
            assert close(o["p_gg"], r[cols["p_gg_corr"]])


def test_statsmodels_anovarm_four_within():
    d = pd.read_csv(FIXTURES / "exp2.csv")
    ours = anova(d, "score", "participant", within=["GAIT", "SEX", "BODY", "METHOD"])
    ref = AnovaRM(d, "score", "participant", within=["GAIT", "SEX", "BODY", "METHOD"]).fit().anova_table
    assert len(ref) == len(ours.effects) == 15
    for name, r in ref.iterrows():
        o = ours.effect(name)
        assert close(o["F"], r["F Value"]) and close(o["p"], r["Pr > F"])
        assert o["df1"] == r["Num DF"] and o["df2"] == r["Den DF"]


def test_statsmodels_anovarm_three_within_with_repetitions():
    """Experiment 1's within part (2 repetitions per cell averaged by both)."""
    d = pd.read_csv(FIXTURES / "exp1.csv")
    ours = anova(d, "rating", "participant", within=["GAIT", "BODY", "MOTION"])
    ref = AnovaRM(d, "rating", "participant", within=["GAIT", "BODY", "MOTION"], aggregate_func="mean").fit().anova_table
    for name, r in ref.iterrows():
        o = ours.effect(name)
        assert close(o["F"], r["F Value"]) and close(o["p"], r["Pr > F"])
    assert ours.rows_per_cell == (2, 2)
