"""Position-bias check of forced-choice responses: are the screen positions chosen equally often?

A check of the data, not part of the paper's analysis: where the design counterbalances which level is
shown where, a preference for the left clip adds noise but no bias to the level shares (a fixed arrangement
confounds the two) — and a strong one says that some participants answered by position rather than by
what they saw.

Tested with the participant as the unit (:mod:`analysis.participant_tests`): 384 choices from 16
people are not 384 independent coin flips, so a binomial test of all choices against ½ would be
pseudo-replicated. Per participant the share of choices at each position; a one-sample t-test of these
shares against chance 1/k per position; for k > 2 positions also a Friedman test of the per-participant
counts (participants as blocks) across all positions. For 2AFC the exact binomial test of each participant's
left choices against ½ is listed too, with the number of participants it flags as biased.

>>> import pandas as pd
>>> data = pd.DataFrame({"participant": ["1"] * 4 + ["2"] * 4, "position": [1, 1, 1, 2, 1, 1, 2, 2],
...                      "practice": [False] * 8})
>>> position_counts(data, ["left", "right"]).to_dict("index")
{'1': {'left': 3, 'right': 1}, '2': {'left': 2, 'right': 2}}
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from analysis.io_design import DesignInfo, arrangement_of
from analysis.participant_tests import friedman_counts, share_test
from analysis.responses.tidy import participant_order
from analysis.result_tables import ResultTable, render_results, write_results

TITLE = "Position-bias check (a check of the data, not part of the paper's analysis)"


def position_names(design: DesignInfo) -> list[str]:
    """Names of the screen positions: the design's position labels, else left/right for two, else 1 … k."""
    k = max((len(arrangement_of(r)) for r in design.test_conditions.to_dict("records")), default=0)
    if len(design.position_labels) == k:
        return list(design.position_labels)
    return ["left", "right"] if k == 2 else [str(i) for i in range(1, k + 1)]


def position_counts(data: pd.DataFrame, names: list[str]) -> pd.DataFrame:
    """Choices per participant (rows, in the tidy table's order) and screen position (columns ``names``).

    Test trials only; ``position`` is 1-based, as the tidy table writes it.
    """
    tests = data[~data["practice"].astype(bool) & data["position"].notna()]
    counts = pd.crosstab(tests["participant"], tests["position"].astype(int))
    counts = counts.reindex(columns=range(1, len(names) + 1), fill_value=0).set_axis(names, axis=1)
    order = participant_order(pd.Series(counts.index, index=counts.index))
    counts = counts.iloc[np.argsort(order.to_numpy(), kind="stable")]
    counts.columns.name = counts.index.name = None
    return counts


def position_tables(counts: pd.DataFrame, alpha: float) -> list[ResultTable]:
    """The check as result tables: shares and t-tests per position, Friedman (k > 2), every participant."""
    names = list(counts.columns)
    k = len(names)
    shares, test_name = _share_table(counts)
    people = _participant_table(counts)
    tables = [ResultTable("position_shares", f"Choices per screen position; per-participant share against chance "
                                             f"(1/{k}), {test_name}", shares)]
    if k == 2:
        # the per-participant binomial flags individuals; the t-test above is the test of the whole sample
        flagged = people["p"] < alpha
        share = people[f"share {names[0]}"]
        shares[f"participants biased (binomial p < {alpha:g})"] = [int((flagged & (share > 0.5)).sum()),
                                                                   int((flagged & (share < 0.5)).sum())]
    else:
        fried = friedman_counts(counts.to_numpy())
        test = pd.DataFrame([{"test": fried["test"], "chi2": fried["statistic"], "df": fried["df"], "p": fried["p"],
                              "participants": fried["participants"]}])
        tables.append(ResultTable("position_test", "Friedman test of the choices per position, participants as "
                                                   "blocks", test))
    binomial = " and exact binomial test of each participant's choices against ½" if k == 2 else ""
    tables.append(ResultTable("position_participants", f"Choices per screen position and participant{binomial}",
                              people))
    return tables


def _share_table(counts: pd.DataFrame) -> tuple[pd.DataFrame, str]:
    """Per position: choices, pooled share (descriptive) and the test of the per-participant shares."""
    names = list(counts.columns)
    k = len(names)
    answers = counts.sum(axis=1).to_numpy()
    tests = [share_test(counts[name].to_numpy(), answers, k, name) for name in names]
    frame = pd.DataFrame({
        "position": names, "choices": counts.sum(axis=0).to_numpy(),
        "share of all choices": counts.sum(axis=0).to_numpy() / answers.sum(), "chance": [1.0 / k] * k,
        "participants": [t["participants"] for t in tests], "mean share": [t["share"] for t in tests],
        "t": [t["t"] for t in tests], "df": [t["df"] for t in tests], "p": [t["p"] for t in tests],
        "95% CI low": [t["ci_low"] for t in tests], "95% CI high": [t["ci_high"] for t in tests]})
    return frame, tests[0]["test"]


def _participant_table(counts: pd.DataFrame) -> pd.DataFrame:
    """One row per participant: choices per position; for 2AFC the left share and its exact binomial p."""
    names = list(counts.columns)
    answers = counts.sum(axis=1).to_numpy()
    people = counts.rename_axis("participant").reset_index().assign(choices=answers)
    if len(names) == 2:
        people[f"share {names[0]}"] = counts[names[0]].to_numpy() / answers
        people["p"] = [stats.binomtest(int(h), int(n), 0.5).pvalue for h, n in zip(counts[names[0]], answers)]
    return people


def first_ranked_positions(data: pd.DataFrame, design: DesignInfo) -> pd.Series:
    """For ranking rows, the 1-based screen position of the clip ranked first (a ranking's 'choice').

    >>> from types import SimpleNamespace
    >>> design = SimpleNamespace(arrangement=lambda sid: {"s1": ["A", "B", "C"]}[sid])
    >>> first_ranked_positions(pd.DataFrame({"stimulus_id": ["s1", "s1"], "ranking": ["B>A>C", "C>B>A"]}),
    ...                        design).tolist()
    [2, 3]
    """
    def position(sid, ranking):
        arrangement, first = design.arrangement(sid), str(ranking).split(">")[0]
        return arrangement.index(first) + 1 if first in arrangement else pd.NA

    return pd.Series([position(sid, r) for sid, r in zip(data["stimulus_id"], data["ranking"])],
                     index=data.index, dtype="Int64")


def position_section(data: pd.DataFrame, design: DesignInfo, out: Path, simulated: bool = False) -> dict | None:
    """The report section of the check (files ``position_bias.*``, under the simulated-data banner when
    ``simulated``); None without choices or positions.

    A ranking's 'choice' is the clip it ranks first: a participant who ranks the leftmost clip first
    every time answers by position as much as one who always picks the left clip.
    """
    if design.response_type == "ranking" and "ranking" in data:
        data = data.assign(position=first_ranked_positions(data, design))
    elif design.response_type != "afc" or "position" not in data:
        return None
    names = position_names(design)
    counts = position_counts(data, names)
    if len(names) < 2 or counts.empty:
        return None
    tables = position_tables(counts, design.alpha)
    results = {"check": "position", "positions": tables[0].frame.to_dict("records"),
               "test": (tables[1].frame.iloc[0].to_dict() if len(names) > 2 else
                        tables[0].frame.iloc[0][["position", "mean share", "t", "df", "p"]].to_dict())}
    infinite = [f"{row['position']} ({'∞' if row['t'] > 0 else '−∞'})" for row in results["positions"]
                if isinstance(row["t"], float) and np.isinf(row["t"])]
    if infinite:
        # JSON has no ±∞: summary.json writes null, position_bias.json lists the cells under "non_finite"
        results["t_infinite"] = {row["position"]: ("inf" if row["t"] > 0 else "-inf") for row in results["positions"]
                                 if isinstance(row["t"], float) and np.isinf(row["t"])}
    note = ("Where the design counterbalances the screen positions, a position preference does not bias the "
            "results above, but it adds noise and may flag participants who answered by position. The "
            "participant is the unit: each participant's share of choices per position is tested against chance with a "
            "one-sample t-test (a binomial test of all choices pooled would treat one person's choices as "
            "independent)." + (" For k > 2 positions a Friedman test compares all positions at once."
                               if len(names) > 2 else "")
            + (" In a ranking, a participant's choice is the clip ranked first." if design.response_type == "ranking"
               else ""))
    if infinite:
        note += (f" t is infinite for {', '.join(infinite)}: every participant chose that position with the "
                 f"same share (no spread between participants), so the t statistic is ±∞ and p is 0. The JSON "
                 f"files write ±∞ as null; position_bias.json lists these cells under \"non_finite\" and "
                 f"summary.json under \"t_infinite\", with their sign.")
    return {"title": TITLE, "html": render_results(tables, "html"), "figures": [], "note": note,
            "results": results, "files": write_results(tables, out / "position_bias", simulated)}


def position_line(results: dict) -> str:
    """One line for the terminal: ``position check …: left 62.5 % of choices (…), t(15) = 4.10, p = 0.001``."""
    first = results["positions"][0]
    test = results["test"]
    if test["p"] is None:      # e.g. a single participant: no spread to test against
        stat = "no test (fewer than 2 participants, or no spread)"
    elif "chi2" in test:
        stat = f"Friedman χ²({test['df']}) = {test['chi2']:.2f}, p = {test['p']:.3g}"
    else:
        # ±∞ (no spread between participants) is null once written as JSON: the sign is that of share − chance
        t = test["t"]
        if t is None or (isinstance(t, float) and np.isinf(t)):
            t = "∞" if first["mean share"] > first["chance"] else "−∞"
        else:
            t = f"{t:.2f}"
        stat = f"t({test['df']}) = {t}, p = {test['p']:.3g}"
    return (f"{TITLE}: {first['position']} {100 * first['share of all choices']:.1f} % of all choices, "
            f"{100 * first['mean share']:.1f} % per participant on average (chance {100 * first['chance']:.1f} %); "
            f"{stat}")
