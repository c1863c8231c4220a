"""analysis.anova against R afex::aov_ez / car::Anova reference fixtures (tests/fixtures/make_fixtures.R).

Every statistic of every effect and error stratum must agree to 1e-8 relative. The fixtures are committed;
these tests do not need R.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.anova import anova

FIXTURES = Path(__file__).parent / "fixtures" / "anova"
NAMES = ["exp1", "exp2", "obk", "onewithin", "between2", "mixed11"]
RTOL = 1e-8
MAUCHLY_RTOL = 1e-10         # the bar for the ANOVA vs afex; measured ≤ 3e-13
MAUCHLY_STATS_RTOL = 1e-10   # stats::mauchly.test vs car differ by up to 2.7e-11 among themselves (obk)


def as_list(v) -> list[str]:
    """jsonlite writes length-1 vectors as scalars and empty ones as []."""
    if v is None:
        return []
    return [v] if isinstance(v, str) else list(v)


def load(name: str):
    fx = json.loads((FIXTURES / f"{name}.json").read_text())
    d = fx["design"]
    data = pd.read_csv(FIXTURES / f"{name}.csv")
    table = anova(data, d["dv"], d["subject"], as_list(d["within"]), as_list(d["between"]), alpha=d["alpha"])
    return fx, table


@pytest.fixture(scope="module", params=NAMES)
def case(request):
    return load(request.param)


def r_effects(fx):
    return [e for e in fx["effects"] if e["effect"] != "(Intercept)"]


def assert_close(got, want, what, rtol=RTOL):
    assert want is not None, what
    assert got == pytest.approx(want, rel=rtol, abs=1e-300), f"{what}: {got!r} vs R {want!r}"


def test_same_effects_as_afex(case):
    fx, table = case
    want = sorted(frozenset(as_list(e["factors"])) for e in r_effects(fx))
    got = sorted(frozenset(f) for f in table.effects["factors"])
    assert sorted(map(sorted, want)) == sorted(map(sorted, got))


@pytest.mark.parametrize("stat", ["ss", "df1", "df2", "ms", "mse", "F", "p", "eta2_partial", "eta2_generalized",
                                  "noncentrality", "power"])
def test_effect_statistics(case, stat):
    fx, table = case
    for e in r_effects(fx):
        row = table.effect(":".join(as_list(e["factors"])))
        assert_close(float(row[stat]), e[stat], f"{fx['design']['name']} {e['effect']} {stat}")


def test_sphericity(case):
    fx, table = case
    n_checked = 0
    for e in r_effects(fx):
        row = table.effect(":".join(as_list(e["factors"])))
        name = f"{fx['design']['name']} {e['effect']}"
        if e.get("eps_gg") is None:  # within part with 1 df, or between-only: no sphericity statistics
            for c in ("eps_gg", "p_gg", "eps_hf", "p_hf", "mauchly_w", "mauchly_p"):
                assert np.isnan(row[c]), f"{name} {c} should be NaN"
            continue
        n_checked += 1
        assert_close(row["eps_gg"], e["eps_gg"], f"{name} eps_gg")
        assert_close(row["p_gg"], e["p_gg"], f"{name} p_gg")
        assert_close(row["eps_hf"], min(1.0, e["eps_hf_raw"]), f"{name} eps_hf (capped at 1)")
        assert_close(row["p_hf"], e["p_hf"], f"{name} p_hf")
        assert_close(row["mauchly_w"], e["mauchly_w"], f"{name} Mauchly W (car)", rtol=MAUCHLY_RTOL)
        assert_close(row["mauchly_p"], e["mauchly_p"], f"{name} Mauchly p (car)", rtol=MAUCHLY_RTOL)
        # stats::mauchly.test on afex's mlm takes another numerical path (solve, det) to the same numbers
        assert_close(row["mauchly_w"], e["mauchly_w_stats"], f"{name} Mauchly W (stats)", rtol=MAUCHLY_STATS_RTOL)
        assert_close(row["mauchly_p"], e["mauchly_p_stats"], f"{name} Mauchly p (stats)", rtol=MAUCHLY_STATS_RTOL)
        assert_close(row["mauchly_w"], e["mauchly_w_textbook"], f"{name} Mauchly W")
    if fx["design"]["name"] in ("exp1", "exp2", "obk", "onewithin", "mixed11"):
        assert n_checked > 0


def test_mauchly_textbook_form_differs_from_r_only_for_three_or_more_contrasts():
    """R (stats and car) writes the number of within cells where the textbook second-order term has d:
    ``mauchly(..., cells=None)`` is the textbook p, equal to R's for d = 2 and within a few per cent beyond."""
    from analysis.anova_core import mauchly

    seen_d = set()
    for name in NAMES:
        fx, table = load(name)
        for e in r_effects(fx):
            if e.get("mauchly_p_textbook") is None:
                continue
            within = [f for f in as_list(e["factors"]) if f in table.within]
            # residual SSCP of the effect's contrasts, from the engine's own transform
            comp = table.design.compile()
            _, T = comp.block_ss(table.Y[None])
            mask = sum(1 << table.within.index(f) for f in within)
            cols = comp.col_slices[comp.strata_masks.index(mask)]
            E = T[0, comp.res_slice, cols]
            sscp = (E.T @ E)[None]
            d = sscp.shape[-1]
            seen_d.add(d)
            _, p_text = mauchly(sscp, np.trace(sscp, axis1=1, axis2=2), comp.df_error)
            _, p_r = mauchly(sscp, np.trace(sscp, axis1=1, axis2=2), comp.df_error, cells=table.design.n_cells)
            assert_close(float(p_text[0]), e["mauchly_p_textbook"], f"{name} {e['effect']} textbook p", MAUCHLY_RTOL)
            assert_close(float(p_r[0]), e["mauchly_p"], f"{name} {e['effect']} R p", MAUCHLY_RTOL)
            if d == 2:
                assert_close(float(p_text[0]), float(p_r[0]), "d = 2: no second-order difference", 1e-14)
            else:   # a real difference, and a small one
                assert 1e-6 < abs(p_text[0] - p_r[0]) / p_r[0] < 0.05
    assert {2, 3} <= seen_d


def test_error_strata(case):
    fx, table = case
    by_within = {}
    for s in fx["strata"]:
        by_within[":".join(as_list(s["within"]))] = s
    assert len(by_within) == len(table.strata)
    within_order = list(table.within)
    for label, row in table.strata.iterrows():
        key = "" if label == "Error" else label[len("Error("):-1]
        # R names strata by its own factor order; compare as sets
        match = [v for k, v in by_within.items() if set(k.split(":")) - {""} == set(key.split(":")) - {""}]
        assert len(match) == 1, label
        assert_close(row["ss"], match[0]["ss"], f"{label} SS")
        assert_close(row["df"], match[0]["df"], f"{label} df")
    assert all(f in within_order for f in table.within)


def test_every_fixture_has_data_and_r_versions():
    for name in NAMES:
        fx = json.loads((FIXTURES / f"{name}.json").read_text())
        assert fx["design"]["afex"].startswith("1.")
        assert (FIXTURES / f"{name}.csv").is_file()


def test_max_relative_error_report():
    """Not a check of its own: computes the worst relative error over all fixtures (printed with -s)."""
    worst = 0.0
    for name in NAMES:
        fx, table = load(name)
        for e in r_effects(fx):
            row = table.effect(":".join(as_list(e["factors"])))
            for c in ("ss", "ms", "mse", "F", "p", "eta2_partial", "eta2_generalized", "power", "eps_gg", "p_gg",
                      "p_hf", "mauchly_w", "mauchly_p"):
                if e.get(c) not in (None, 0):
                    worst = max(worst, abs(float(row[c]) - e[c]) / abs(e[c]))
    print(f"max relative error vs R afex fixtures: {worst:.2e}")
    assert worst <= RTOL


def test_every_afex_statistic_to_1e_10():
    """Issue 19's bar: the ANOVA equals afex to ≤ 1e-10 relative in every column afex/car give (measured ≤ 7.4e-14).
    Observed power is not afex's: the fixture computes it with R's pf(ncp=), whose pnbeta stops at 1e-9, so it is
    held to RTOL above."""
    for name in NAMES:
        fx, table = load(name)
        for e in r_effects(fx):
            row = table.effect(":".join(as_list(e["factors"])))
            for c in ("ss", "df1", "df2", "ms", "mse", "F", "p", "eta2_partial", "eta2_generalized", "noncentrality",
                      "eps_gg", "p_gg", "p_hf", "mauchly_w", "mauchly_p"):
                if e.get(c) is not None:
                    assert_close(float(row[c]), e[c], f"{name} {e['effect']} {c}", rtol=1e-10)
            if e.get("eps_hf_raw") is not None:
                assert_close(row["eps_hf"], min(1.0, e["eps_hf_raw"]), f"{name} {e['effect']} eps_hf", rtol=1e-10)


def test_generalized_eta2_with_observed_factor():
    """afex's ges with observed = "gender" (a measured, not manipulated, factor) on obk.long."""
    fx = json.loads((FIXTURES / "obk.json").read_text())
    d = fx["design"]
    data = pd.read_csv(FIXTURES / "obk.csv")
    table = anova(data, d["dv"], d["subject"], as_list(d["within"]), as_list(d["between"]),
                  observed=as_list(d["observed"]))
    for e in r_effects(fx):
        row = table.effect(":".join(as_list(e["factors"])))
        assert_close(row["eta2_generalized"], e["eta2_generalized_observed"], f"{e['effect']} ges (observed gender)")
