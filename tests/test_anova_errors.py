"""Bad data: one exception type (AnalysisError) with a message naming what is wrong and where."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from analysis.anova import anova
from analysis.errors import AnalysisError


def make(n=6, seed=0) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    rows = []
    for s in range(n):
        for a in ("a1", "a2", "a3"):
            for b in ("b1", "b2"):
                rows.append((f"S{s}", "F" if s % 2 else "M", a, b, float(rng.normal())))
    return pd.DataFrame(rows, columns=["subject", "SEX", "A", "B", "y"])


def run(data, **kw):
    args = dict(dv="y", subject="subject", within=["A", "B"], between=["SEX"])
    args.update(kw)
    return anova(data, **args)


def test_missing_cell_names_subject_and_cell():
    d = make()
    d = d[~((d.subject == "S3") & (d.A == "a2") & (d.B == "b1"))]
    with pytest.raises(AnalysisError, match=r"subject 'S3' has no data for cell A=a2, B=b1"):
        run(d)


def test_many_missing_cells_are_counted():
    d = make()
    d = d[~((d.subject.isin(["S1", "S4"])) & (d.A == "a3"))]
    with pytest.raises(AnalysisError, match=r"subject 'S1' has no data for cell A=a3, B=b1 and 1 more cell\(s\); 2 subjects"):
        run(d)


def test_subject_in_two_between_groups():
    d = make()
    d.loc[(d.subject == "S2") & (d.A == "a1"), "SEX"] = "F"
    with pytest.raises(AnalysisError, match=r"subject 'S2' appears in two between-subjects groups \(SEX=F and SEX=M\)"):
        run(d)


def test_non_numeric_dv():
    d = make()
    d["y"] = d["y"].astype(object)
    d.loc[5, "y"] = "n/a"
    with pytest.raises(AnalysisError, match=r"dependent variable 'y' must be numeric.*'n/a'.*row index 5"):
        run(d)


def test_nan_in_dv_and_factors():
    d = make()
    d.loc[[3, 7], "y"] = np.nan
    with pytest.raises(AnalysisError, match=r"column 'y' has 2 missing value\(s\).*row index 3, 7"):
        run(d)
    d = make()
    d.loc[4, "A"] = None
    with pytest.raises(AnalysisError, match=r"column 'A' has 1 missing"):
        run(d)


def test_infinite_dv():
    d = make()
    d.loc[2, "y"] = np.inf
    with pytest.raises(AnalysisError, match="not finite"):
        run(d)


def test_factor_with_one_level():
    d = make()
    d["B"] = "b1"
    with pytest.raises(AnalysisError, match=r"factor 'B' has only one level \('b1'\)"):
        run(d)


def test_constant_dv():
    d = make()
    d["y"] = 3.0
    with pytest.raises(AnalysisError, match=r"dependent variable 'y' is constant"):
        run(d)


def test_unknown_and_duplicate_columns():
    d = make()
    with pytest.raises(AnalysisError, match=r"column\(s\) 'C' not in the data"):
        run(d, within=["A", "C"])
    with pytest.raises(AnalysisError, match="more than one role"):
        run(d, between=["A"])
    with pytest.raises(AnalysisError, match="no factors"):
        run(d, within=[], between=[])


def test_too_few_subjects_and_empty_between_cell():
    d = make(n=2)
    with pytest.raises(AnalysisError, match="degrees of freedom"):
        run(d)
    d = make(n=8)
    d["G"] = np.where(d.subject.isin(["S0", "S1", "S2", "S3"]), "g1", "g2")
    d.loc[d.subject.isin(["S1", "S3"]), "SEX"] = "M"  # now no subject is (SEX=F, G=g1)
    with pytest.raises(AnalysisError, match=r"between-subjects cell SEX=F, G=g1 has no subjects"):
        run(d, between=["SEX", "G"])


def test_bad_alpha_and_observed():
    d = make()
    with pytest.raises(AnalysisError, match="alpha"):
        run(d, alpha=1.5)
    with pytest.raises(AnalysisError, match="observed factor"):
        run(d, observed=["Z"])


def test_not_a_dataframe():
    with pytest.raises(AnalysisError, match="DataFrame"):
        anova([[1, 2]], "y", "s", within=["A"])


def test_repeated_rows_are_averaged_and_counted():
    d = make()
    twice = pd.concat([d, d.assign(y=d.y + 1.0)], ignore_index=True)
    t1, t2 = run(d), run(twice)
    assert t2.rows_per_cell == (2, 2)
    assert np.allclose(t2.Y, t1.Y + 0.5)
    assert np.allclose(t1.effects["F"], t2.effects["F"])


def test_level_order_categorical_and_numeric():
    d = make()
    d["A"] = pd.Categorical(d["A"], categories=["a3", "a1", "a2"])
    t = run(d)
    assert t.levels["A"] == ("a3", "a1", "a2")
    d = make()
    d["A"] = d["A"].map({"a1": 10, "a2": 2, "a3": 1})
    assert run(d).levels["A"] == ("1", "2", "10")


def test_effects_without_variance_have_no_F():
    """% NoCOM + % COM = 100 in every cell: effects without METHOD are 0/0, never 'significant' noise."""
    import numpy as np
    import pandas as pd

    from analysis.anova import anova

    rng = np.random.default_rng(0)
    rows = []
    for s in range(16):
        for gait in ("walk", "jog"):
            for body in ("H1", "H2", "L1", "L2"):
                x = rng.integers(0, 5) * 25.0
                rows += [dict(subject=s, GAIT=gait, BODY=body, METHOD="NoCOM", pct=x),
                         dict(subject=s, GAIT=gait, BODY=body, METHOD="COM", pct=100 - x)]
    effects = anova(pd.DataFrame(rows), "pct", "subject", within=["GAIT", "BODY", "METHOD"]).effects
    without_method = [e for e in effects.index if "METHOD" not in e]
    assert effects.loc[without_method, "F"].isna().all() and (effects.loc[without_method, "ss"] == 0).all()
    assert effects.loc[[e for e in effects.index if "METHOD" in e], "F"].notna().all()
