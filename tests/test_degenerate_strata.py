"""Degenerate error strata (no error variance, up to rounding) and the audit's other findings.

- ε, Mauchly and corrected p are NaN where a stratum's error SSCP is singular (R car/afex: NA);
- an effect over an error of pure rounding noise has F = ∞, p = 0, power = 1, in the engine, the JSON and
  the tables alike;
- Tukey does not test against such an error (q = 1e16 against MSE = 1e-31 was reported as p = 0);
- Tukey pairs of a mixed effect that differ only in between-subjects levels are marked;
- the report says which participant × cell values rest on fewer answers than the design plans.
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.anova import anova, anova_many
from analysis.anova_core import Design
from analysis.posthoc import tukey, tukey_all
from analysis.tables import render

FIXTURES = Path(__file__).parent / "fixtures" / "anova"
DATA = Path(__file__).parent / "data" / "responses"
ROOT = Path(__file__).resolve().parents[1]
SPHERICITY = ["eps_gg", "eps_hf", "p_gg", "p_hf", "mauchly_w", "mauchly_p"]
NO_ERROR = ["W", "W:G", "W:V", "W:V:G"]   # Error(W) and Error(W:V) are 0 up to rounding


# the audit's C.csv: (subject, group, y at W = a / V = x, V offset); y = that + shift(W) + offset at V = y
C_SUBJECTS = [("s0", "g1", 2, 2), ("s1", "g1", 3, 0), ("s2", "g1", 1, 1), ("s3", "g1", 3, 2), ("s4", "g2", 2, 2),
              ("s5", "g2", 3, 2), ("s6", "g2", 3, 2), ("s7", "g2", 3, 2), ("s8", "g2", 1, 0), ("s9", "g2", 3, 1)]


def audit_c(scale: float = 1.0) -> pd.DataFrame:
    """The audit's C.csv: 10 subjects (G 4/6), y = subject intercept + shift(W) + a subject-specific V offset,
    so Error(W) and Error(W:V) have no variance at all (R afex: error SS 0, ε and Mauchly NA)."""
    rows = [(s, g, w, v, scale * (base + shift + (off if v == "y" else 0)))
            for s, g, base, off in C_SUBJECTS for w, shift in (("a", 0), ("b", 1), ("c", 2)) for v in ("x", "y")]
    return pd.DataFrame(rows, columns=["subj", "G", "W", "V", "y"])


def table_c(scale: float = 1.0):
    return anova(audit_c(scale), "y", "subj", ["W", "V"], ["G"])


# -- 1. sphericity from a singular error SSCP ----------------------------------------------------------------

@pytest.mark.parametrize("scale", [1.0, 1e-6, 1e6])
def test_no_sphericity_statistics_from_a_stratum_without_error_variance(scale):
    table = table_c(scale)
    assert table.strata.loc["Error(W)", "ss"] < 1e-20 * scale**2          # rounding noise, not exact 0
    for effect in NO_ERROR:
        row = table.effects.loc[effect]
        assert all(math.isnan(row[c]) for c in SPHERICITY), (effect, row[SPHERICITY].tolist())
    recs = {r["effect"]: r for r in table.to_records()}
    assert all(recs[e][c] is None for e in NO_ERROR for c in SPHERICITY)


def test_singular_error_shows_dash_for_epsilon_and_uncorrected_dof():
    table = table_c()
    md = render(table, "md", all_rows=True, correction="gg")
    assert "1.24, 9.94" not in md and "0.621" not in md and "0.846" not in md
    assert "| W | 38.40 | 2, 16 | 19.20 | ∞ | <0.001 | 1.00 | ∞ | 1.00 | — |" in md
    assert "| W\\*V | 0.00 | 2, 16 | 0.00 | — | — | — | — | — | — |" in md
    assert "| V | 27.23 | 1, 8 | 27.23 | 23.23 | <0.01 | 0.74 | 23.23 | 0.99 |  |" in md   # d = 1: no ε, blank
    assert render(table, "md", all_rows=True) == render(table_c(), "md", all_rows=True)   # no ε column: unchanged


def test_partially_singular_error_sscp_has_no_sphericity_statistics():
    """Error variance along one W contrast only (b − a is the same for everyone): F is finite, but ε and
    Mauchly would come from a rank-deficient SSCP (W ≈ 1e-31)."""
    rng = np.random.default_rng(1)
    rows = []
    for s in range(8):
        base, c = rng.normal() * 3, rng.normal()
        rows += [(s, "a", base), (s, "b", base + 1), (s, "c", base + 2 + c)]
    d = pd.DataFrame(rows, columns=["subj", "W", "y"])
    row = anova(d, "y", "subj", ["W"]).effect("W")
    assert np.isfinite(row["F"]) and row["F"] > 1
    assert all(math.isnan(row[c]) for c in SPHERICITY)


def test_vectorised_engine_agrees_and_ordinary_data_keep_their_epsilon():
    table = table_c()
    design = Design(within=table.design.within, between=table.design.between, groups=table.design.groups)
    rng = np.random.default_rng(0)
    Y = np.stack([table.Y, table.Y + rng.normal(size=table.Y.shape)])
    res = anova_many(Y, design, power=True)
    eps = res.frame("eps_gg")
    assert eps.loc[0, NO_ERROR].isna().all() and eps.loc[1, NO_ERROR].notna().all()
    assert res.frame("F").loc[0, "W"] == np.inf and res.frame("power").loc[0, "W"] == 1.0


def test_fewer_error_df_than_contrasts_still_reports_epsilon():
    """n < d: the SSCP is singular by construction; ε stays (as before), Mauchly is NaN."""
    rng = np.random.default_rng(2)
    d = pd.DataFrame([(s, a, b, rng.normal()) for s in range(5) for a in "pqrs" for b in "uvwx"],
                     columns=["subj", "A", "B", "y"])
    row = anova(d, "y", "subj", ["A", "B"]).effect("A:B")     # d = 9 > 4 error df
    assert 0 < row["eps_gg"] <= 1 and math.isnan(row["mauchly_w"])


# -- 3. F = ∞ where only the error is noise: engine, JSON and tables agree -------------------------------------

def test_infinite_f_is_infinite_in_the_engine_and_json_and_tables():
    table = table_c()
    row = table.effect("W")
    assert row["F"] == np.inf and row["p"] == 0.0 and row["power"] == 1.0 and row["eta2_partial"] == 1.0
    rec = next(r for r in json.loads(table.to_json()) if r["effect"] == "W")
    assert rec["F"] is None and rec["noncentrality"] is None          # JSON has no ∞
    assert rec["p"] == 0.0 and rec["power"] == 1.0 and rec["eta2_partial"] == 1.0
    untestable = next(r for r in table.to_records() if r["effect"] == "W:G")
    assert untestable["F"] is None and untestable["p"] is None and untestable["power"] is None
    assert "| W | 38.40 | 2, 16 | 19.20 | ∞ | <0.001 | 1.00 | ∞ | 1.00 |" in render(table, "md", all_rows=True)
    rows = {r["effect"]: r for r in csv.DictReader(io.StringIO(render(table, "csv", all_rows=True)))}
    assert rows["W"]["F"] == "inf" and rows["W"]["power"] == "1.0"


# -- 2. Tukey against an error without variance ------------------------------------------------------------

def test_tukey_does_not_test_against_an_error_without_variance():
    table = table_c()
    tukey_all(table, effects=["G", "W", "W:G", "W:V", "V:G"])
    for effect in ("W", "W:G", "W:V"):
        ph = table.posthoc[effect]
        assert ph.untestable and "no variance" in ph.untestable
        assert ph.summary == "" and not ph.pairs["significant"].any()
        assert ph.pairs["q"].isna().all() and ph.pairs["p"].isna().all()
        assert ph.pairs["diff"].notna().all()                           # the differences are still given
    g1a_g2a = table.posthoc["W:G"].pairs.set_index(["a", "b"]).loc[("g1/a", "g2/a")]
    assert math.isnan(g1a_g2a["q"])                                     # was q = 2.16e15, p = 0
    assert table.posthoc["G"].untestable == "" and table.posthoc["V:G"].pairs["q"].notna().all()

    recs = {r["effect"]: r for r in json.loads(render(table, "json"))}
    for effect in ("W", "W:G", "W:V"):
        assert recs[effect]["summary"] is None and "no variance" in recs[effect]["posthoc_untestable"]
        assert all(p["q"] is None and p["p"] is None for p in recs[effect]["posthoc"])
    assert "posthoc_untestable" not in recs["G"] and recs["G"]["summary"] == ""

    md = render(table, "md", all_rows=True)
    assert "g1/b > g1/a" not in md and "b > a" not in md
    assert md.splitlines()[0].endswith("Tukey: W, W\\*G, W\\*V not tested (—), their error term has no variance.**")
    w_row = next(line for line in md.splitlines() if line.startswith("| W |"))
    assert w_row.endswith("| — |")
    for fmt in ("tex", "html"):
        out = render(table, fmt, all_rows=True)
        assert "not tested" in out and "g1/b &gt; g1/a" not in out and "g1/b $>$ g1/a" not in out
    rows = {r["effect"]: r for r in csv.DictReader(io.StringIO(render(table, "csv", all_rows=True)))}
    assert rows["W:G"]["posthoc"].startswith("— (the error term Error(W) has no variance")
    assert rows["V:G"]["posthoc"] == table.posthoc["V:G"].summary


# -- 4. mixed effects: pairs differing in between-subjects levels are marked by their kind ------------------

def test_pairs_of_a_mixed_effect_carry_their_kind():
    d = pd.read_csv(FIXTURES / "exp1.csv")
    table = anova(d, "rating", "participant", ["GAIT", "BODY", "MOTION"], ["SEX"])
    body_sex = tukey(table, "BODY:SEX", followup="statistica")
    flagged = body_sex.pairs[body_sex.pairs["kind"] == "between"]
    levels = table.design.within["BODY"]
    assert sorted(zip(flagged["a"], flagged["b"])) == sorted((f"F/{b}", f"M/{b}") for b in levels)
    assert body_sex.records()[0]["kind"] == "within" and body_sex.unprotected   # in the JSON, and said
    assert set(tukey(table, "SEX").pairs["kind"]) == {"between"}
    assert set(tukey(table, "BODY").pairs["kind"]) == {"within"}
    three = tukey(table, "GAIT:BODY:SEX").pairs
    assert (three["kind"] == "between").sum() == 2 * len(levels)


# -- 5. the report: values resting on fewer answers than planned ------------------------------------------

def test_report_notes_cells_with_a_missing_repetition(tmp_path):
    from analysis.io_design import load_design
    from analysis.io_writers import export_text
    from analysis.model_spec import load_model
    from analysis.report import analyze
    from analysis.simulate import simulate_responses

    design = load_design(DATA / "mini_likert")
    sim = simulate_responses(design, load_model(None, design), 6, seed=2)
    frame = pd.read_csv(io.StringIO(export_text(sim, design, "long")), dtype=str, keep_default_na=False)
    frame.to_csv(tmp_path / "full.csv", index=False)
    tests = frame.index[frame["practice"].isin(["0", "False", "false"])]
    frame.drop(index=tests[[0, 7]]).to_csv(tmp_path / "missing.csv", index=False)

    full = analyze(DATA / "mini_likert", tmp_path / "full.csv", tmp_path / "full", models=False)
    assert "cells_with_fewer_answers" not in full["sections"][0]["results"]

    summary = analyze(DATA / "mini_likert", tmp_path / "missing.csv", tmp_path / "report", models=False)
    short = summary["sections"][0]["results"]["cells_with_fewer_answers"]
    cells = pd.read_csv(tmp_path / "report" / "cell_values.csv")
    assert short["count"] == 2 == int((cells["n"] < 2).sum()) and short["cells"] == len(cells)
    assert all(e["n"] == 1 and e["planned"] == 2 for e in short["examples"])
    html = (tmp_path / "report" / "report.html").read_text(encoding="utf-8")
    first = short["examples"][0]
    assert "2 of" in html and "participant × cell values rest on fewer answers than the design plans" in html
    assert f"participant {first['participant']}, {first['cell']} (1 of 2)" in html


def test_csv_writes_an_undefined_reported_p_blank_not_nan():
    """The CSV's p_reported of an untestable effect read the literal 'nan' while its other undefined cells were empty."""
    import csv
    import io

    text = render(table_c(), "csv", all_rows=True)
    rows = list(csv.DictReader(io.StringIO(text)))
    assert rows and all(r["p_reported"] != "nan" for r in rows)
    assert any(r["p_reported"] == "" for r in rows)


def test_complete_data_of_a_between_counterbalanced_design_are_not_short(tmp_path):
    """With arrangements counterbalanced between participants, each sees one arrangement per condition;
    the planned count took every arrangement and flagged all 128 values of complete Exp-2 data as short."""
    from analysis.io_design import load_design
    from analysis.io_writers import export_text
    from analysis.model_spec import load_model
    from analysis.report import analyze
    from analysis.simulate import simulate_responses
    from stimuli.cli import main

    text = (ROOT / "protocols" / "exp2_com_vs_average.yaml").read_text()
    assert "counterbalance: within" in text
    (tmp_path / "p.yaml").write_text(text.replace("counterbalance: within", "counterbalance: between"))
    assert main(["design", str(tmp_path / "p.yaml"), "--participants", "8", "--out", str(tmp_path / "d")]) == 0
    design = load_design(tmp_path / "d")
    sim = simulate_responses(design, load_model(None, design), 8, seed=2)
    (tmp_path / "r.csv").write_text(export_text(sim, design, "long"), encoding="utf-8")
    summary = analyze(tmp_path / "d", tmp_path / "r.csv", tmp_path / "report", models=False)
    assert "cells_with_fewer_answers" not in summary["sections"][0]["results"]
