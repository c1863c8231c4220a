"""Report sections of the k-AFC vote and ranking designs (the thesis's surveys): tables, tests, figures.

The tests SPEC §1.3 names for these designs — χ² goodness of fit for votes, Friedman for rank points,
binomial for "chosen first" — with the participant as the unit wherever a participant gives several
answers (:mod:`analysis.participant_tests`): the thesis's designs ask each viewer once per cell, but a
design with within factors or repetitions asks the same person several times, and pooling those
answers would treat them as independent.

- votes: counts per level, for all trials and per within cell, each with the test of equal shares (χ²
  where every participant voted once, else Friedman over participants); the most voted level against 1/k.
- rankings: points k … 1 per level, "ranked first" against 1/k over participants, the Friedman test of the
  rank points (participants as blocks); with within factors also per within cell.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from analysis.io_design import DesignInfo
from analysis.measures import friedman, percent_chosen, rank_points, vote_counts
from analysis.participant_tests import share_test, votes_test
from analysis.result_tables import ResultTable, render_results, write_results

PARTICIPANT_NOTE = ("Participants are the unit of every test: where a participant gives several answers, they "
                    "are aggregated per participant first (one-sample t-test of per-participant shares, Friedman "
                    "with participants as blocks); where each gives one, the exact binomial and χ² tests are used.")


def cell_label(cell) -> str:
    """``walk`` or, for several within factors, ``walk / 45``.

    >>> cell_label(("walk", 45)), cell_label("H1")
    ('walk / 45', 'H1')
    """
    return " / ".join(map(str, cell)) if isinstance(cell, tuple) else str(cell)


# -- votes ----------------------------------------------------------------------------------------------

def votes_section(design: DesignInfo, data: pd.DataFrame, out: Path, simulated: bool = False) -> dict:
    """k-AFC votes: counts per alternative, the test of equal shares overall and per cell, the top level."""
    from analysis import figures
    alt = design.alternatives
    overall = vote_counts(data, design)
    per_cell = vote_counts(data, design, by=design.within) if design.within else overall
    per_cell.to_csv(out / "votes.csv", lineterminator="\n")
    tests = _vote_tests(data, design, per_cell)
    pd.DataFrame(tests).to_csv(out / "vote_tests.csv", index=False, lineterminator="\n")
    by_person = vote_counts(data, design, by=["participant"])
    top = overall.iloc[0].idxmax()
    most = share_test(by_person[top].to_numpy(), by_person.sum(axis=1).to_numpy(), len(alt.levels), top)
    tables = _vote_tables(pd.concat([overall, per_cell]) if design.within else overall, tests, most, design)
    shares = percent_chosen(data, design)
    figs = [(f"% of votes per {alt.name}", figures.choice_bars(shares, "percent", design,
                                                                out / "figures" / "votes", "% of votes",
                                                                100.0 / len(alt.levels)))]
    results = {"votes": overall.iloc[0].to_dict(), "tests": tests, "most_voted": most}
    return {"title": f"k-AFC votes per {alt.name}", "html": render_results(tables, "html"), "figures": figs,
            "results": results, "note": "Equal shares under chance. " + PARTICIPANT_NOTE,
            "files": write_results(tables, out / "vote_results", simulated) + ["votes.csv", "vote_tests.csv"]}


def _vote_tests(data: pd.DataFrame, design: DesignInfo, per_cell: pd.DataFrame) -> list[dict]:
    """The test of equal vote shares for all trials, then per within cell (rows of ``per_cell``)."""
    tests = [{"cell": "all", **votes_test(vote_counts(data, design, by=["participant"]).to_numpy())}]
    if design.within:
        by_cell = vote_counts(data, design, by=[*design.within, "participant"])
        for cell in per_cell.index:
            tests.append({"cell": cell_label(cell), **votes_test(by_cell.loc[cell].to_numpy())})
    return tests


def _vote_tables(counts: pd.DataFrame, tests: list[dict], most: dict, design: DesignInfo) -> list[ResultTable]:
    """The vote results as tables: counts and the test per cell (all trials first), the most voted level."""
    alt = design.alternatives
    k = len(alt.levels)
    frame = counts.reset_index(drop=True).rename(columns=str)
    frame.insert(0, "cell", [t["cell"] for t in tests])
    frame = frame.assign(**{key: [t[name] for t in tests] for key, name in
                            (("n", "n"), ("participants", "participants"), ("test", "test"),
                             ("chi2", "statistic"), ("df", "df"), ("p", "p"))})
    within = " × ".join(design.within)
    per_cell = f", then per {within} cell" if within else ""
    top = pd.DataFrame([{alt.name: most["label"], "votes": most["successes"], "n": most["n"],
                         "participants": most["participants"], "share": most["share"], "test": most["test"],
                         "t": most["t"], "df": most["df"], "p": most["p"], "95% CI low": most["ci_low"],
                         "95% CI high": most["ci_high"]}])
    return [ResultTable("votes", f"Votes per {alt.name} level (all trials{per_cell}) and the test of equal shares: "
                                 f"χ² goodness of fit where each participant voted once, else Friedman over "
                                 f"participants", frame),
            ResultTable("most_voted", f"{most['label']} (most votes): share against chance 1/{k}, two-sided "
                                      f"{most['test']}", top)]


# -- rankings -------------------------------------------------------------------------------------------

def ranking_section(design: DesignInfo, data: pd.DataFrame, out: Path, simulated: bool = False) -> dict:
    """Rankings: points (k … 1), 'ranked first' over participants, Friedman; per within cell too."""
    from analysis import figures
    alt = design.alternatives
    points = rank_points(data, design)
    points.to_csv(out / "rank_points.csv", index=False, lineterminator="\n")
    fried = [{"cell": "all", **friedman(points, design)}]
    totals, firsts = rank_summary(points, design)
    cells = _cells(points, design)
    fried += [{"cell": label, **friedman(part, design)} for label, part in cells]
    by_cell = [(label, *rank_summary(part, design)) for label, part in cells]
    tables = _ranking_tables(totals, firsts, fried, by_cell, design)
    figs = [(f"Mean rank points per {alt.name}", figures.choice_bars(points, "points", design,
                                                                      out / "figures" / "rank_points",
                                                                      "mean points", (len(alt.levels) + 1) / 2))]
    results = {"totals": totals.reset_index().to_dict("records"), "friedman": fried[0], "ranked_first": firsts}
    if cells:
        results["by_cell"] = [{"cell": label, "totals": t.reset_index().to_dict("records"), "friedman": f,
                               "ranked_first": first} for (label, t, first), f in zip(by_cell, fried[1:])]
    pooled = (f" The first tables pool the rankings over {' × '.join(design.within)}; the last one breaks them "
              f"down per cell." if cells else "")
    return {"title": f"Rankings of {alt.name}", "html": render_results(tables, "html"), "figures": figs,
            "results": results,
            "note": f"Points: k for first place … 1 for last (the thesis scored 4/3/2/1).{pooled} "
                    + PARTICIPANT_NOTE,
            "files": write_results(tables, out / "rank_results", simulated) + ["rank_points.csv"]}


def _cells(points: pd.DataFrame, design: DesignInfo) -> list[tuple[str, pd.DataFrame]]:
    """The rank points of each within cell, labelled (none without within factors)."""
    if not design.within:
        return []
    return [(cell_label(cell), part) for cell, part in points.groupby(design.within if len(design.within) > 1
                                                                       else design.within[0], sort=True)]


def rank_summary(points: pd.DataFrame, design: DesignInfo) -> tuple[pd.DataFrame, list[dict]]:
    """Per level: total and mean points, times ranked first and rankings; the 'ranked first' test per level.

    ``points`` is :func:`analysis.measures.rank_points` (mean points per participant × cell × level over
    ``n`` rankings), so a total is Σ points·n — the points actually given, also with repetitions.
    """
    alt = design.alternatives
    given = points.assign(total=points["points"] * points["n"])
    per_level = given.groupby(alt.name).agg(total=("total", "sum"), first=("first", "sum"), n=("n", "sum"))
    per_level = per_level.reindex(alt.levels)
    # a total is a sum of whole points; the float product only carries rounding
    totals = pd.DataFrame({"total points": per_level["total"].round().astype(int),
                           "mean points": per_level["total"] / per_level["n"],
                           "ranked first": per_level["first"].astype(int), "rankings": per_level["n"].astype(int)},
                          index=pd.Index(alt.levels, name=alt.name))
    person = given.groupby(["participant", alt.name])[["first", "n"]].sum()
    firsts = [share_test(person.xs(lv, level=alt.name)["first"].to_numpy(),
                         person.xs(lv, level=alt.name)["n"].to_numpy(), len(alt.levels), lv) for lv in alt.levels]
    return totals, firsts


def _first_columns(totals: pd.DataFrame, firsts: list[dict]) -> pd.DataFrame:
    """``totals`` with the 'ranked first' test of each level as columns."""
    return totals.reset_index().assign(**{
        "participants": [f["participants"] for f in firsts], "share first": [f["share"] for f in firsts],
        "test": [f["test"] for f in firsts], "t": [f["t"] for f in firsts], "df": [f["df"] for f in firsts],
        "p": [f["p"] for f in firsts], "95% CI low": [f["ci_low"] for f in firsts],
        "95% CI high": [f["ci_high"] for f in firsts]})


def _ranking_tables(totals: pd.DataFrame, firsts: list[dict], fried: list[dict], by_cell: list[tuple],
                    design: DesignInfo) -> list[ResultTable]:
    """Points and 'ranked first' per level, the Friedman tests (all, then per cell), the per-cell breakdown."""
    alt = design.alternatives
    k = len(alt.levels)
    within = " × ".join(design.within)
    pooled = f", pooled over {within}" if within else ""
    test = pd.DataFrame([{"cell": f["cell"], "test": f["test"], "chi2": f["statistic"], "df": f["df"], "p": f["p"],
                          "participants": f["n"]} for f in fried])
    per_cell = f" (all rankings, then per {within} cell)" if within else ""
    tables = [ResultTable("rank_points", f"Rank points per {alt.name} ({k} for first … 1 for last{pooled}) and "
                                         f"'ranked first' against chance (1/{k}) over participants",
                          _first_columns(totals, firsts)),
              ResultTable("friedman", f"Friedman test of the rank points, participants as blocks{per_cell}", test)]
    if by_cell:
        frame = pd.concat([_first_columns(t, first).assign(cell=label) for label, t, first in by_cell],
                          ignore_index=True)
        frame = frame[["cell", *[c for c in frame.columns if c != "cell"]]]
        tables.append(ResultTable("rank_points_by_cell", f"Rank points and 'ranked first' per {within} cell",
                                  frame))
    return tables
