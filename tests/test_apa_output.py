"""ANOVA output a researcher can paste into a paper: APA p and sentences, SPSS's nc/power on corrected rows, .docx
tables, Markdown that escapes user text, and the simulated-data banner (issue 19 "APA-ready output", items 4–5;
issue 26 item 8)."""

from __future__ import annotations

import csv
import io
import math
import re
from pathlib import Path

import docx
import pandas as pd
import pytest
from scipy import stats

from analysis.anova import anova, reported_statistics
from analysis.errors import AnalysisError
from analysis.posthoc import tukey_all
from analysis.result_tables import ResultTable, render_results
from analysis.tables import SIMULATED_BANNER, apa_sentence, format_p_apa, md_escape, render

FIXTURES = Path(__file__).parent / "fixtures" / "anova"
EXP1 = ["--dv", "rating", "--subject", "participant", "--within", "GAIT", "BODY", "MOTION", "--between", "SEX"]
XSS = "<img src=x onerror=alert(1)>"


@pytest.fixture(scope="module")
def exp1():
    d = pd.read_csv(FIXTURES / "exp1.csv")
    return anova(d, "rating", "participant", ["GAIT", "BODY", "MOTION"], ["SEX"])


# -- SPSS's reading of nc and observed power on corrected rows ----------------------------------------------

@pytest.mark.parametrize("correction,eps_key", [("gg", "eps_gg"), ("hf", "eps_hf")])
def test_corrected_rows_scale_df_and_noncentrality_by_epsilon_as_spss(exp1, correction, eps_key):
    """λ = F·df1·ε and power of the non-central F with df1·ε, df2·ε — computed here with scipy.stats, not the
    engine's special.ncfdtr; the uncorrected reading keeps the sphericity-assumed λ and power."""
    checked = 0
    for name, row in exp1.effects.iterrows():
        eps = row[eps_key]
        got = reported_statistics(row, correction, "spss", exp1.alpha)
        if math.isnan(eps):   # 1-df effects: nothing to correct
            assert (got["nc"], got["power"]) == (row["noncentrality"], row["power"])
            continue
        d1, d2 = row["df1"] * eps, row["df2"] * eps
        assert got["df1"] == pytest.approx(d1, rel=1e-14) and got["df2"] == pytest.approx(d2, rel=1e-14)
        assert got["nc"] == pytest.approx(row["F"] * d1, rel=1e-14)
        want = stats.ncf.sf(stats.f.ppf(1 - exp1.alpha, d1, d2), d1, d2, row["F"] * d1)
        assert got["power"] == pytest.approx(want, rel=1e-9, abs=1e-12), name
        assert got["p"] == row["p_gg" if correction == "gg" else "p_hf"]
        old = reported_statistics(row, correction, "uncorrected", exp1.alpha)
        assert (old["nc"], old["power"], old["df1"]) == (row["noncentrality"], row["power"], d1)
        if eps < 0.999:
            assert got["power"] < row["power"] or row["power"] > 0.9999   # fewer df: less power
        checked += 1
    assert checked >= 8


def test_spss_reading_on_a_hand_computed_example():
    """F = 4, df 2 and 20, ε = 0.6: SPSS prints df 1.2 and 12, λ = 4·2·0.6 = 4.8 and the power of F(1.2, 12; 4.8)."""
    row = pd.Series({"F": 4.0, "df1": 2.0, "df2": 20.0, "p": stats.f.sf(4.0, 2, 20), "noncentrality": 8.0,
                     "power": 0.65, "eps_gg": 0.6, "p_gg": stats.f.sf(4.0, 1.2, 12), "eps_hf": 0.7, "p_hf": 0.05})
    got = reported_statistics(row, "gg")
    assert (got["df1"], got["df2"], got["nc"]) == pytest.approx((1.2, 12.0, 4.8))
    assert got["power"] == pytest.approx(stats.ncf.sf(stats.f.ppf(0.95, 1.2, 12), 1.2, 12, 4.8), rel=1e-9)
    with pytest.raises(AnalysisError, match="corrected-power"):
        reported_statistics(row, "gg", "both")


def test_corrected_df_and_p_equal_a_published_spss_table():
    """SPSS GLM output for 5 subjects × 3 conditions (UCLA ATS "Repeated measures ANOVA in SPSS" code fragment,
    Example 1): F = 4.725; Greenhouse–Geisser df 1.269, 5.075, p .077; Huynh–Feldt 1.590, 6.361, p .060; ε .634 and
    .795. (That output has no nc/power columns; those are checked against scipy above.)"""
    rows = [(1, 100, 90, 130), (2, 90, 100, 100), (3, 110, 110, 109), (4, 100, 90, 109), (5, 100, 100, 130)]
    d = pd.DataFrame([(s, f"c{i}", v) for s, *vals in rows for i, v in enumerate(vals)],
                     columns=["subject", "cond", "y"])
    row = anova(d, "y", "subject", ["cond"]).effect("cond")
    assert round(row["F"], 3) == 4.725 and (round(row["eps_gg"], 3), round(row["eps_hf"], 3)) == (0.634, 0.795)
    for correction, want in (("gg", (1.269, 5.075, 0.077)), ("hf", (1.590, 6.361, 0.060))):
        got = reported_statistics(row, correction)
        assert (round(got["df1"], 3), round(got["df2"], 3), round(got["p"], 3)) == want


def test_tables_print_the_corrected_nc_and_power(exp1):
    row = exp1.effect("BODY:MOTION")
    spss = reported_statistics(row, "gg", "spss", exp1.alpha)
    md = render(exp1, "md", correction="gg")
    line = next(x for x in md.splitlines() if x.startswith("| BODY\\*MOTION |"))
    assert f"| {spss['nc']:.2f} |" in line and f"{row['noncentrality']:.2f}" not in line
    assert "nc and power from the corrected dof, as SPSS" in md
    old = render(exp1, "md", correction="gg", corrected_power="uncorrected")
    assert f"| {row['noncentrality']:.2f} |" in next(x for x in old.splitlines() if x.startswith("| BODY\\*MOTION |"))
    rows = {r["effect"]: r for r in csv.DictReader(io.StringIO(render(exp1, "csv", correction="gg")))}
    assert float(rows["BODY:MOTION"]["nc_reported"]) == spss["nc"]
    assert float(rows["BODY:MOTION"]["power_reported"]) == spss["power"]
    assert float(rows["BODY:MOTION"]["noncentrality"]) == row["noncentrality"]   # the engine's column unchanged


# -- APA p and sentences ---------------------------------------------------------------------------------------

def test_apa_p_never_prints_zero_and_has_no_leading_zero():
    assert [format_p_apa(p) for p in (0.0, 1e-300, 0.000999, 0.001, 0.0312, 0.5, 1.0)] == \
        ["< .001", "< .001", "< .001", ".001", ".031", ".500", "> .999"]
    assert format_p_apa(float("nan")) == ""


def test_apa_sentence_uses_corrected_df(exp1):
    md = render(exp1, "md", correction="gg")
    row = exp1.effect("BODY:SEX")
    rep = reported_statistics(row, "gg", "spss", exp1.alpha)
    sentence = apa_sentence({"F": row["F"], **rep}, row["eta2_partial"], "md")
    assert f"- BODY × SEX: {sentence}" in md
    assert sentence.startswith(f"*F*({rep['df1']:.2f}, {rep['df2']:.1f}) = {row['F']:.2f}, *p* < .001, ηp² = .")
    assert "APA-style report (Greenhouse–Geisser corrected):" in md
    gait = apa_sentence({"F": 33.76, "df1": 1.0, "df2": 14.0, "p": 4.5e-5}, 0.7069)
    assert gait == "F(1, 14) = 33.76, p < .001, ηp² = .71"
    html = render(exp1, "html")
    assert "<li>GAIT: <i>F</i>(1, 14) = 33.76, <i>p</i> &lt; .001, ηp² = .71</li>" in html
    assert "0.000" not in md and "0.000" not in html


def test_apa_style_table(exp1):
    md = render(exp1, "md", style="apa")
    assert "| GAIT | 14.28 | 1, 14 | 14.28 | 33.76 | < .001 | .71 | 33.76 | 1.00 |" in md
    with pytest.raises(AnalysisError, match="style"):
        render(exp1, "md", style="chicago")


# -- .docx ---------------------------------------------------------------------------------------------------

def test_docx_cells_and_apa_sentences(exp1, tmp_path):
    from analysis.docx_tables import write_docx

    path = tmp_path / "anova.docx"
    write_docx(exp1, path, correction="gg")
    doc = docx.Document(str(path))
    grid = doc.tables[0]
    assert [c.text for c in grid.rows[0].cells][:9] == ["Effect", "SS", "dof", "MS", "F", "p", "ηp²", "nc", "power"]
    rows = {r.cells[0].text: [c.text for c in r.cells] for r in grid.rows}
    assert rows["GAIT"][1:9] == ["14.28", "1, 14", "14.28", "33.76", "< .001", ".71", "33.76", "1.00"]
    body = exp1.effect("BODY:MOTION")
    rep = reported_statistics(body, "gg", "spss", exp1.alpha)
    assert rows["BODY × MOTION"][2] == f"{rep['df1']:.2f}, {rep['df2']:.2f}"
    assert rows["BODY × MOTION"][7] == f"{rep['nc']:.2f}"
    texts = [p.text for p in doc.paragraphs]
    assert texts[0] == "Table 1" and texts[1].startswith("Mixed ANOVA of rating")
    gait = next(p for p in doc.paragraphs if p.text.startswith("GAIT: "))
    assert gait.text == "GAIT: F(1, 14) = 33.76, p < .001, ηp² = .71"
    assert [r.text for r in gait.runs if r.italic] == ["F", "p"]
    assert not any(SIMULATED_BANNER in t for t in texts)
    write_docx(exp1, path, simulated=True)
    assert docx.Document(str(path)).paragraphs[0].text == SIMULATED_BANNER


def test_cli_writes_docx_and_refuses_docx_on_stdout(run_cli, tmp_path):
    out = tmp_path / "F.docx"
    code, _, err = run_cli("anova", FIXTURES / "exp1.csv", *EXP1, "--format", "docx", "--out", out,
                           "--correction", "hf")
    assert code == 0, err
    doc = docx.Document(str(out))
    assert any(p.text.startswith("APA-style report (Huynh–Feldt corrected)") for p in doc.paragraphs)
    code, out_text, err = run_cli("anova", FIXTURES / "exp1.csv", *EXP1, "--format", "docx")
    assert code == 2 and "--out" in err and not out_text


# -- Markdown escaping (issue 26 item 8) ------------------------------------------------------------------------

def test_markdown_escape_keeps_markup_out():
    assert md_escape(XSS) == "&lt;img src=x onerror=alert(1)>"
    assert md_escape("a|b\nc") == "a\\|b c"
    assert md_escape("W > J, p < .05, <0.001") == "W > J, p < .05, <0.001"   # readable where nothing can open
    for opener in ("</script>", "<!-- x -->", "<?php", "<https://x.org>", "<svg/onload=alert(1)>"):
        assert "<" not in md_escape(opener)[:1] and md_escape(opener).startswith("&lt;")


def test_abbreviation_with_html_lands_escaped_in_anova_markdown(exp1):
    """An abbreviation (user text) that is an HTML tag: no raw tag in the md table (today's code wrote it raw)."""
    tukey_all(exp1, effects=["GAIT"], abbreviations={"GAIT": {"W": XSS, "J": "a|b"}})
    md = render(exp1, "md", all_rows=True)
    assert "<img" not in md and "&lt;img src=x onerror=alert(1)>" in md
    row = next(x for x in md.splitlines() if x.startswith("| GAIT |"))
    assert row.count(" | ") == md.splitlines()[2].count(" | ")   # a|b did not add a column
    assert "<img" not in render(exp1, "html", all_rows=True)
    exp1.posthoc.clear()


def test_factor_names_and_labels_with_html_are_escaped_in_markdown(tmp_path):
    d = pd.read_csv(FIXTURES / "mixed11.csv").rename(columns={"group": "<b>grp</b>"})
    t = anova(d, "score", "subject", ["time"], ["<b>grp</b>"])
    md = render(t, "md", all_rows=True)
    assert "<b>" not in md and "&lt;b>grp&lt;/b>" in md
    people = pd.DataFrame({"participant": [XSS, "p|2"], "left": [3, 1], "p": [0.5, 0.04]})
    text = render_results([ResultTable("position_participants", f"Choices per {XSS}", people)], "md")
    assert "<img" not in text and "p\\|2" in text


def test_position_bias_markdown_escapes_position_labels():
    """position_bias.md: the design's position labels (user text) are headers of its tables."""
    from analysis.position_bias import position_tables

    counts = pd.DataFrame({XSS: [6, 5, 7], "right": [2, 3, 1]}, index=["1", "2", "3"])
    text = render_results(position_tables(counts, 0.05), "md")
    assert "<img" not in text and "&lt;img" in text


# -- simulated responses say so --------------------------------------------------------------------------------

def test_simulated_banner_on_markdown_html_and_tex(exp1):
    for fmt, start in (("md", f"> **{SIMULATED_BANNER}**"), ("html", '<p class="simulated">'),
                       ("tex", r"\noindent\textbf{SIMULATED DATA")):
        assert render(exp1, fmt, simulated=True).startswith(start)
        assert "SIMULATED" not in render(exp1, fmt)
    assert "SIMULATED" not in render(exp1, "csv", simulated=True)   # data files stay data


@pytest.fixture(scope="module")
def onewithin_design(tmp_path_factory):
    from analysis.io_design import load_design
    from stimuli.cli import main

    folder = tmp_path_factory.mktemp("exp2")
    root = Path(__file__).resolve().parents[1]
    assert main(["design", str(root / "protocols" / "exp2_com_vs_average.yaml"), "--participants", "4",
                 "--out", str(folder)]) == 0
    return load_design(folder)


@pytest.mark.parametrize("fmt,suffix", [("long", ".csv"), ("qualtrics", ".csv"), ("qualtrics-legacy", ".csv"),
                                        ("jspsych", ".csv"), ("jspsych", ".json")])
def test_simulated_marker_survives_every_export_and_import(onewithin_design, fmt, suffix, tmp_path):
    from analysis.io_writers import export_text
    from analysis.model_spec import load_model
    from analysis.responses import import_responses
    from analysis.simulate import SIMULATED_COLUMN, simulate_responses, simulated_export

    design = onewithin_design
    sim = simulate_responses(design, load_model(None, design), 4, seed=1)
    path = tmp_path / f"r{suffix}"
    path.write_text(export_text(sim, design, fmt.replace("-json", ""), suffix, seed=1))
    assert simulated_export(path)
    imported = import_responses(path, design)
    assert imported.reconciles and "column not imported" not in set(imported.exclusions["reason"])
    real = tmp_path / f"real{suffix}"   # the same export without the marker: a real file, imported alike
    real.write_text(export_text(sim.drop(columns=[SIMULATED_COLUMN]), design, fmt, suffix, seed=1))
    assert not simulated_export(real)
    again = import_responses(real, design)
    pd.testing.assert_frame_equal(again.data.drop(columns=["row"], errors="ignore"),
                                  imported.data.drop(columns=["row"], errors="ignore"))


def test_report_of_simulated_responses_says_so_at_the_top(onewithin_design, tmp_path, run_cli):
    from analysis.io_writers import export_text
    from analysis.model_spec import load_model
    from analysis.report import analyze
    from analysis.simulate import SIMULATED_COLUMN, simulate_responses

    design = onewithin_design
    sim = simulate_responses(design, load_model(None, design), 4, seed=2)
    (tmp_path / "sim.csv").write_text(export_text(sim, design, "qualtrics", seed=2))
    summary = analyze(design.directory, tmp_path / "sim.csv", tmp_path / "report", models=False)
    report = tmp_path / "report"
    html = (report / "report.html").read_text(encoding="utf-8")
    body = html[html.index("<body>"):]
    assert re.match(r"<body>\s*<p class=\"simulated\"", body) and summary["simulated"] is True
    for name in ("anova.md", "anova_all.md", "anova_gg.md"):
        assert (report / name).read_text().startswith("> **SIMULATED DATA")
    assert docx.Document(str(report / "anova.docx")).paragraphs[0].text == SIMULATED_BANNER
    apa = summary["sections"][0]["results"]["apa"]
    assert apa and all(s.startswith("F(") for s in apa.values())
    (tmp_path / "real.csv").write_text(export_text(sim.drop(columns=[SIMULATED_COLUMN]), design, "qualtrics", seed=2))
    summary = analyze(design.directory, tmp_path / "real.csv", tmp_path / "report2", models=False)
    assert summary["simulated"] is False
    assert "SIMULATED" not in (tmp_path / "report2" / "report.html").read_text(encoding="utf-8")
    assert "SIMULATED" not in (tmp_path / "report2" / "anova.md").read_text()
    for name, says in (("sim.csv", True), ("real.csv", False)):   # and the terminal says it too
        code, out, err = run_cli("analyze", design.directory, "--responses", tmp_path / name, "--out",
                                 tmp_path / f"cli_{name}", "--no-models")
        assert code == 0, err
        assert ("SIMULATED DATA" in out) is says
