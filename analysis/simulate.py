"""Synthetic participants: draw responses to a design from a :class:`~analysis.model_spec.GenerativeModel`.

Everything is vectorised over data sets (``sims``), participants and trials, so the same code writes one
realistic response file (:func:`simulate_responses`) and feeds thousands of data sets to the power
analysis (:func:`draw`).

>>> from analysis.io_design import load_design                         # doctest: +SKIP
>>> from analysis.model_spec import load_model                          # doctest: +SKIP
>>> d = load_design("design"); m = load_model(None, d)                  # doctest: +SKIP
>>> simulate_responses(d, m, participants=16, seed=1).head()            # doctest: +SKIP

Every simulated trial carries ``shapemotion_simulated`` = 1, and every export format writes it (a long-CSV
column, Qualtrics embedded data, a jsPsych data property), so a report built from a simulated file can say so
(:func:`simulated_export`) however often the file is converted or re-imported.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.errors import AnalysisError
from analysis.io_design import DesignInfo, arrangement_of
from analysis.model_spec import GenerativeModel
from analysis.practice import practice_flags


SIMULATED_COLUMN = "shapemotion_simulated"   # 1 on every row of a simulated export; real exports lack it
TRUE_TEXT = {"1", "true", "yes"}


def simulated_export(path: str | Path) -> bool:
    """Does the response file (or any file of a response folder) hold rows that ``shapemotion simulate`` wrote?

    True when a row has :data:`SIMULATED_COLUMN` set (``1``/``true``): the column the tool's own exports
    carry in every format. A real export has no such column; one that names it without a true value on any
    row is not simulated either.

    >>> import tempfile
    >>> p = Path(tempfile.mkdtemp()) / "r.csv"
    >>> _ = p.write_text("participant,stimulus_id,response,shapemotion_simulated\\n1,s1,3,1\\n")
    >>> simulated_export(p), simulated_export(p.with_name("none.csv"))
    (True, False)
    """
    from analysis.responses.read import read_response_file, response_files

    path = Path(path)
    files = response_files(path) if path.is_dir() else [path] if path.is_file() else []
    return any(_has_simulated_rows(read_response_file(f)) for f in files)


def _has_simulated_rows(raw) -> bool:
    if raw.format == "jspsych-json":
        return any(str(r.get(SIMULATED_COLUMN, "")).strip().lower() in TRUE_TEXT for r in raw.rows
                   if isinstance(r, dict))
    if SIMULATED_COLUMN not in raw.columns:
        return False
    i = raw.columns.index(SIMULATED_COLUMN)
    return any(len(r) > i and str(r[i]).strip().lower() in TRUE_TEXT for r in raw.rows)


@dataclass
class TrialPlan:
    """Who sees what: per participant the trial list (stimulus index into ``stimuli``), test trials only
    in ``test`` (participants × trials, same count for everyone), and all trials in ``trials``."""

    trials: pd.DataFrame          # participant, <between>, block, trial, stimulus_id, repetition, practice
    stimuli: list[str]            # stimulus ids, the index used by ``test``
    test: np.ndarray              # participants × test trials → stimulus index
    groups: pd.DataFrame          # participant → between levels


def trial_plan(design: DesignInfo, participants: int) -> TrialPlan:
    """Trial lists for ``participants`` people, reusing the design's lists beyond its N.

    Participant p gets the list of the design's participant ((p−1) mod N_design)+1 when that keeps the
    between groups equal (N a multiple of the design's balanced N); otherwise the groups take turns
    (as the protocol's ``assignment: balanced`` promises), each reusing its own design participants in
    order. N must be a positive multiple of the number of groups.
    """
    trials = _design_trials(design)
    parts = []
    for p, base in enumerate(_lists(design, trials, participants), start=1):
        source = trials[trials["participant"] == base].copy()
        source["participant"] = p
        parts.append(source)
    plan = pd.concat(parts, ignore_index=True)
    stimuli = list(design.conditions["stimulus_id"])
    index = {s: i for i, s in enumerate(stimuli)}
    test = plan[~plan["practice"]]
    counts = test.groupby("participant").size()
    if counts.nunique() != 1:
        raise AnalysisError(f"{design.directory}/trials.csv: participants have different numbers of test trials "
                            f"({sorted(counts.unique())}); simulation needs the same number for everyone")
    matrix = test["stimulus_id"].map(index).to_numpy().reshape(participants, -1)
    groups = plan.groupby("participant")[design.between].first().reset_index() if design.between else \
        pd.DataFrame({"participant": range(1, participants + 1)})
    return TrialPlan(plan, stimuli, matrix, groups)


def _design_trials(design: DesignInfo) -> pd.DataFrame:
    """trials.csv without familiarization rows, with whole-number participant, trial and repetition."""
    if design.trials is None:
        raise AnalysisError(f"{design.directory}: trials.csv is missing; it lists each participant's trials")
    where = design.directory / "trials.csv"
    trials = design.trials.copy()
    for column in ("practice", "trial", "repetition"):
        if column not in trials:
            raise AnalysisError(f"{where}: column {column!r} is missing; simulation needs it")
    practice = practice_flags(trials["practice"], where, line_offset=2)
    kind = trials["kind"] if "kind" in trials else np.where(practice, "practice", "test")
    keep = pd.Series(kind, index=trials.index) != "familiarization"
    trials = trials[keep]
    trials["practice"] = practice[keep]
    for column in ("participant", "trial", "repetition"):
        trials[column] = _integers(trials[column], column, where)
    return trials


def _lists(design: DesignInfo, trials: pd.DataFrame, participants: int) -> list[int]:
    """The design participant whose list each simulated participant gets, after checking ``participants``."""
    n_groups = max(1, len(design.test_conditions[design.between].drop_duplicates())) if design.between else 1
    if participants < 1:
        raise AnalysisError(f"--participants: expected a positive number of participants, got {participants}")
    if participants % n_groups:
        raise AnalysisError(f"--participants: {participants} participants cannot be balanced over {n_groups} "
                            f"between-subject groups; use a multiple of {n_groups}")
    return _assign(design, trials, participants)


def list_reuse_note(design: DesignInfo, participants: int) -> str | None:
    """A note when ``participants`` exceeds the trial lists of the design (None otherwise).

    Simulated people beyond the design's N reuse its lists (:func:`trial_plan`), so several of them see the
    same trial order and, with ``counterbalance: between``, the same arrangements — worth knowing before
    reading a simulated study as if it had N distinct lists.

    >>> list_reuse_note(load_design("my_afc"), 16)                       # doctest: +SKIP
    'my_afc/trials.csv lists trials for 8 participants; simulating 16 reuses their lists (each used 2 times),
    simulated → design participant: 9→1, 10→2, 11→3, …, 16→8. For distinct lists, make the design for 16: …'
    """
    trials = _design_trials(design)
    n_design = trials["participant"].nunique()
    if participants <= n_design:
        return None
    lists = _lists(design, trials, participants)
    extra = [f"{p}→{b}" for p, b in enumerate(lists, start=1) if p > n_design]
    shown = ", ".join(extra if len(extra) <= 4 else [*extra[:3], "…", extra[-1]])
    planned = f" (design.json plans {design.participants})" if design.participants not in (0, n_design) else ""
    uses = sorted(set(Counter(lists).values()))
    times = f"each used {uses[0]} times" if len(uses) == 1 else f"each used {uses[0]} to {uses[-1]} times"
    return (f"{design.directory / 'trials.csv'} lists trials for {n_design} participants{planned}; simulating "
            f"{participants} reuses their lists ({times}), simulated → design participant: "
            f"{shown}. For distinct lists, make the design for {participants}: "
            f"`shapemotion design PROTOCOL --participants {participants}`")


def _assign(design: DesignInfo, trials: pd.DataFrame, participants: int) -> list[int]:
    """The design participant whose trial list each of the ``participants`` simulated people reuses.

    Cycling through the design's list keeps the data of N = N_design (and its multiples) as before; when
    cycling would leave the between groups unequal (e.g. N = 4 from a design whose first four are
    F, M, M, M), the groups take turns instead.
    """
    base = sorted(trials["participant"].unique())
    cyclic = [base[p % len(base)] for p in range(participants)]
    if not design.between:
        return cyclic
    group_of = _groups_of(design, trials)
    members: dict[tuple, list[int]] = {}
    for b in base:
        members.setdefault(group_of[b], []).append(b)
    counts = Counter(group_of[b] for b in cyclic)
    if len(counts) == len(members) and len(set(counts.values())) == 1:
        return cyclic
    order = list(members)   # groups in the order of their first design participant
    members = {g: _interleave_block_orders(m, trials) for g, m in members.items()}
    out = []
    for p in range(participants):
        group = members[order[p % len(order)]]
        out.append(group[(p // len(order)) % len(group)])
    return out


def _interleave_block_orders(members: list[int], trials: pd.DataFrame) -> list[int]:
    """A group's design participants with their block orders taking turns (jog-first, walk-first, …), so
    that the first few simulated people of a group are counterbalanced too."""
    if "block_label" not in trials:
        return members
    test = trials.sort_values("trial", kind="stable")
    signature = {p: tuple(dict.fromkeys(rows["block_label"])) for p, rows in test.groupby("participant")}
    by_order: dict[tuple, list[int]] = {}
    for m in members:
        by_order.setdefault(signature[m], []).append(m)
    queues = list(by_order.values())
    return [q[i] for i in range(max(map(len, queues))) for q in queues if i < len(q)]


def _groups_of(design: DesignInfo, trials: pd.DataFrame) -> dict[int, tuple]:
    """Between group of each design participant: trials.csv's columns, else the stimuli of their test trials."""
    if all(b in trials for b in design.between):
        first = trials.groupby("participant")[design.between].first()
        return {p: tuple(str(v) for v in row) for p, row in zip(first.index, first.itertuples(index=False))}
    stimuli = design.stimulus_table()
    tests = trials[~trials["practice"]].groupby("participant")["stimulus_id"].first()
    return {p: tuple(str(stimuli.loc[s, b]) for b in design.between) for p, s in tests.items()}


def _integers(column: pd.Series, name: str, where) -> pd.Series:
    """A whole-number column of trials.csv; a bad cell names its row (line 1 is the header)."""
    numbers = pd.to_numeric(column, errors="coerce")
    bad = numbers.isna() | (numbers % 1 != 0)
    if bad.any():
        row = int(np.flatnonzero(bad.to_numpy())[0])
        raise AnalysisError(f"{where}: row {column.index[row] + 2}: {name} {column.iloc[row]!r} is not a whole number")
    return numbers.astype(int)


# -- the linear predictor -------------------------------------------------------------------------

def fixed_utilities(design: DesignInfo, model: GenerativeModel) -> np.ndarray:
    """Fixed part of the latent value per stimulus × alternative (× screen position for choices).

    Shape (stimuli, A): A = 1 for Likert; for choices column j is the alternative shown at position j+1.
    """
    rows = design.conditions.to_dict("records")
    alt = design.alternatives
    out = []
    for row in rows:
        arrangement = arrangement_of(row) or [None]
        values = []
        for position, level in enumerate(arrangement):
            levels = {f.name: str(row.get(f.name, "")) for f in design.factors if f.role != "alternatives"}
            if alt is not None and level is not None:
                levels[alt.name] = level
            value = model.intercept + sum(_term_value(t, levels) for t in model.effects)
            values.append(value + (model.choice.position_bias if position == 0 and level is not None else 0.0))
        out.append(values)
    width = max(len(v) for v in out)
    return np.array([v + [np.nan] * (width - len(v)) for v in out])


def _term_value(term, levels: dict[str, str]) -> float:
    key = ":".join(levels.get(f, "") for f in term.factors)
    return term.values.get(key, 0.0)


def _random_part(design: DesignInfo, model: GenerativeModel, plan: TrialPlan, rng: np.random.Generator,
                 sims: int) -> np.ndarray:
    """Participant random effects per trial (and position): sims × participants × trials × A."""
    rows = design.conditions.to_dict("records")
    n, t = plan.test.shape
    width = max(1, max(len(arrangement_of(r)) for r in rows))
    total = np.zeros((sims, n, t, width))
    if model.random.intercept_sd and design.response_type == "likert":
        total += rng.normal(0.0, model.random.intercept_sd, (sims, n, 1, 1))
    for name, sd in sorted(model.random.slopes.items()):
        factor = design.factor(name)
        deviations = rng.normal(0.0, sd, (sims, n, len(factor.levels)))
        code = np.array([[factor.levels.index(lv) if lv in factor.levels else -1 for lv in _levels_of(r, name, width)]
                         for r in rows])           # stimuli × A, −1 where the factor does not apply
        per_trial = code[plan.test]               # n × t × A
        gathered = deviations[:, np.arange(n)[:, None, None], np.clip(per_trial, 0, None)]
        total += np.where(per_trial[None] >= 0, gathered, 0.0)
    return total


def _levels_of(row: dict, factor: str, width: int) -> list[str]:
    arrangement = arrangement_of(row)
    if factor in row and row.get(factor, "") != "":
        return [str(row[factor])] * width
    return arrangement + [""] * (width - len(arrangement)) if arrangement else [""] * width


# -- drawing --------------------------------------------------------------------------------------

def draw(design: DesignInfo, model: GenerativeModel, plan: TrialPlan, rng: np.random.Generator,
         sims: int = 1) -> np.ndarray:
    """Responses for ``sims`` data sets: sims × participants × test trials.

    Likert: ratings 1…k. k-AFC: the 0-based screen position chosen. Ranking: an extra last axis with the
    0-based positions best first.
    """
    fixed = fixed_utilities(design, model)[plan.test]            # n × t × A
    latent = fixed[None] + _random_part(design, model, plan, rng, sims)
    if design.response_type == "likert":
        noise = rng.normal(0.0, model.residual_sd, latent.shape[:3])
        return 1 + np.searchsorted(np.asarray(model.thresholds), latent[..., 0] + noise).astype(np.int64)
    if design.response_type == "afc" and latent.shape[-1] == 2:
        # 2AFC: logistic choice, P(right) = σ(u_right − u_left); one logistic draw instead of two Gumbels
        return (rng.logistic(size=latent.shape[:3]) < latent[..., 1] - latent[..., 0]).astype(np.int64)
    gumbel = rng.gumbel(size=latent.shape)
    utility = np.where(np.isnan(latent), -np.inf, latent + gumbel)
    if design.response_type == "afc":
        return np.argmax(utility, axis=-1)
    return np.argsort(-utility, axis=-1, kind="stable")


def simulate_responses(design: DesignInfo, model: GenerativeModel, participants: int, seed: int) -> pd.DataFrame:
    """One synthetic data set as a trial table: the plan's rows (practice included) plus the answers.

    Columns: participant, <between>, block, block_label, trial, stimulus_id, repetition, practice, and
    ``rating`` (Likert), ``position`` (1-based, k-AFC) or ``order`` (positions best first, 1-based,
    ``|``-joined, ranking); ``rt`` in seconds; :data:`SIMULATED_COLUMN` (1), which every export writes.
    """
    check_seed(seed)
    rng = np.random.default_rng(seed)
    plan = trial_plan(design, participants)
    test_answers = draw(design, model, plan, rng, sims=1)[0]
    practice_plan = _practice_plan(design, plan)
    practice_answers = draw(design, model, practice_plan, rng, sims=1)[0] if practice_plan else None
    trials = plan.trials.reset_index(drop=True).copy()
    column = {"likert": "rating", "afc": "position", "ranking": "order"}[design.response_type]
    values = np.empty(len(trials), dtype=object)
    is_test = ~trials["practice"].to_numpy()
    values[is_test] = _format_answers(design, test_answers.reshape(-1, *test_answers.shape[2:]))
    if practice_answers is not None:
        values[~is_test] = _format_answers(design, practice_answers.reshape(-1, *practice_answers.shape[2:]))
    trials[column] = values
    trials["rt"] = np.round(rng.lognormal(np.log(2.5), 0.35, len(trials)), 3)
    trials[SIMULATED_COLUMN] = 1
    return trials


def check_seed(seed: int) -> None:
    """numpy seeds are non-negative integers; say so instead of numpy's traceback."""
    if seed < 0:
        raise AnalysisError(f"--seed: expected a non-negative whole number, got {seed}")


def _practice_plan(design: DesignInfo, plan: TrialPlan) -> TrialPlan | None:
    practice = plan.trials[plan.trials["practice"]]
    if practice.empty:
        return None
    counts = practice.groupby("participant").size()
    if counts.nunique() != 1 or len(counts) != len(plan.groups):
        raise AnalysisError(f"{design.directory}/trials.csv: participants have different numbers of practice trials")
    index = {s: i for i, s in enumerate(plan.stimuli)}
    matrix = practice["stimulus_id"].map(index).to_numpy().reshape(len(counts), -1)
    return TrialPlan(practice, plan.stimuli, matrix, plan.groups)


def _format_answers(design: DesignInfo, answers: np.ndarray) -> list:
    if design.response_type == "likert":
        return [int(a) for a in answers]
    if design.response_type == "afc":
        return [int(a) + 1 for a in answers]
    return ["|".join(str(int(p) + 1) for p in row if p >= 0) for row in answers]
