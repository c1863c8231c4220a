"""Tests of choice shares with the participant as the unit of analysis.

A participant who gives several answers (several rankings, votes in several cells, 24 left/right
choices) gives answers that are not independent: someone who prefers a walk prefers it on every trial.
Pooling all answers into one binomial or χ² test then treats, say, 32 rankings from 16 people as 32
independent observations, and its p is too small whenever participants differ. Every test here
therefore aggregates per participant first:

- :func:`share_test` — is one outcome (a level ranked or chosen first, a screen position chosen) more
  frequent than chance 1/k? With **one answer per participant** the answers are independent and the
  exact binomial test over participants is used (Clopper–Pearson 95 % CI). With **several answers per
  participant** each participant's share of answers is one observation: a one-sample t-test of the shares
  against 1/k (df = participants − 1; 95 % t interval of the mean share, clipped to [0, 1]), the usual
  "chance-level" test of psychophysics. Both weight every participant equally.
- :func:`friedman_counts` — do the k outcomes differ in frequency? Friedman test of the per-participant
  counts, participants as blocks (ties corrected as :func:`scipy.stats.friedmanchisquare`, which it
  equals for k ≥ 3; it also works for k = 2, where it is the sign test's χ²).
- :func:`votes_test` — the test of equal vote shares for a set of participants: the χ² goodness of fit of
  the pooled counts when every participant voted once (valid then), otherwise :func:`friedman_counts`.

>>> r = share_test([1, 0, 1, 1, 0, 1, 1, 1], [1] * 8, k=4, label="mod")
>>> r["test"], r["successes"], r["participants"], round(r["p"], 4)
('exact binomial over participants', 6, 8, 0.0042)
>>> r = share_test([2, 1, 2, 1, 0, 2], [2] * 6, k=4, label="mod")
>>> r["test"], round(r["share"], 3), r["df"], round(r["p"], 4)
('one-sample t-test over participants', 0.667, 5, 0.0545)
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from analysis.errors import AnalysisError
from analysis.measures import chi2_votes

BINOMIAL = "exact binomial over participants"
T_TEST = "one-sample t-test over participants"


def share_test(hits, answers, k: int, label: str) -> dict:
    """Is ``label`` more (or less) frequent than chance 1/``k``? One test with participants as the unit.

    ``hits[i]`` of participant i's ``answers[i]`` answers were ``label``. Two-sided.

    Returns ``test``, ``label``, ``successes`` (all hits), ``n`` (all answers), ``participants``, ``share``
    (the mean per-participant share), ``t`` and ``df`` (t-test only, else NaN), ``p``, ``ci_low``,
    ``ci_high`` (95 % CI of the share).
    """
    hits = np.asarray(hits, dtype=float)
    answers = np.asarray(answers, dtype=float)
    if len(hits) == 0 or np.any(answers < 1) or np.any(hits > answers) or np.any(hits < 0):
        raise AnalysisError(f"share test of {label!r}: need participants with 1 or more answers and "
                            f"0 ≤ hits ≤ answers")
    base = {"label": label, "successes": int(hits.sum()), "n": int(answers.sum()), "participants": len(hits)}
    if np.all(answers == 1):
        # one answer each: the participants' answers are independent Bernoulli draws, the binomial is exact
        result = stats.binomtest(int(hits.sum()), len(hits), 1.0 / k)
        ci = result.proportion_ci(confidence_level=0.95)
        return {"test": BINOMIAL, **base, "share": float(hits.mean()), "t": math.nan, "df": math.nan,
                "p": float(result.pvalue), "ci_low": float(ci.low), "ci_high": float(ci.high)}
    return {"test": T_TEST, **base, **_t_test(hits / answers, 1.0 / k)}


def _t_test(shares: np.ndarray, chance: float) -> dict:
    """One-sample t-test of per-participant shares against ``chance``; undefined (NaN) below 2 participants.

    Without any spread (every participant has the same share) t is ±∞ and p is 0 when that share is not
    chance, NaN when it is — scipy's limits, kept so that "everyone always chose left" is not silent.
    """
    mean = float(shares.mean())
    if len(shares) < 2:
        return {"share": mean, "t": math.nan, "df": math.nan, "p": math.nan, "ci_low": math.nan, "ci_high": math.nan}
    if np.all(shares == shares[0]):
        t = math.nan if mean == chance else math.copysign(math.inf, mean - chance)
        return {"share": mean, "t": t, "df": len(shares) - 1, "p": math.nan if mean == chance else 0.0,
                "ci_low": mean, "ci_high": mean}
    result = stats.ttest_1samp(shares, chance)
    ci = result.confidence_interval(confidence_level=0.95)
    # a share lies in [0, 1]; the symmetric t interval can cross those bounds near 0 or 1
    return {"share": mean, "t": float(result.statistic), "df": int(result.df), "p": float(result.pvalue),
            "ci_low": max(0.0, float(ci.low)), "ci_high": min(1.0, float(ci.high))}


def friedman_counts(counts) -> dict:
    """Friedman test of a participants × k table of counts (or shares), participants as blocks.

    Ranks within each participant (ties averaged), χ² with k − 1 df and the usual tie correction.

    >>> r = friedman_counts([[3, 1, 0], [2, 2, 0], [4, 0, 0], [3, 0, 1]])
    >>> round(r["statistic"], 4), r["df"], round(r["p"], 4)
    (5.5714, 2, 0.0617)
    """
    counts = np.asarray(counts, dtype=float)
    n, k = counts.shape
    if n < 2 or k < 2:
        return {"test": "Friedman", "statistic": math.nan, "df": k - 1, "p": math.nan, "participants": n}
    ranks = stats.rankdata(counts, axis=1)
    ties = sum(float(np.sum(c ** 3 - c)) for c in (np.unique(row, return_counts=True)[1] for row in ranks))
    correction = 1.0 - ties / (n * (k ** 3 - k))
    if correction <= 0:   # every participant gave every outcome the same count: nothing to compare
        return {"test": "Friedman", "statistic": math.nan, "df": k - 1, "p": math.nan, "participants": n}
    sums = ranks.sum(axis=0)
    statistic = (12.0 / (n * k * (k + 1)) * float(np.sum(sums ** 2)) - 3.0 * n * (k + 1)) / correction
    return {"test": "Friedman", "statistic": float(statistic), "df": k - 1,
            "p": float(stats.chi2.sf(statistic, k - 1)), "participants": n}


def votes_test(counts) -> dict:
    """Equal vote shares? ``counts``: participants × levels (votes per participant and level).

    One vote per participant: χ² goodness of fit of the pooled counts (independent votes). More: Friedman
    of the per-participant counts (:func:`friedman_counts`), as the pooled χ² would count one person's
    votes as independent. Returns ``test``, ``statistic`` (χ², k − 1 df either way), ``df``, ``p``, ``n``
    (votes) and ``participants``.
    """
    counts = np.asarray(counts, dtype=float)
    n_votes = int(counts.sum())
    if np.all(counts.sum(axis=1) <= 1):
        return {**chi2_votes(counts.sum(axis=0)), "participants": len(counts)}
    return {**friedman_counts(counts), "n": n_votes}
