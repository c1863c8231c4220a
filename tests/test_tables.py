"""ANOVA tables: the paper's layout in md / tex / csv / html / json, significance filter, p formatting."""

from __future__ import annotations

import csv
import io
import json
import re
from pathlib import Path

import pandas as pd
import pytest

from analysis.anova import EFFECT_COLUMNS, anova
from analysis.errors import AnalysisError
from analysis.posthoc import tukey_all
from analysis.tables import FORMATS, format_p, render

FIXTURES = Path(__file__).parent / "fixtures" / "anova"
DESIGN_KEYS = {"effect", "factors", "ss", "df1", "df2", "ms", "mse", "F", "p", "eta2_partial", "eta2_generalized",
               "noncentrality", "power", "eps_gg", "p_gg", "eps_hf", "p_hf", "mauchly_w", "mauchly_p", "posthoc",
               "summary"}


@pytest.fixture(scope="module")
def table():
    d = pd.read_csv(FIXTURES / "exp1.csv")
    t = anova(d, "rating", "participant", ["GAIT", "BODY", "MOTION"], ["SEX"])
    tukey_all(t, abbreviations={"GAIT": {"W": "W", "J": "J"}})
    return t


def test_format_p_like_the_paper():
    assert format_p(0.0004) == "<0.001"
    assert format_p(0.004) == "<0.01"
    assert format_p(0.04) == "<0.05"
    assert format_p(0.07) == "0.070"
    assert format_p(0.5) == "0.50"
    assert format_p(float("nan")) == ""


def md_name(effect: str) -> str:
    """An effect as the md table shows it: ``GAIT:SEX`` as ``GAIT\\*SEX`` (stars escaped: not emphasis)."""
    return effect.replace(":", "\\*")


def test_markdown_groups_and_significant_only(table):
    md = render(table, "md")
    sig = table.significant()
    assert "| *Main effects* |" in md and "| *Two-way interaction effects* |" in md
    for name in table.effects.index:
        shown = f"| {md_name(name)} |" in md
        assert shown == (name in sig), name
    assert "| GAIT | 14.28 | 1, 14 | 14.28 | 33.76 | <0.001 | 0.71 | 33.76 | 1.00 | W > J |" in md
    assert "Error(" not in md


def test_all_rows_include_every_effect_and_strata(table):
    md = render(table, "md", all_rows=True)
    for name in table.effects.index:
        assert f"| {md_name(name)} |" in md
    assert "| *Four-way interaction effects* |" in md
    for label in table.strata.index:
        assert f"| {label} |" in md


def test_correction_changes_p_and_dof(table):
    md = render(table, "md", all_rows=True, correction="gg")
    row = table.effect("BODY:MOTION")
    assert f"{9 * row['eps_gg']:.2f}, {126 * row['eps_gg']:.2f}" in md
    assert "| ε |" in md
    with pytest.raises(AnalysisError):
        render(table, "md", correction="box")


def test_latex_booktabs(table):
    tex = render(table, "tex")
    for cmd in (r"\toprule", r"\midrule", r"\bottomrule", r"\begin{tabular}", r"\caption{"):
        assert cmd in tex
    assert r"BODY$\times$SEX" in tex
    assert r"W $>$ J" in tex and r"$<$0.001" in tex
    assert "η" not in tex and "α" not in tex  # no raw Unicode math for pdflatex


def test_html_escapes_and_breaks_summaries(table):
    html = render(table, "html")
    assert html.lstrip().startswith('<table class="anova">')
    assert "W &gt; J" in html and "&lt;0.001" in html
    assert "<br>" in html  # multi-part post-hoc summaries on separate lines


def test_csv_exact_numbers(table):
    text = render(table, "csv", all_rows=True)
    rows = list(csv.DictReader(io.StringIO(text)))
    effects = [r for r in rows if r["section"] != "Error"]
    assert len(effects) == len(table.effects)
    for r in effects:
        want = table.effects.loc[r["effect"]]
        for c in ("ss", "F", "p", "eta2_partial", "power"):
            assert float(r[c]) == float(want[c])  # repr round-trip: exact
    errors = [r for r in rows if r["section"] == "Error"]
    assert [r["effect"] for r in errors] == list(table.strata.index)


def test_json_is_the_design_schema(table):
    recs = json.loads(render(table, "json"))
    assert recs == json.loads(table.to_json())
    assert len(recs) == len(table.effects)  # JSON is always complete
    for r in recs:
        assert set(r) == DESIGN_KEYS
        if r["df1"] == 1:
            assert r["eps_gg"] is None and r["mauchly_w"] is None
    gait = next(r for r in recs if r["effect"] == "GAIT")
    assert gait["summary"] == "W > J"
    assert set(gait["posthoc"][0]) >= {"a", "b", "diff", "q", "p", "se", "df", "t", "lower", "upper", "kind"}
    assert set(EFFECT_COLUMNS) < DESIGN_KEYS


def test_all_formats_render_and_unknown_format(table):
    for fmt in FORMATS:
        assert render(table, fmt).strip()
    assert render(table, "markdown") == render(table, "md")
    with pytest.raises(AnalysisError, match="unknown table format"):
        render(table, "xlsx")


def test_nothing_significant_says_so():
    d = pd.read_csv(FIXTURES / "onewithin.csv")
    t = anova(d, "rt", "subject", ["cond"], alpha=0.05)
    md = render(t, "md", alpha=0.001)
    assert "No effect reaches p < 0.001" in md
    assert "No effect reaches" in render(t, "html", alpha=0.001)


def test_deterministic_output(table):
    assert render(table, "csv", all_rows=True) == render(table, "csv", all_rows=True)


# -- walkthrough: rounding noise, untestable effects, Tukey without a difference -----------------------------

def constant_sum_table():
    """2AFC percentages (% capture + % synth = 100 in every cell; the walkthrough's 8 participants): VIEW,
    BODY and BODY:VIEW are 0/0, and BODY:SOURCE:VIEW is 0 up to rounding noise."""
    sixths = {"side": [(3, 2), (1, 2), (3, 5), (1, 1)], "oblique": [(4, 2), (3, 2), (2, 5), (2, 4)]}
    rows = []
    for view, people in sixths.items():
        for s, (heavy, thin) in enumerate(people):
            for body, x in (("Heavy", heavy * 100 / 6), ("Thin", thin * 100 / 6)):
                rows += [(f"{view}{s}", view, body, "capture", x), (f"{view}{s}", view, body, "synth", 100 - x)]
    d = pd.DataFrame(rows, columns=["participant", "VIEW", "BODY", "SOURCE", "percent"])
    return anova(d, "percent", "participant", ["BODY", "SOURCE"], ["VIEW"])


def test_rounding_noise_prints_as_zero_and_untestable_effects_as_dashes():
    table = constant_sum_table()
    assert 0 < abs(table.effects.loc["BODY:SOURCE:VIEW", "ss"]) < 1e-20     # noise, not an exact 0
    assert 0 < table.strata.loc["Error", "ss"] < 1e-20
    md = render(table, "md", all_rows=True)
    assert not re.search(r"\de-\d", md)                                       # no 2.6e-29 anywhere
    assert "| BODY\\*SOURCE\\*VIEW | 0.00 | 1, 6 | 0.00 | 0.00 | 1.00 | 0.00 | 0.00 | 0.05 |" in md
    assert "| VIEW | 0.00 | 1, 6 | 0.00 | — | — | — | — | — |" in md
    assert "| Error | 0.00 | 6 | 0.00 |" in md and "| Error(BODY) | 0.00 | 6 | 0.00 |" in md
    rows = {r["effect"]: r for r in csv.DictReader(io.StringIO(render(table, "csv", all_rows=True)))}
    assert float(rows["BODY:SOURCE:VIEW"]["ss"]) == table.effects.loc["BODY:SOURCE:VIEW", "ss"]   # CSV stays exact


def test_error_term_without_variance_prints_infinite_f():
    """Every subject shows the same BODY pattern: Error(BODY) is rounding noise, BODY's F is infinite."""
    d = pd.DataFrame([(s, b, s * 0.7 + e) for s in range(6) for b, e in (("a", 0), ("b", 1), ("c", 3))],
                     columns=["subject", "BODY", "y"])
    table = anova(d, "y", "subject", ["BODY"])
    assert "| BODY | 28.00 | 2, 10 | 14.00 | ∞ | <0.001 | 1.00 | ∞ | 1.00 |" in render(table, "md")
    assert r"$\infty$" in render(table, "tex") and "∞" not in render(table, "tex")


def test_tukey_without_a_significant_pair_says_ns(table):
    md = render(table, "md", all_rows=True)
    assert "n.s." not in md                     # Tukey ran only on the significant effects
    tukey_all(table, effects=["SEX"])           # not significant: no pair differs
    assert table.posthoc["SEX"].summary == ""   # the API keeps "" (DESIGN.md), the tables say n.s.
    row = next(line for line in render(table, "md", all_rows=True).splitlines() if line.startswith("| SEX |"))
    assert row.endswith("| n.s. |")
    assert "n.s." in render(table, "html", all_rows=True) and "n.s." in render(table, "tex", all_rows=True)
    untested = constant_sum_table()
    tukey_all(untested, effects=["VIEW"])
    assert "| VIEW | 0.00 | 1, 6 | 0.00 | — | — | — | — | — | — |" in render(untested, "md", all_rows=True)
