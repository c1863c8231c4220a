"""Simulation-based power analysis: how often does the planned analysis reject, per effect, for N participants?

Data sets are drawn from a generative model (:mod:`analysis.simulate`), reduced to the design's
dependent measure all at once (:func:`analysis.measures.measure_arrays`) and analysed by the vectorised
ANOVA path (:func:`analysis.anova.anova_many`); k-AFC vote designs use the χ² goodness-of-fit test and
ranking designs the Friedman test. The rejection rate of each effect comes with a 95 % Clopper–Pearson
interval. :func:`power_sweep` repeats this over several N and :func:`required_participants` answers
"how many participants for 80 % power on BODY×MOTION?".

>>> from analysis.io_design import load_design                                  # doctest: +SKIP
>>> d = load_design("design"); m = load_model(None, d)                           # doctest: +SKIP
>>> power_analysis(d, m, participants=16, sims=500, seed=1).table                # doctest: +SKIP
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from analysis.anova import anova_many
from analysis.anova_core import Design as AnovaDesign
from analysis.errors import AnalysisError
from analysis.io_design import DesignInfo
from analysis.measures import measure_arrays, within_levels
from analysis.model_spec import GenerativeModel
from analysis.participant_tests import votes_test
from analysis.simulate import TrialPlan, check_seed, draw, trial_plan

CHUNK = 250   # data sets per vectorised batch: bounded memory, frequent progress updates


@dataclass
class PowerResult:
    """Rejection rate per effect for one N: columns effect, rejections, sims, power, ci_low, ci_high."""

    participants: int
    sims: int
    alpha: float
    table: pd.DataFrame
    seconds: float

    @property
    def datasets_per_second(self) -> float:
        return self.sims / self.seconds if self.seconds > 0 else float("inf")


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact binomial confidence interval of a rejection rate k/n.

    >>> [round(x, 4) for x in clopper_pearson(50, 1000)]
    [0.0373, 0.0654]
    """
    ci = stats.binomtest(int(k), int(n)).proportion_ci(confidence_level=level, method="exact")
    return float(ci.low), float(ci.high)


def anova_design(design: DesignInfo, plan: TrialPlan) -> AnovaDesign:
    """The ANOVA engine's design for the plan's participants (between groups in participant order)."""
    between = {b: design.factor(b).levels for b in design.between}
    codes = np.array([[design.factor(b).levels.index(str(g)) for b, g in zip(design.between, row)]
                      for row in plan.groups[design.between].itertuples(index=False)]) if between else None
    within = within_levels(design)
    if between:
        return AnovaDesign.make(within=within, between=between, groups=codes)
    return AnovaDesign.make(within=within, n_subjects=len(plan.groups))


def informative_effects(design: DesignInfo, effects: list[str]) -> list[str]:
    """Effects the measure can test: with percentages or rank points the alternatives always sum to a
    constant within a cell, so only effects that involve the alternatives factor carry information."""
    if design.response_type == "likert":
        return list(effects)
    alt = design.alternatives.name
    return [e for e in effects if alt in e.split(":")]


def power_analysis(design: DesignInfo, model: GenerativeModel, participants: int, sims: int, seed: int,
                   alpha: float | None = None, progress: bool = False, correction: str = "none") -> PowerResult:
    """Rejection rates of the design's planned tests over ``sims`` simulated data sets of N participants.

    ``correction`` ("none" as the paper, "gg" or "hf") applies a sphericity correction to the ANOVA p-values.
    """
    if correction not in ("none", "gg", "hf"):
        raise AnalysisError(f"--correction: expected none, gg or hf, got {correction!r}")
    if sims < 1:
        raise AnalysisError(f"--sims: expected a positive number of simulated data sets, got {sims}")
    check_seed(seed)
    alpha = design.alpha if alpha is None else alpha
    rng = np.random.default_rng([seed, participants])
    plan = trial_plan(design, participants)
    start = time.perf_counter()
    if design.dependent_measure in ("votes", "rank_points"):
        names, rejections = _nonparametric(design, model, plan, rng, sims, alpha, progress)
    else:
        names, rejections = _anova_rejections(design, model, plan, rng, sims, alpha, progress, correction)
    seconds = time.perf_counter() - start
    rows = []
    for name, k in zip(names, rejections):
        low, high = clopper_pearson(k, sims)
        rows.append({"effect": name, "rejections": int(k), "sims": sims, "power": k / sims, "ci_low": low,
                     "ci_high": high})
    return PowerResult(participants, sims, alpha, pd.DataFrame(rows), seconds)


def _chunks(sims: int, progress: bool, label: str):
    from tqdm import tqdm
    bar = tqdm(total=sims, desc=label, unit="data sets", disable=not progress, leave=False)
    done = 0
    while done < sims:
        size = min(CHUNK, sims - done)
        yield size
        done += size
        bar.update(size)
    bar.close()


def _anova_rejections(design, model, plan, rng, sims, alpha, progress, correction):
    compiled = anova_design(design, plan).compile()
    names, counts = None, None
    for size in _chunks(sims, progress, f"N={len(plan.groups)}"):
        Y = measure_arrays(design, plan.test, draw(design, model, plan, rng, sims=size))
        result = anova_many(Y, compiled, alpha=alpha, sphericity=correction != "none")
        hits = result.rejections(alpha, correction).to_numpy()
        names = result.effects
        counts = hits if counts is None else counts + hits
    keep = informative_effects(design, names)
    return keep, [int(counts[names.index(e)]) for e in keep]


def _nonparametric(design, model, plan, rng, sims, alpha, progress):
    """The report's test of each data set: equal vote shares (k-AFC: χ² with one vote per participant,
    else Friedman of the per-participant counts, :func:`analysis.participant_tests.votes_test`) or
    Friedman on rank points (rankings)."""
    k = len(design.alternatives.levels)
    trials = _trials_per_participant(plan)
    hits = 0
    for size in _chunks(sims, progress, f"N={len(plan.groups)}"):
        values = measure_arrays(design, plan.test, draw(design, model, plan, rng, sims=size))
        per_level = values.reshape(size, values.shape[1], -1, k).mean(axis=2)      # sims × n × k
        for one in per_level:
            if design.dependent_measure == "votes":
                # whole votes: float noise in the shares would break the Friedman test's ties
                p = votes_test(np.rint(one / 100.0 * trials))["p"]
            else:
                p = stats.friedmanchisquare(*one.T).pvalue if len(one) > 1 else 1.0
            hits += int(np.nan_to_num(p, nan=1.0) < alpha)
    test = ("χ² votes" if trials == 1 else "Friedman votes") if design.dependent_measure == "votes" else "Friedman"
    return [f"{design.alternatives.name} ({test})"], [hits]


def _trials_per_participant(plan: TrialPlan) -> int:
    return plan.test.shape[1]


def power_sweep(design: DesignInfo, model: GenerativeModel, participants: list[int], sims: int, seed: int,
                alpha: float | None = None, progress: bool = False, correction: str = "none",
                scheduler=None) -> pd.DataFrame:
    """:func:`power_analysis` for each N; one row per N × effect, plus data sets per second.

    ``scheduler`` (a ``shapemotion.execution.Scheduler``): each N is one task on that Dask cluster. Every
    N draws from its own generator seeded ``[seed, N]``, so the rejections are those of the local run.
    """
    repeated = sorted({n for n in participants if list(participants).count(n) > 1})
    if repeated:   # one column per N in the table: a repeat would only cost time and break the layout
        raise AnalysisError(f"--participants: N = {', '.join(map(str, repeated))} given more than once; "
                            f"list each number of participants once")
    if scheduler is None:
        results = [power_analysis(design, model, n, sims, seed, alpha, progress, correction) for n in participants]
    else:
        results = _distributed_results(scheduler, design, model, participants, sims, seed, alpha, correction,
                                       progress)
    frames = [r.table.assign(participants=r.participants, datasets_per_second=r.datasets_per_second) for r in results]
    table = pd.concat(frames, ignore_index=True)
    return table[["participants", "effect", "rejections", "sims", "power", "ci_low", "ci_high", "datasets_per_second"]]


def _distributed_results(scheduler, design, model, participants, sims, seed, alpha, correction,
                         progress) -> list[PowerResult]:
    """:func:`power_analysis` of each N as a Dask task keyed by a hash of its inputs; in ``participants`` order."""
    from dask.base import tokenize

    from shapemotion.execution import dask_client, run_tasks

    inputs = (str(design.directory), model.model_dump_json(), sims, seed, alpha, correction)
    tasks = {f"power-N{n}-{tokenize(n, *inputs)}": (design, model, n, sims, seed, alpha, False, correction)
             for n in participants}
    with dask_client(scheduler, announce=lambda line: print(line, file=sys.stderr)) as client:
        done = dict(run_tasks(client, power_analysis, tasks, "power", "N", progress))
    return [done[key] for key in tasks]


def required_participants(sweep: pd.DataFrame, effect: str, target: float = 0.8) -> int | None:
    """The smallest N of the sweep whose estimated power on ``effect`` reaches ``target`` (None if none)."""
    check_target(target)
    wanted = _canonical(effect)
    rows = sweep[sweep["effect"].map(_canonical) == wanted]
    if rows.empty:
        raise AnalysisError(f"--effect: {effect!r} is not one of the effects {sorted(sweep['effect'].unique())}")
    hits = rows[rows["power"] >= target]
    return int(hits["participants"].min()) if not hits.empty else None


def required_text(sweep: pd.DataFrame, effect: str, target: float, required: int | None) -> str:
    """The sweep's answer in words, bounded by the N tried: at the smallest N the power may already be reached
    with fewer participants, and beyond the largest N nothing is known.

    >>> sweep = pd.DataFrame({"participants": [8, 16], "effect": ["A", "A"], "power": [0.5, 0.9]})
    >>> required_text(sweep, "A", 0.8, 16)
    'A: power 0.8 needs more than 8 and at most 16 participants (N = 16 reaches 0.900; N = 8: 0.500)'
    """
    rows = sweep[sweep["effect"].map(_canonical) == _canonical(effect)].sort_values("participants")
    power = dict(zip(rows["participants"], rows["power"]))
    tried = list(power)
    if required is None:
        largest = tried[-1]
        return (f"{effect}: none of N = {', '.join(map(str, tried))} reaches power {target:g} (largest N = {largest}: "
                f"{power[largest]:.3f}); more than {largest} participants are needed, try larger N")
    if required == tried[0]:
        return (f"{effect}: power {target:g} is already reached at the smallest N tried ({required}: "
                f"{power[required]:.3f}), so at most {required} participants are needed; try smaller N to know more")
    below = tried[tried.index(required) - 1]
    return (f"{effect}: power {target:g} needs more than {below} and at most {required} participants "
            f"(N = {required} reaches {power[required]:.3f}; N = {below}: {power[below]:.3f})")


def check_target(target: float) -> None:
    """Power is a probability: a target of 0 is always met and one of 1 or more never is."""
    if not 0 < target < 1:
        raise AnalysisError(f"--target: expected a power between 0 and 1 (e.g. 0.8), got {target:g}")


def _canonical(name: str) -> frozenset:
    for sep in ("*", "×", " x "):
        name = name.replace(sep, ":")
    return frozenset(p.strip().upper() for p in name.split(":") if p.strip())
