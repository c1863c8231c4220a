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
    # the protocol's `posthoc: tukey` now means emmeans' univariate rule (issue 19), and the tables say so
    assert "post-hoc (Tukey, univariate, emmeans means)" in (report / "anova.md").read_text()
    method = summary["sections"][0]["results"]["posthoc_method"]["BODY:SEX"]
    assert method.startswith("Tukey, univariate follow-up, emmeans means")
    models = pd.read_csv(report / "additional_models.csv")
    lmm = "linear mixed model (REML, Satterthwaite F tests, as lmerTest)"
    assert set(models["model"]) == {lmm, "cumulative link mixed model (Laplace, as ordinal::clmm)"}
    assert models.set_index(["model", "term"]).loc[(lmm, "SEX:BODY"), "p"] < 0.001
    assert models.set_index(["model", "term"]).loc[(lmm, "SEX"), "df_den"] == pytest.approx(14, abs=1e-4)


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
    for model in ("logistic GEE (exchangeable, robust SE)", "logistic mixed model (Laplace, as lme4::glmer)"):
        assert models.loc[(model, "METHOD"), "p"] < 0.001 and models.loc[(model, "SEX:METHOD"), "p"] < 0.01
        assert models.loc[(model, "BODY:METHOD"), "df"] == 3


def test_vote_and_ranking_reports(reports):
    _, votes = reports["thesis_pointlight"]
    section = votes["sections"][0]["results"]
    assert section["tests"][0]["cell"] == "all" and section["tests"][0]["p"] < 0.001
    assert section["most_voted"]["label"] == "58" and section["most_voted"]["p"] < 0.001
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
    for name, stem, tables in (("thesis_pointlight", "vote_results", ["votes", "most_voted"]),
                               ("thesis_validation", "rank_results", ["rank_points", "friedman"])):
        folder, summary = reports[name]
        report = folder / "report"
        results = summary["sections"][0]["results"]
        data = json.loads((report / f"{stem}.json").read_text())
        assert [t["name"] for t in data["tables"]] == tables
        frame = pd.read_csv(report / f"{stem}.csv")
        assert list(frame["table"].unique()) == tables
        md = (report / f"{stem}.md").read_text()
        assert md.startswith("> **SIMULATED DATA")                 # the fixture's responses are simulated
        assert all(line.startswith(("**", "|")) for line in md.splitlines()[1:] if line)
        assert "\\toprule" in (report / f"{stem}.tex").read_text()
        alone = (report / f"{stem}.html").read_text()
        assert "<table class=\"result\">" in alone and alone.startswith('<p class="simulated">')
        html = (report / "report.html").read_text(encoding="utf-8")
        assert alone.split("\n", 1)[1] in html       # the report shows the same tables (its banner is on top)
        if name == "thesis_validation":
            friedman = data["tables"][1]["rows"][0]
            assert friedman["chi2"] == results["friedman"]["statistic"] and friedman["p"] == results["friedman"]["p"]
            points = frame[frame["table"] == "rank_points"].set_index("SOURCE")
            for total, first in zip(results["totals"], results["ranked_first"]):
                assert points.loc[total["SOURCE"], "total points"] == total["total points"]
                assert points.loc[total["SOURCE"], "p"] == first["p"]
        else:
            votes = frame[frame["table"] == "votes"].set_index("cell")
            assert votes.loc["all", "chi2"] == results["tests"][0]["statistic"]
            assert data["tables"][1]["rows"][0]["p"] == results["most_voted"]["p"]


# -- participants as the unit: position-bias check, ranked first, votes --------------------------------

def _per_participant(tidy: pd.DataFrame, column: str, value) -> pd.Series:
    """Share of each participant's test answers whose ``column`` equals ``value`` (from responses_tidy.csv)."""
    tests = tidy[~tidy["practice"]]
    return (tests[column] == value).groupby(tests["participant"]).mean()


def test_2afc_report_has_a_position_bias_check_over_participants(reports, tmp_path):
    """A model that prefers the left clip: the report says so, tested over participants (t-test of the
    per-participant left share, as statsmodels computes it), with each participant's exact binomial."""
    from scipy import stats
    from statsmodels.stats.weightstats import DescrStatsW

    from analysis.model_spec import parse_model
    folder, _ = reports["exp2_com_vs_average"]
    design = load_design(folder / "design")
    sim = simulate_responses(design, parse_model({"name": "left", "choice": {"position_bias": 0.6}}, "<t>", design),
                             16, seed=5)
    (tmp_path / "r.csv").write_text(export_text(sim, design, "long"))
    summary = analyze(folder / "design", tmp_path / "r.csv", tmp_path / "report", models=False)
    report = tmp_path / "report"
    tidy = pd.read_csv(report / "responses_tidy.csv", dtype={"participant": str})
    left = _per_participant(tidy, "position", 1)
    t, p, df = DescrStatsW(left.to_numpy()).ttest_mean(0.5)
    low, high = DescrStatsW(left.to_numpy()).tconfint_mean()
    section = summary["sections"][-1]
    assert section["title"].startswith("Position-bias check") and "not part of the paper" in section["title"]
    row = section["results"]["positions"][0]
    assert row["position"] == "left" and row["choices"] == int((tidy.loc[~tidy["practice"], "position"] == 1).sum())
    assert row["mean share"] == pytest.approx(left.mean()) and row["mean share"] > 0.6
    assert (row["t"], row["df"], row["p"]) == (pytest.approx(t), df, pytest.approx(p)) and p < 0.001
    assert (row["95% CI low"], row["95% CI high"]) == (pytest.approx(low), pytest.approx(high))
    tables = json.loads((report / "position_bias.json").read_text())["tables"]
    assert [t["name"] for t in tables] == ["position_shares", "position_participants"]
    people = {r["participant"]: r for r in tables[1]["rows"]}
    tests = tidy[~tidy["practice"]]
    for person, rows in tests.groupby("participant"):
        lefts = int((rows["position"] == 1).sum())
        assert (people[person]["left"], people[person]["choices"]) == (lefts, len(rows))
        assert people[person]["p"] == pytest.approx(stats.binomtest(lefts, len(rows), 0.5).pvalue)
    html = (report / "report.html").read_text(encoding="utf-8")
    alone = (report / "position_bias.html").read_text()
    assert alone.startswith('<p class="simulated">')   # simulated responses: the banner tops the file …
    assert alone.split("\n", 1)[1] in html and "Position-bias check" in html   # … and the report, once
    assert set(pd.read_csv(report / "position_bias.csv")["table"]) == {"position_shares", "position_participants"}


def test_kafc_position_check_uses_friedman_and_likert_has_none(reports):
    """6-AFC: per-position t-tests and a Friedman test of the per-participant position counts (scipy);
    a Likert design has no screen positions and so no check."""
    from scipy import stats
    folder, summary = reports["thesis_pointlight"]
    tidy = pd.read_csv(folder / "report" / "responses_tidy.csv", dtype={"participant": str})
    tests = tidy[~tidy["practice"]]
    counts = pd.crosstab(tests["participant"], tests["position"]).reindex(columns=range(1, 7), fill_value=0)
    expected = stats.friedmanchisquare(*(counts[c].to_numpy() for c in counts))
    check = summary["sections"][-1]["results"]
    assert [r["position"] for r in check["positions"]] == list("ABCDEF")
    assert check["test"]["chi2"] == pytest.approx(expected.statistic)
    assert check["test"]["p"] == pytest.approx(expected.pvalue)
    shares_a = _per_participant(tidy, "position", 1)
    assert check["positions"][0]["p"] == pytest.approx(stats.ttest_1samp(shares_a, 1 / 6).pvalue)
    assert not (reports["exp1_shape_motion"][0] / "report" / "position_bias.md").exists()
    assert not any("Position" in s["title"] for s in reports["exp1_shape_motion"][1]["sections"])


def test_votes_of_one_participant_are_not_pooled_as_independent(reports):
    """Point-light: 10 votes per participant over all trials → Friedman over participants, not χ² of 160
    pooled votes; one vote per participant in each PARAMETER cell → χ² there; the most voted level is
    tested with the t-test of per-participant shares."""
    from scipy import stats
    folder, summary = reports["thesis_pointlight"]
    results = summary["sections"][0]["results"]
    tidy = pd.read_csv(folder / "report" / "responses_tidy.csv", dtype={"participant": str, "chosen": str})
    tests = tidy[~tidy["practice"]]
    levels = ["0.5", "12", "23.5", "35", "46.5", "58"]   # a level nobody chose still counts (zero votes)
    counts = pd.crosstab(tests["participant"], tests["chosen"]).reindex(columns=levels, fill_value=0)
    fried = stats.friedmanchisquare(*(counts[c].to_numpy() for c in counts))
    overall = results["tests"][0]
    assert (overall["cell"], overall["test"], overall["participants"]) == ("all", "Friedman", 16)
    assert overall["statistic"] == pytest.approx(fried.statistic) and overall["p"] == pytest.approx(fried.pvalue)
    for row in results["tests"][1:]:
        cell = tests[tests["PARAMETER"] == row["cell"]]
        votes = cell["chosen"].value_counts().reindex(levels, fill_value=0)
        assert row["test"] == "chi-squared goodness of fit" and row["participants"] == 16
        assert row["p"] == pytest.approx(stats.chisquare(votes.to_numpy()).pvalue)
    most = results["most_voted"]
    shares = _per_participant(tidy, "chosen", most["label"])
    assert most["test"] == "one-sample t-test over participants" and most["participants"] == 16
    assert most["p"] == pytest.approx(stats.ttest_1samp(shares, 1 / 6).pvalue)
    frame = pd.read_csv(folder / "report" / "vote_results.csv")
    assert frame.loc[frame["table"] == "votes", "test"].tolist()[:2] == ["Friedman", "chi-squared goodness of fit"]


RANKING_PROTOCOL = """
name: rank_by_body
title: Which walk suits this body best?
seed: 11
participants: 8
actors:
  - {id: H1, label: H1, sex: F, height_m: 1.62, bmi: 34.0, body_fat_pct: 40}
  - {id: H2, label: H2, sex: M, height_m: 1.80, bmi: 31.0, body_fat_pct: 30}
factors:
  - {name: BODY, role: within, levels: [H1, H2], maps_to: body}
  - name: SOURCE
    role: alternatives
    maps_to: source
    levels: [lean, gen, mod]
    level_settings: {lean: {motion: lean_walk}, gen: {motion: generator}, mod: {motion: modifier}}
gaits:
  walk: {cadence_spm: 108, speed_mps: 1.1}
display: {layout: row, labels: [A, B, C]}
alternatives: {arrangements: latin_square, counterbalance: between}
clip: {duration_s: 2, cycles: 1, fps: 15, width: 480, height: 180,
       camera: {azimuth_deg: 30, elevation_deg: 5, distance_m: 8.0, fov_deg: 40}}
blocks: {by: [], order: fixed}
repetitions: 1
response: {type: ranking, question: Rank the walks.}
analysis: {dependent_measure: rank_points, alpha: 0.05, posthoc: none}
"""


@pytest.fixture(scope="module")
def ranking_by_body(tmp_path_factory):
    """A ranking design with a within factor (BODY): 16 participants rank twice, once per body."""
    from stimuli.cli import main

    from analysis.model_spec import parse_model
    folder = tmp_path_factory.mktemp("rank_by_body")
    (folder / "p.yaml").write_text(RANKING_PROTOCOL)
    assert main(["design", str(folder / "p.yaml"), "--out", str(folder / "design")]) == 0
    design = load_design(folder / "design")
    model = parse_model({"name": "m", "effects": [{"term": "SOURCE", "values": {"lean": -1.0, "mod": 0.6}}]},
                        "<t>", design)
    (folder / "r.csv").write_text(export_text(simulate_responses(design, model, 16, seed=2), design, "long"))
    summary = analyze(folder / "design", folder / "r.csv", folder / "report", models=False)
    tidy = pd.read_csv(folder / "report" / "responses_tidy.csv", dtype={"participant": str})
    return folder / "report", summary["sections"][0]["results"], tidy[~tidy["practice"]]


def test_ranked_first_is_tested_over_participants(ranking_by_body):
    """32 rankings from 16 people: each participant's share of rankings with the level first, one-sample
    t-test against 1/3 (statsmodels) — not an exact binomial of 32 'independent' rankings."""
    from statsmodels.stats.weightstats import DescrStatsW
    _, results, tidy = ranking_by_body
    first = tidy["ranking"].str.split(">").str[0]
    for test in results["ranked_first"]:
        shares = (first == test["label"]).groupby(tidy["participant"]).mean().to_numpy()
        t, p, df = DescrStatsW(shares).ttest_mean(1 / 3)
        assert test["test"] == "one-sample t-test over participants"
        assert (test["participants"], test["n"], test["successes"]) == (16, 32, int((first == test["label"]).sum()))
        assert (test["t"], test["p"], test["df"]) == (pytest.approx(t), pytest.approx(p), df)
    assert results["friedman"]["n"] == 16    # the Friedman test keeps participants as blocks


def test_rankings_are_broken_down_per_within_cell(ranking_by_body):
    """Per BODY: points and firsts from the tidy rankings, the exact binomial (one ranking per participant
    and cell) and a Friedman test per cell (scipy); the cells add up to the pooled totals."""
    from scipy import stats
    report, results, tidy = ranking_by_body
    tables = json.loads((report / "rank_results.json").read_text())["tables"]
    assert [t["name"] for t in tables] == ["rank_points", "friedman", "rank_points_by_cell"]
    rows = {(r["cell"], r["SOURCE"]): r for r in tables[2]["rows"]}
    for body, cell in tidy.groupby("BODY"):
        order = cell["ranking"].str.split(">")
        points = {lv: int(sum(3 - o.index(lv) for o in order)) for lv in ("lean", "gen", "mod")}
        for lv in points:
            firsts = int(sum(o[0] == lv for o in order))
            row = rows[(body, lv)]
            assert (row["total points"], row["ranked first"], row["rankings"]) == (points[lv], firsts, 16)
            assert row["test"] == "exact binomial over participants"
            assert row["p"] == pytest.approx(stats.binomtest(firsts, 16, 1 / 3).pvalue)
        wide = pd.DataFrame([{lv: 3 - o.index(lv) for lv in o} for o in order])
        expected = stats.friedmanchisquare(*(wide[c] for c in ("lean", "gen", "mod")))
        fried = next(r for r in tables[1]["rows"] if r["cell"] == body)
        assert fried["chi2"] == pytest.approx(expected.statistic) and fried["p"] == pytest.approx(expected.pvalue)
    for total in results["totals"]:
        assert total["total points"] == sum(rows[(b, total["SOURCE"])]["total points"] for b in ("H1", "H2"))
    assert "pooled over BODY" in tables[0]["caption"]


def test_participant_tests_match_scipy_and_statsmodels():
    """The tests on their own: binomial with one answer each, t-test with several, Friedman for any k."""
    import numpy as np
    from scipy import stats
    from statsmodels.stats.weightstats import DescrStatsW

    from analysis.participant_tests import friedman_counts, share_test, votes_test
    one = share_test([1, 0, 1, 1, 0, 1, 1, 1, 0, 1], [1] * 10, 4, "x")
    assert one["p"] == pytest.approx(stats.binomtest(7, 10, 0.25).pvalue) and one["share"] == 0.7
    hits, answers = np.array([3, 1, 4, 2, 2, 4]), np.array([4, 4, 4, 4, 3, 4])
    several = share_test(hits, answers, 2, "left")
    t, p, _ = DescrStatsW(hits / answers).ttest_mean(0.5)
    assert (several["t"], several["p"], several["n"]) == (pytest.approx(t), pytest.approx(p), 23)
    everyone = share_test([5, 5, 5], [5, 5, 5], 2, "left")   # no spread: p 0, not an error or silence
    assert everyone["p"] == 0.0 and everyone["t"] == float("inf")
    rng = np.random.default_rng(3)
    for k in (3, 5):
        counts = rng.integers(0, 6, size=(12, k))
        expected = stats.friedmanchisquare(*counts.T)
        got = friedman_counts(counts)
        assert got["statistic"] == pytest.approx(expected.statistic) and got["p"] == pytest.approx(expected.pvalue)
    pairs = np.array([[3, 1], [2, 2], [4, 0], [1, 3], [3, 1], [4, 1]])   # k = 2: the sign test's χ², ties dropped
    plus, minus = int((pairs[:, 0] > pairs[:, 1]).sum()), int((pairs[:, 0] < pairs[:, 1]).sum())
    assert friedman_counts(pairs)["statistic"] == pytest.approx((plus - minus) ** 2 / (plus + minus))
    single = votes_test(np.eye(3)[[0, 0, 1, 0, 2, 0]])
    assert single["test"] == "chi-squared goodness of fit" and single["p"] == pytest.approx(
        stats.chisquare([4, 1, 1]).pvalue)


# -- degenerate choices: everyone always picks one screen position ---------------------------------------

def _all_first_position(design, tmp_path, name="r.csv", participants=16, seed=5):
    """Simulated long-format answers in which every test (and practice) answer is the first position."""
    import io
    sim = simulate_responses(design, load_model(None, design), participants, seed=seed)
    frame = pd.read_csv(io.StringIO(export_text(sim, design, "long")), dtype=str, keep_default_na=False)
    labels = design.position_labels or ["left", "right"]
    frame["response"] = labels[0]
    frame.to_csv(tmp_path / name, index=False)
    return tmp_path / name


def test_2afc_everyone_always_left_report_explains_instead_of_failing(reports, run_cli, tmp_path):
    """percent_chosen is 50 in every cell: analyze used to stop (exit 2, "'percent' is constant") before the
    position check could say why; right's t was shown as ∞ instead of −∞ and was a bare null in the JSON."""
    folder, _ = reports["exp2_com_vs_average"]
    answers = _all_first_position(load_design(folder / "design"), tmp_path)
    code, out, err = run_cli("analyze", folder / "design", "--responses", answers, "--out", tmp_path / "report")
    assert code == 0 and "Traceback" not in err, err
    assert "not computed — every value of percent in cell_values.csv is 50" in out
    assert "every participant chose the same screen position on every test trial (left by 16 participants)" in out
    assert "carry no information about METHOD" in out and "t(15) = ∞, p = 0" in out
    report = tmp_path / "report"
    summary = json.loads((report / "summary.json").read_text())
    anova_section = summary["sections"][0]
    assert anova_section["title"].endswith("not computed") and anova_section["results"]["significant"] is None
    assert [s["title"] for s in summary["sections"]][-1].startswith("Position-bias check")
    assert not (report / "anova.md").exists() and not (report / "additional_models.csv").exists()
    assert "cannot be computed" in (report / "report.html").read_text(encoding="utf-8")
    md = (report / "position_bias.md").read_text()
    assert "| left | 1024 | 1.00 | 0.50 | 16 | 1.00 | ∞ | 15 |" in md
    assert "| right | 0 | 0.00 | 0.50 | 16 | 0.00 | −∞ | 15 |" in md
    assert r"$-\infty$" in (report / "position_bias.tex").read_text()
    shares = json.loads((report / "position_bias.json").read_text())["tables"][0]
    assert [r["t"] for r in shares["rows"]] == [None, None]            # JSON has no ±∞: null, as summary.json
    assert shares["non_finite"] == [{"row": 0, "column": "t", "value": "inf"},
                                    {"row": 1, "column": "t", "value": "-inf"}]
    assert summary["sections"][-1]["results"]["t_infinite"] == {"left": "inf", "right": "-inf"}


def test_kafc_everyone_always_first_position_has_negative_infinite_t(reports, tmp_path):
    from analysis.position_bias import position_tables
    from analysis.result_tables import render_results
    counts = pd.DataFrame([[10, 0, 0]] * 4, columns=list("ABC"), index=[str(i) for i in range(1, 5)])
    tables = position_tables(counts, 0.05)
    assert tables[0].frame["t"].tolist() == [float("inf"), float("-inf"), float("-inf")]
    md = render_results(tables, "md")
    assert "| A | 40 | 1.00 | 0.33 | 4 | 1.00 | ∞ |" in md and "| B | 0 | 0.00 | 0.33 | 4 | 0.00 | −∞ |" in md
    assert json.loads(render_results(tables, "json"))["tables"][0]["non_finite"][1] == \
        {"row": 1, "column": "t", "value": "-inf"}


def test_report_says_which_dependent_measure_and_that_it_was_the_default(reports, tmp_path):
    """An afc design.json without dependent_measure gets percent_chosen (votes is also valid): say so."""
    folder, _ = reports["exp2_com_vs_average"]
    design_dir = tmp_path / "design"
    shutil.copytree(folder / "design", design_dir)
    meta = json.loads((design_dir / "design.json").read_text())
    meta.pop("dependent_measure", None)
    meta.get("protocol", {}).get("analysis", {}).pop("dependent_measure", None)
    (design_dir / "design.json").write_text(json.dumps(meta))
    summary = analyze(design_dir, folder / "responses.csv", tmp_path / "report", models=False)
    note = ("Dependent measure: percent_chosen, the default for response type afc, as design.json sets no "
            "dependent_measure (votes would also fit this design")
    assert summary["design"]["dependent_measure"] == "percent_chosen"
    assert summary["design"]["dependent_measure_source"] == "default"
    assert summary["design"]["dependent_measure_note"].startswith(note)
    assert note.replace("'", "&#39;") in (tmp_path / "report" / "report.html").read_text(encoding="utf-8")
    explicit = analyze(folder / "design", folder / "responses.csv", tmp_path / "report2", models=False)
    assert explicit["design"]["dependent_measure_source"] != "default"
    assert "as set by design.json field" in explicit["design"]["dependent_measure_note"]


def test_ranking_report_checks_the_position_of_the_clip_ranked_first(reports, tmp_path):
    """A ranking's 'choice' is its first place: a participant who always ranks the leftmost clip first answers by
    position. The thesis validation row (4 clips A–D) got no position check at all."""
    folder, summary = reports["thesis_validation"]
    report = folder / "report"
    section = next(s for s in summary["sections"] if s["results"].get("check") == "position")
    tidy = pd.read_csv(report / "responses_tidy.csv", keep_default_na=False)
    design = load_design(folder / "design")
    tests = tidy[tidy["practice"].astype(str).str.lower() == "false"]
    first = [design.arrangement(s).index(r.split(">")[0]) + 1 for s, r in zip(tests["stimulus_id"], tests["ranking"])]
    counts = pd.Series(first).value_counts().sort_index()
    shares = {row["position"]: row["choices"] for row in section["results"]["positions"]}
    assert list(shares.values()) == [int(counts.get(i, 0)) for i in range(1, len(shares) + 1)]
    assert (report / "position_bias.json").is_file() and "clip ranked first" in (report / "report.html").read_text()
