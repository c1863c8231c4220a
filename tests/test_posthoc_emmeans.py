"""Post-hoc follow-ups against emmeans on afex fits (tests/fixtures/make_posthoc_fixtures.R).

Three designs (an unbalanced split-plot with two within factors and a 3-level between factor; two between
factors with unequal cells and one within factor; repeated measures only), every main effect and
interaction, emmeans' ``model = "univariate"`` and ``"multivariate"``, adjustments tukey / holm /
bonferroni / none, equal-weight and (where an effect averages over a between factor) observed means.

Tolerances: estimates, SE, df and t to 1e-9 relative (seen: ≤ 4e-14 absolute); p-values to 1e-6 absolute
(seen: ≤ 3e-8 with Tukey, the accuracy of R's ptukey quadrature; ≤ 3e-14 otherwise); confidence limits
to 1e-9 relative, except Tukey's to 1e-6 absolute (seen: ≤ 1.3e-7; R's qtukey stops its secant iteration
at |Δq| < 1e-4, so R's own limits are the less accurate ones: scipy's studentized_range.isf agrees with
ours to 1e-9, tests/test_posthoc.py).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.anova import anova
from analysis.posthoc import posthoc

FIXTURES = Path(__file__).parent / "fixtures" / "posthoc"
NAMES = ["unbal3", "between2", "within2"]


@pytest.fixture(scope="module", params=NAMES)
def case(request):
    fx = json.loads((FIXTURES / f"{request.param}.json").read_text())
    d = fx["design"]
    data = pd.read_csv(FIXTURES / f"{request.param}.csv")
    as_list = (lambda v: [] if v is None else [v] if isinstance(v, str) else list(v))
    return fx, anova(data, "y", "subject", as_list(d["within"]), as_list(d["between"]))


def _match(res, ref_pairs):
    """Our pair row and the sign (+1 when emmeans' a − b is our a − b) of every emmeans pair."""
    facs = res.factors
    label = {tuple(row[f] for f in facs): lab for lab, row in res.means.iterrows()}
    rows = {(a, b): i for i, (a, b) in enumerate(zip(res.pairs["a"], res.pairs["b"]))}
    for ref in ref_pairs:
        a, b = label[tuple(ref["a"][f] for f in facs)], label[tuple(ref["b"][f] for f in facs)]
        yield (rows[(a, b)], 1.0) if (a, b) in rows else (rows[(b, a)], -1.0)


def test_pairs_equal_emmeans(case):
    fx, table = case
    seen = 0
    for r in fx["results"]:
        effect = r["effect"] if isinstance(r["effect"], str) else ":".join(r["effect"])
        res = posthoc(table, effect, followup=r["model"], adjust=r["adjust"], means=r["means"])
        pr = res.pairs
        assert len(pr) == len(r["pairs"])
        for (row, sign), ref in zip(_match(res, r["pairs"]), r["pairs"]):
            what = f"{fx['design']['name']} {effect} {r['model']} {r['adjust']} {r['means']} {ref['contrast']}"
            assert sign * pr.at[row, "diff"] == pytest.approx(ref["estimate"], rel=1e-9, abs=1e-12), what
            assert pr.at[row, "se"] == pytest.approx(ref["se"], rel=1e-9), what
            assert pr.at[row, "df"] == pytest.approx(ref["df"], rel=1e-9), what
            assert sign * pr.at[row, "t"] == pytest.approx(ref["t"], rel=1e-9, abs=1e-12), what
            assert pr.at[row, "p"] == pytest.approx(ref["p"], abs=1e-6), what
            lo, hi = (pr.at[row, "lower"], pr.at[row, "upper"]) if sign > 0 else \
                (-pr.at[row, "upper"], -pr.at[row, "lower"])
            tol = 1e-6 if r["adjust"] == "tukey" and len(pr) > 1 else 1e-9 * abs(ref["lower"]) + 1e-12
            assert abs(lo - ref["lower"]) <= tol and abs(hi - ref["upper"]) <= tol, what
            seen += 1
    assert seen == sum(len(r["pairs"]) for r in fx["results"]) > 100


def test_means_equal_emmeans(case):
    """Cell means equal emmeans' multivariate ones (1e-10). emmeans' univariate (aovlist) means carry the
    n-weighted grand mean as intercept — its own warning "EMMs are biased unless design is perfectly
    balanced" — so they differ from ours by one constant per design, which cancels in every pair."""
    fx, table = case
    for r in fx["results"]:
        if r["adjust"] != "none":
            continue
        effect = r["effect"] if isinstance(r["effect"], str) else ":".join(r["effect"])
        res = posthoc(table, effect, followup=r["model"], means=r["means"])
        ours = res.means.set_index(list(res.factors))["mean"]
        diff = np.array([c["emmean"] - ours.loc[tuple(c["levels"][f] for f in res.factors)] for c in r["cells"]])
        if r["model"] == "multivariate":
            assert np.allclose(diff, 0.0, atol=1e-10)
        else:
            assert np.ptp(diff) < 1e-10
