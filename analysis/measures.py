"""Dependent measures per design, from the tidy table of :mod:`analysis.responses`.

- ``mean_rating`` (Experiment 1): the mean of the repetitions per participant × cell;
- ``percent_chosen`` (Experiment 2): per participant × cell, the percentage of trials on which each level
  of the alternatives factor (METHOD) was chosen — the alternatives factor becomes a within factor of
  the ANOVA, as in the paper's Table 4;
- ``votes`` (k-AFC, thesis): vote counts per alternative, χ² goodness of fit against equal shares;
- ``rank_points`` (ranking, thesis): k points for first … 1 for last, Friedman test over participants.

The tests with the participant as the unit ("ranked first", votes of repeated answers) are in
:mod:`analysis.participant_tests`.

:func:`anova_input` gives the ANOVA-ready long table (dv, within, between) of a design;
:func:`measure_arrays` does the same for many simulated data sets at once (power analysis).

>>> import pandas as pd
>>> t = pd.DataFrame({"participant": ["1", "1", "1", "1"], "GAIT": ["walk", "walk", "jog", "jog"],
...                   "rating": [4, 5, 2, 3], "practice": [False] * 4})
>>> mean_ratings(t, [], ["GAIT"])["rating"].tolist()
[2.5, 4.5]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from analysis.errors import AnalysisError
from analysis.io_design import DesignInfo, arrangement_of


def _tests_only(data: pd.DataFrame) -> pd.DataFrame:
    return data[~data["practice"].astype(bool)] if "practice" in data else data


def mean_ratings(data: pd.DataFrame, between: list[str], within: list[str]) -> pd.DataFrame:
    """Mean rating per participant × cell (repetitions averaged); column ``n`` = answers averaged."""
    keys = ["participant", *between, *within]
    frame = _tests_only(data).astype({"rating": float})
    out = frame.groupby(keys, sort=True, observed=True)["rating"].agg(["mean", "size"]).reset_index()
    return out.rename(columns={"mean": "rating", "size": "n"})


def percent_chosen(data: pd.DataFrame, design: DesignInfo) -> pd.DataFrame:
    """Percentage of trials each alternatives level was chosen, per participant × cell × level."""
    alt = design.alternatives
    keys = ["participant", *design.between, *design.within]
    frame = _tests_only(data)
    counts = frame.groupby(keys + ["chosen"], observed=True).size().unstack("chosen", fill_value=0)
    counts = counts.reindex(columns=alt.levels, fill_value=0)
    percent = counts.div(counts.sum(axis=1), axis=0) * 100.0
    out = percent.stack().rename("percent").reset_index().rename(columns={"chosen": alt.name})
    out["n"] = np.repeat(counts.sum(axis=1).to_numpy(), len(alt.levels))
    return out


def rank_points(data: pd.DataFrame, design: DesignInfo) -> pd.DataFrame:
    """Points per participant × cell × level: k for first place … 1 for last, averaged over trials."""
    alt = design.alternatives
    k = len(alt.levels)
    rows = []
    for rec in _tests_only(data).to_dict("records"):
        for place, level in enumerate(str(rec["ranking"]).split(">")):
            rows.append({**{c: rec[c] for c in ["participant", *design.between, *design.within]},
                         alt.name: level, "points": k - place, "first": place == 0})
    frame = pd.DataFrame(rows)
    keys = ["participant", *design.between, *design.within, alt.name]
    return frame.groupby(keys, observed=True).agg(points=("points", "mean"), first=("first", "sum"),
                                                  n=("points", "size")).reset_index()


def vote_counts(data: pd.DataFrame, design: DesignInfo, by: list[str] | None = None) -> pd.DataFrame:
    """Votes per alternatives level (rows: the ``by`` cells; columns: levels)."""
    alt = design.alternatives
    frame = _tests_only(data)
    if by:
        table = frame.groupby(by + ["chosen"], observed=True).size().unstack("chosen", fill_value=0)
    else:
        table = frame["chosen"].value_counts().to_frame().T.set_axis(["all"], axis=0)
    return table.reindex(columns=alt.levels, fill_value=0)


def chi2_votes(counts) -> dict:
    """χ² goodness of fit of vote counts against equal shares (k-AFC at chance)."""
    counts = np.asarray(counts, dtype=float)
    chi2, p = stats.chisquare(counts)
    return {"test": "chi-squared goodness of fit", "statistic": float(chi2), "df": int(len(counts) - 1),
            "p": float(p), "n": int(counts.sum())}


def friedman(points: pd.DataFrame, design: DesignInfo) -> dict:
    """Friedman test of rank points across the alternatives, participants as blocks."""
    alt = design.alternatives
    wide = points.groupby(["participant", alt.name])["points"].mean().unstack(alt.name)[alt.levels].dropna()
    if len(wide) < 2:
        raise AnalysisError("the Friedman test needs at least 2 participants with complete rankings")
    stat, p = stats.friedmanchisquare(*(wide[c].to_numpy() for c in alt.levels))
    return {"test": "Friedman", "statistic": float(stat), "df": len(alt.levels) - 1, "p": float(p), "n": len(wide),
            "mean_points": {c: float(wide[c].mean()) for c in alt.levels}}


# -- the ANOVA view ------------------------------------------------------------------------------

@dataclass
class AnovaInput:
    """A long table with one row per participant × cell and the roles of its columns."""

    data: pd.DataFrame
    dv: str
    within: list[str]
    between: list[str]


def anova_input(data: pd.DataFrame, design: DesignInfo) -> AnovaInput:
    """The ANOVA-ready table of the design's dependent measure (mean_rating or percent_chosen/rank_points)."""
    measure = design.dependent_measure
    if measure == "mean_rating":
        return AnovaInput(mean_ratings(data, design.between, design.within), "rating", design.within, design.between)
    if measure in ("percent_chosen", "votes"):
        return AnovaInput(percent_chosen(data, design), "percent", design.within + [design.alternatives.name],
                          design.between)
    if measure == "rank_points":
        return AnovaInput(rank_points(data, design), "points", design.within + [design.alternatives.name],
                          design.between)
    raise AnalysisError(f"unknown dependent measure {measure!r}")


# -- many simulated data sets at once -------------------------------------------------------------

def within_levels(design: DesignInfo) -> dict[str, list[str]]:
    """Within factors of the ANOVA with their levels (the alternatives factor last, when it is a measure)."""
    levels = {f: design.factor(f).levels for f in design.within}
    if design.response_type != "likert":
        levels[design.alternatives.name] = design.alternatives.levels
    return levels


def _cell_codes(design: DesignInfo) -> np.ndarray:
    """Per stimulus (conditions.csv row), the index of its within cell (C order; −1 for practice)."""
    names = design.within
    sizes = [len(design.factor(n).levels) for n in names]
    codes = []
    for rec in design.conditions.to_dict("records"):
        if rec["practice"]:
            codes.append(-1)
            continue
        idx = [design.factor(n).levels.index(str(rec[n])) for n in names]
        codes.append(int(np.ravel_multi_index(idx, sizes)) if names else 0)
    return np.array(codes)


def measure_arrays(design: DesignInfo, stimulus_matrix: np.ndarray, draws: np.ndarray) -> np.ndarray:
    """Cell values of many data sets: (sims × participants × trials) answers → sims × participants × cells.

    ``stimulus_matrix`` (participants × trials) holds the conditions.csv row of each test trial; Likert
    draws are ratings, k-AFC draws 0-based chosen positions, ranking draws positions best first.
    Cells follow :func:`within_levels` in C order, as the ANOVA engine expects.
    """
    cells = _cell_codes(design)[stimulus_matrix]                    # n × t
    n_cells = int(np.prod([len(design.factor(n).levels) for n in design.within])) if design.within else 1
    onehot = np.zeros(cells.shape + (n_cells,))
    np.put_along_axis(onehot, cells[..., None], 1.0, axis=2)
    counts = onehot.sum(axis=1)                                       # n × cells
    if np.any(counts == 0):
        raise AnalysisError("a participant's trial list leaves a design cell empty; cannot compute cell means")
    if design.response_type == "likert":
        # batched matrix products (BLAS) instead of einsum: (s, p, 1, t) @ (p, t, c) → (s, p, 1, c)
        return np.matmul(draws.astype(float)[:, :, None, :], onehot)[:, :, 0, :] / counts[None]
    level_of = _level_codes(design)[stimulus_matrix]                 # n × t × positions → level index
    k = len(design.alternatives.levels)
    if design.response_type == "afc":
        chosen = np.take_along_axis(np.broadcast_to(level_of, draws.shape + level_of.shape[-1:]),
                                    draws[..., None], axis=-1)[..., 0]
        hits = (chosen[..., None] == np.arange(k)).astype(float)     # s × n × t × k
        values = np.matmul(onehot.transpose(0, 2, 1), hits) / counts[None, :, :, None] * 100.0
    else:
        order = np.take_along_axis(np.broadcast_to(level_of, draws.shape), draws, axis=-1)  # levels best first
        points = np.zeros(order.shape)
        np.put_along_axis(points, order, np.arange(k, 0, -1, dtype=float)[None, None, None, :], axis=-1)
        values = np.matmul(onehot.transpose(0, 2, 1), points) / counts[None, :, :, None]
    return values.reshape(values.shape[0], values.shape[1], -1)


def _level_codes(design: DesignInfo) -> np.ndarray:
    """Per stimulus and screen position, the index of the alternatives level shown there."""
    levels = design.alternatives.levels
    rows = [[levels.index(x) for x in arrangement_of(r)] for r in design.conditions.to_dict("records")]
    width = max(len(r) for r in rows)
    return np.array([r + [0] * (width - len(r)) for r in rows])
