"""`shapemotion analyze`: tables, figures, exclusions and a self-contained report.html (opened in Chromium)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd
import pytest

from analysis.io_design import load_design
from analysis.io_writers import export_text
from analysis.model_spec import load_model
from analysis.report import analyze, demo_report
from analysis.simulate import simulate_responses

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(__file__).parent / "data" / "responses"
CHROMIUM = Path("/usr/bin/chromium")


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    """Design dirs of the bundled protocols, simulated Qualtrics responses with a few bad rows, and reports."""
    from stimuli.cli import main
    out = {}
    for name in ["exp1_shape_motion", "exp2_com_vs_average", "thesis_pointlight", "thesis_validation"]:
        folder = tmp_path_factory.mktemp(name)
        assert main(["design", str(ROOT / "protocols" / f"{name}.yaml"), "--out", str(folder / "design")]) == 0
        design = load_design(folder / "design")
        sim = simulate_responses(design, load_model(None, design), 16, seed=8)
        text = export_text(sim, design, "qualtrics", seed=8)
        lines = text.splitlines(keepends=True)
        # an unfinished copy of the first respondent and a duplicate of the second
        unfinished = lines[3].replace(",100,", ",40,", 1).replace(",True,", ",False,", 1)
        text = "".join(lines + [unfinished, lines[4]])
        (folder / "responses.csv").write_text(text, encoding="utf-8")
        summary = analyze(folder / "design", folder / "responses.csv", folder / "report")
        out[name] = (folder, summary)
    return out


def test_exp1_report_files_tables_and_recovered_effects(reports):
    folder, summary = reports["exp1_shape_motion"]
    report = folder / "report"
    for ext in ("md", "tex", "csv", "html", "json"):
        assert (report / f"anova.{ext}").stat().st_size > 200
    for ext in ("png", "svg", "pdf"):
        assert (report / "figures" / f"figure4.{ext}").stat().st_size > 5000
    effects = {e["effect"]: e for e in json.loads((report / "anova.json").read_text())}
    assert len(effects) == 15 and effects["BODY:SEX"]["p"] < 0.001
    significant = summary["sections"][0]["results"]["significant"]
    assert {"BODY", "BODY:SEX"} <= set(significant)
    assert "Tukey" in (report / "anova.md").read_text() and "\\toprule" in (report / "anova.tex").read_text()
    models = pd.read_csv(report / "additional_models.csv")
    assert set(models["model"]) == {"linear mixed model (MixedLM, REML)", "ordinal (cumulative logit) model"}
    assert models.set_index(["model", "term"]).loc[("linear mixed model (MixedLM, REML)", "SEX:BODY"), "p"] < 0.001


def test_exclusions_are_listed_and_reconcile(reports):
    folder, summary = reports["exp2_com_vs_average"]
    imp = summary["import"]
    assert (imp["rows"], imp["imported_rows"], imp["excluded_rows"]) == (18, 16, 2)
    assert imp["excluded_by_reason"] == {"duplicate participant id": 1, "unfinished": 1}
    exclusions = pd.read_csv(folder / "report" / "exclusions.csv")
    assert exclusions["row"].tolist() == [20, 21]
    tidy = pd.read_csv(folder / "report" / "responses_tidy.csv")
    assert tidy["row"].nunique() == imp["imported_rows"] and len(tidy) == 16 * 80


def test_exp2_report_has_figure9_and_gee(reports):
    folder, summary = reports["exp2_com_vs_average"]
    results = summary["sections"][0]["results"]
    assert {"METHOD", "SEX:METHOD"} <= set(results["significant"])
    assert all("METHOD" in e["effect"] for e in results["effects"])
    assert results["posthoc"]["METHOD"] == "NC > C"  # Table 4 abbreviations from the protocol
    assert (folder / "report" / "figures" / "figure9.svg").exists()
    models = pd.read_csv(folder / "report" / "additional_models.csv").set_index(["model", "term"])
    for model in ("logistic GEE (exchangeable, robust SE)", "logistic mixed model (variational Bayes, approximate)"):
        assert models.loc[(model, "METHOD"), "p"] < 0.001 and models.loc[(model, "SEX:METHOD"), "p"] < 0.01
        assert models.loc[(model, "BODY:METHOD"), "df"] == 3


def test_vote_and_ranking_reports(reports):
    _, votes = reports["thesis_pointlight"]
    section = votes["sections"][0]["results"]
    assert section["chi2"][0]["cell"] == "all" and section["chi2"][0]["p"] < 0.001
    assert section["binomial"]["test"].startswith("binomial (58 first")
    _, ranking = reports["thesis_validation"]
    friedman = ranking["sections"][0]["results"]["friedman"]
    assert friedman["test"] == "Friedman" and friedman["n"] == 16
    assert max(friedman["mean_points"], key=friedman["mean_points"].get) == "obese_mocap"


def test_report_html_is_self_contained(reports):
    folder, _ = reports["exp1_shape_motion"]
    html = (folder / "report" / "report.html").read_text(encoding="utf-8")
    assert html.count("<img src=\"data:image/png;base64,") >= 2
    assert "src=\"figures/" not in html and "<script" not in html
    for text in ("Responses and exclusions", "18 rows in the file = 16 imported", "Additional analyses",
                 "class=\"anova\"", "statsmodels", "BODY*SEX"):
        assert text in html


def test_analyze_is_deterministic(reports, tmp_path):
    folder, _ = reports["exp2_com_vs_average"]
    analyze(folder / "design", folder / "responses.csv", tmp_path / "again")
    for name in ("anova.json", "anova.md", "exclusions.csv", "summary.json", "report.html", "figures/figure9.svg"):
        assert (tmp_path / "again" / name).read_bytes() == (folder / "report" / name).read_bytes(), name


def test_bad_responses_exit_2_without_partial_output(reports, run_cli, tmp_path):
    folder, _ = reports["exp1_shape_motion"]
    out = tmp_path / "report"
    code, _, err = run_cli("analyze", str(folder / "design"), "--responses", str(DATA / "bad_latin1.csv"),
                           "--out", str(out))
    assert code == 2 and "not UTF-8" in err
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_cli_analyze_and_demo_helper(reports, run_cli, tmp_path):
    folder, _ = reports["exp2_com_vs_average"]
    code, out, _ = run_cli("analyze", str(folder / "design"), "--responses", str(folder / "responses.csv"),
                           "--out", str(tmp_path / "r"), "--no-models")
    assert code == 0 and "16 imported, 2 excluded" in out and "METHOD" in out
    assert not (tmp_path / "r" / "additional_models.csv").exists()
    html = demo_report(folder / "design", tmp_path / "demo", participants=8, seed=3, fmt="jspsych")
    assert html.exists() and (tmp_path / "demo" / "responses.csv").exists()


@pytest.mark.skipif(not CHROMIUM.exists(), reason="Debian chromium is not installed (/usr/bin/chromium); "
                                                   "add `chromium` to the Makefile's APT_PACKAGES")
def test_report_opens_in_chromium(reports, tmp_path):
    playwright = pytest.importorskip("playwright.sync_api")
    folder, _ = reports["exp1_shape_motion"]
    shot = tmp_path / "report.png"
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=[
            "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking"])
        try:
            page = browser.new_page(viewport={"width": 1200, "height": 900})
            page.goto((folder / "report" / "report.html").as_uri())
            tables = page.locator("table.anova").count()      # the paper's table + the GG-corrected one
            visible = page.locator("table.anova").first.inner_text() if page.locator("table.anova").first.is_visible() else ""
            images = page.evaluate("Array.from(document.images).map(i => i.complete && i.naturalWidth)")
            heading = page.locator("h1").inner_text()
            page.screenshot(path=str(shot), full_page=True)
        finally:
            browser.close()
    assert tables == 2 and "BODY*SEX" in visible and heading.startswith("Analysis report: exp1_shape_motion")
    assert len(images) >= 2 and all(w and w > 300 for w in images)
    assert shot.stat().st_size > 50_000


def test_analyze_a_folder_of_jspsych_files(reports, tmp_path, jspsych_folder):
    folder, _ = reports["exp2_com_vs_average"]
    files = jspsych_folder(load_design(folder / "design"), tmp_path / "responses", 8, seed=4, prefix="shapemotion_exp2_")
    summary = analyze(folder / "design", files, tmp_path / "report")
    assert summary["import"]["participants"] == 8
    assert summary["import"]["excluded_by_reason"]["duplicate participant id"] == 80
    html = (tmp_path / "report" / "report.html").read_text(encoding="utf-8")
    assert "<th>file</th>" in html and "shapemotion_exp2_1_again.csv" in html


def test_nothing_left_after_exclusions_is_a_user_error(run_cli, tmp_path):
    bad = tmp_path / "r.csv"
    bad.write_text("participant,stimulus_id,response\nA,walk-Hi1-NoCOM_COM,maybe\n")
    code, _, err = run_cli("analyze", str(DATA / "mini_afc"), "--responses", str(bad), "--out", str(tmp_path / "out"))
    err = " ".join(err.split())   # the CLI wraps long messages
    assert code == 2 and "no participant is left" in err and "answer outside the scale" in err
    assert not (tmp_path / "out").exists()


def test_design_without_a_paper_figure_gets_a_cell_means_figure(tmp_path):
    """SEX × GAIT × BODY without MOTION: Figure 4 does not apply and nothing is significant, yet the report
    must show the data."""
    design = load_design(DATA / "mini_likert")
    sim = simulate_responses(design, load_model(None, design), 6, seed=2)
    (tmp_path / "r.csv").write_text(export_text(sim, design, "long"))
    summary = analyze(DATA / "mini_likert", tmp_path / "r.csv", tmp_path / "report", models=False)
    assert summary["sections"][0]["results"]["significant"] == []
    figures = tmp_path / "report" / "figures"
    assert sorted(p.name for p in figures.iterdir()) == ["cell_means.pdf", "cell_means.png", "cell_means.svg"]
    html = (tmp_path / "report" / "report.html").read_text(encoding="utf-8")
    assert html.count("<img src=\"data:image/png;base64,") == 1 and "Mean rating per GAIT × BODY × SEX" in html
    svg = (figures / "cell_means.svg").read_text()
    for text in ("SEX = F", "SEX = M", "GAIT", "BODY"):     # panels per between level, within on x and as lines
        assert text in svg


def test_vote_and_ranking_results_are_tables_in_every_format(reports):
    for name, stem, tables in (("thesis_pointlight", "vote_results", ["votes", "binomial"]),
                               ("thesis_validation", "rank_results", ["rank_points", "friedman"])):
        folder, summary = reports[name]
        report = folder / "report"
        results = summary["sections"][0]["results"]
        data = json.loads((report / f"{stem}.json").read_text())
        assert [t["name"] for t in data["tables"]] == tables
        frame = pd.read_csv(report / f"{stem}.csv")
        assert list(frame["table"].unique()) == tables
        md = (report / f"{stem}.md").read_text()
        assert all(line.startswith(("**", "|")) for line in md.splitlines() if line)
        assert "\\toprule" in (report / f"{stem}.tex").read_text()
        assert "<table class=\"result\">" in (report / f"{stem}.html").read_text()
        html = (report / "report.html").read_text(encoding="utf-8")
        assert (report / f"{stem}.html").read_text() in html       # the report shows the same tables
        if name == "thesis_validation":
            friedman = data["tables"][1]["rows"][0]
            assert friedman["chi2"] == results["friedman"]["statistic"] and friedman["p"] == results["friedman"]["p"]
            points = frame[frame["table"] == "rank_points"].set_index("SOURCE")
            for total, binomial in zip(results["totals"], results["binomial"]):
                assert points.loc[total["SOURCE"], "total points"] == total["total points"]
                assert points.loc[total["SOURCE"], "p"] == binomial["p"]
        else:
            votes = frame[frame["table"] == "votes"].set_index("cell")
            assert votes.loc["all", "chi2"] == results["chi2"][0]["statistic"]
            assert data["tables"][1]["rows"][0]["p"] == results["binomial"]["p"]
