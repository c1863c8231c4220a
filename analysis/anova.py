"""Split-plot (mixed) ANOVA for any number of within and between factors — the public API.

    table = anova(data, dv="rating", subject="participant",
                  within=["GAIT", "BODY", "MOTION"], between=["SEX"])
    table.effects            # DataFrame, one row per effect (index "GAIT:SEX" …)
    table.strata             # DataFrame, the error strata (SS, df, MS)
    table.to_records()       # list of dicts, DESIGN.md's ANOVA JSON schema

    res = anova_many(Y, design)   # Y: datasets × subjects × cells; res.p is datasets × effects

Type III sums of squares (sum-to-zero coding of the between factors), unequal group sizes, Mauchly's
test, Greenhouse–Geisser and Huynh–Feldt ε, partial and generalised η², non-centrality λ = F·df1 and
observed power. The engine is in ``analysis.anova_core``; checks and reshaping in ``analysis.anova_data``.

Naming: an effect lists its within factors first, then its between factors, each in the order given
(``GAIT:SEX``, as Statistica and the paper). Any order and ``:``/``*``/``×`` separators are accepted by
``AnovaTable.effect``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from analysis.anova_core import CompiledDesign, Design, mauchly, observed_power
from analysis.anova_data import prepare
from analysis.errors import AnalysisError

__all__ = ["AnovaTable", "Design", "ManyResult", "anova", "anova_many", "observed_power", "mauchly", "EFFECT_COLUMNS",
           "CORRECTED_POWER", "corrected_p", "reported_statistics"]

# Columns of AnovaTable.effects, in order (also the JSON record keys, with "effect" and "factors").
EFFECT_COLUMNS = [
    "ss", "df1", "df2", "ms", "mse", "F", "p", "eta2_partial", "eta2_generalized", "noncentrality", "power",
    "eps_gg", "p_gg", "eps_hf", "p_hf", "mauchly_w", "mauchly_p",
]


def _canonical(name: str) -> frozenset[str]:
    for sep in ("*", "×", " x ", "/"):
        name = name.replace(sep, ":")
    return frozenset(p.strip() for p in name.split(":") if p.strip())


@dataclass
class AnovaTable:
    """The result of :func:`anova`.

    Attributes:
        effects: DataFrame indexed by effect name, columns ``factors`` (tuple), ``order`` (number of
            factors), ``error`` (label of its error stratum) and :data:`EFFECT_COLUMNS`. Sphericity
            columns are NaN where the effect's within part has 1 df (or none). ``eps_hf`` is capped at 1.
        strata: DataFrame indexed by error-stratum label (``Error`` = between subjects,
            ``Error(GAIT)`` = GAIT × subject, …), columns ``ss``, ``df``, ``ms``.
        design: the :class:`Design` (levels of every factor; between group of every subject).
        Y: subjects × cells array of cell means (cells in ``design.cells`` order).
        counts: subjects × cells array, number of input rows averaged into each cell mean.
        subjects: subject labels in row order of ``Y``.
        posthoc: effect name → :class:`analysis.posthoc.PosthocResult`, filled by ``posthoc.tukey``.
    """

    dv: str
    subject: str
    within: tuple[str, ...]
    between: tuple[str, ...]
    alpha: float
    effects: pd.DataFrame
    strata: pd.DataFrame
    design: Design
    Y: np.ndarray
    counts: np.ndarray
    subjects: tuple[str, ...]
    observed: tuple[str, ...] = ()
    posthoc: dict = field(default_factory=dict)

    @property
    def levels(self) -> dict[str, tuple[str, ...]]:
        return {**self.design.between, **self.design.within}

    @property
    def n_subjects(self) -> int:
        return len(self.subjects)

    @property
    def group_sizes(self) -> pd.Series:
        """Number of subjects per between-subjects cell (a single ``all`` entry without between factors)."""
        if not self.between:
            return pd.Series({"all": self.n_subjects}, name="n")
        g = pd.DataFrame(self.design.groups, columns=list(self.between))
        for f in self.between:
            g[f] = [self.design.between[f][i] for i in g[f]]
        return g.value_counts(sort=False).sort_index().rename("n")

    @property
    def rows_per_cell(self) -> tuple[int, int]:
        """(min, max) number of input rows averaged into one subject × cell mean."""
        return int(self.counts.min()), int(self.counts.max())

    def effect_name(self, name: str) -> str:
        """The canonical name of an effect given in any factor order / separator (``SEX*GAIT`` → ``GAIT:SEX``)."""
        want = _canonical(name)
        for e, facs in zip(self.effects.index, self.effects["factors"]):
            if frozenset(facs) == want:
                return e
        raise AnalysisError(f"no effect {name!r} in this ANOVA; effects are: {', '.join(self.effects.index)}")

    def effect(self, name: str) -> pd.Series:
        """One row of :attr:`effects`, looked up by name in any factor order."""
        return self.effects.loc[self.effect_name(name)]

    def significant(self, alpha: float | None = None, correction: str = "none") -> list[str]:
        """Effects with p < alpha (``correction``: ``none``, ``gg`` or ``hf``, where available)."""
        a = self.alpha if alpha is None else alpha
        return [e for e in self.effects.index if corrected_p(self.effects.loc[e], correction) < a]

    def to_records(self) -> list[dict]:
        """DESIGN.md's ANOVA JSON: one dict per effect; NaN → None; post-hoc pairs and summary when run.

        Where Tukey ran on an effect whose error term has no variance, its pairs carry q = p = None, the
        summary is None and ``posthoc_untestable`` (a key present only then) says why.

        JSON has no ∞: an infinite F (and nc), where the effect is real but its error term has no
        variance, is also None — told apart from an untestable effect (F = 0/0, p None) by p = 0 and
        power = 1, exactly what the tables print as ``∞``, ``<0.001`` and ``1.00``.
        """
        out = []
        for name, row in self.effects.iterrows():
            rec = {"effect": name, "factors": list(row["factors"])}
            for c in EFFECT_COLUMNS:
                v = float(row[c])
                rec[c] = None if not math.isfinite(v) else v
            ph = self.posthoc.get(name)
            rec["posthoc"] = ph.records() if ph is not None else []
            rec["summary"] = ph.summary if ph is not None and not ph.untestable else None
            if ph is not None and ph.untestable:   # Tukey asked for but nothing testable: q, p null, and why
                rec["posthoc_untestable"] = ph.untestable
            out.append(rec)
        return out

    def to_json(self, indent: int | None = 2) -> str:
        return json.dumps(self.to_records(), indent=indent, ensure_ascii=False, allow_nan=False)


def corrected_p(row: pd.Series, correction: str = "none") -> float:
    """The p of an effect row with the chosen sphericity correction (uncorrected where none applies)."""
    correction = correction.lower()
    if correction in ("none", ""):
        return float(row["p"])
    key = {"gg": "p_gg", "hf": "p_hf"}.get(correction)
    if key is None:
        raise AnalysisError(f"unknown sphericity correction {correction!r}; use none, gg or hf")
    v = float(row[key])
    return float(row["p"]) if math.isnan(v) else v


CORRECTED_POWER = ("spss", "uncorrected")


def reported_statistics(row: pd.Series, correction: str = "none", corrected_power: str = "spss",
                        alpha: float = 0.05) -> dict[str, float]:
    """ε, df1, df2, p, nc and observed power of an effect row as a table reports them under ``correction``.

    ``none``: the row's own numbers (ε NaN). ``gg`` / ``hf``: df1 and df2 multiplied by ε (HF capped at 1)
    and the corrected p; nc and power then follow ``corrected_power``:

    * ``spss`` (default): SPSS's reading of its corrected rows — λ = F·df1·ε and observed power from the
      non-central F with the corrected df, i.e. the power of the corrected test the row reports;
    * ``uncorrected``: λ = F·df1 and power with the uncorrected df (the sphericity-assumed values, as
      before), whatever the row's df and p.

    Where the effect has no correction (d = 1) or ε is undefined (singular error SSCP), ε is NaN and every
    number is the uncorrected one.

    >>> row = pd.Series({"F": 4.0, "df1": 2.0, "df2": 20.0, "p": 0.0346, "noncentrality": 8.0, "power": 0.65,
    ...                  "eps_gg": 0.6, "p_gg": 0.066, "eps_hf": 0.7, "p_hf": 0.055})
    >>> r = reported_statistics(row, "gg")
    >>> round(r["df1"], 2), round(r["df2"], 1), round(r["nc"], 2), round(r["power"], 4)
    (1.2, 12.0, 4.8, 0.4875)
    >>> reported_statistics(row, "gg", corrected_power="uncorrected")["nc"]
    8.0
    """
    correction = (correction or "none").lower()
    if corrected_power not in CORRECTED_POWER:
        raise AnalysisError(f"unknown corrected-power reading {corrected_power!r}; use spss or uncorrected")
    p = corrected_p(row, correction)   # first: it refuses an unknown correction
    eps = float(row["eps_gg" if correction == "gg" else "eps_hf"]) if correction != "none" else float("nan")
    scale = 1.0 if math.isnan(eps) else eps
    out = {"eps": eps, "df1": float(row["df1"]) * scale, "df2": float(row["df2"]) * scale, "p": p,
           "nc": float(row["noncentrality"]), "power": float(row["power"])}
    if scale != 1.0 and corrected_power == "spss":
        F = float(row["F"])
        out["nc"] = F * out["df1"]
        out["power"] = float(observed_power(F, out["df1"], out["df2"], alpha)) if not math.isnan(F) else float("nan")
    return out


def anova(
    data: pd.DataFrame,
    dv: str,
    subject: str,
    within: list[str] | tuple[str, ...] = (),
    between: list[str] | tuple[str, ...] = (),
    alpha: float = 0.05,
    observed: list[str] | tuple[str, ...] = (),
) -> AnovaTable:
    """Split-plot ANOVA of long-format ``data`` (one row per subject × cell; repeated rows are averaged).

    ``alpha`` is the level for observed power (and the default significance level of tables and
    post-hoc tests). ``observed`` names measured (not manipulated) factors for generalised η²
    (Olejnik & Algina 2003; afex's ``observed``). Raises ``AnalysisError`` on bad data.
    """
    if not 0 < alpha < 1:
        raise AnalysisError(f"alpha must be between 0 and 1, got {alpha}")
    observed = tuple(observed or ())
    for o in observed:
        if o not in tuple(within or ()) + tuple(between or ()):
            raise AnalysisError(f"observed factor {o!r} is not one of the factors")
    prep = prepare(data, dv, subject, within, between)
    comp = CompiledDesign(prep.design)
    res = comp.fit(prep.Y, alpha=alpha)
    names = [e.name for e in comp.effects]
    if observed:
        # afex: ges = SS / (SS + Σ error SS + Σ SS of effects with a measured factor − own SS if measured)
        ss = res["ss"]
        obs = np.array([any(o in e.factors for o in observed) for e in comp.effects])
        res["eta2_generalized"] = ss / (ss + res["stratum_ss"].sum() + (ss * obs).sum() - ss * obs)
    err_label = ["Error" if not s else f"Error({s})" for s in comp.stratum_names]
    cols = {"factors": [e.factors for e in comp.effects], "order": [e.order for e in comp.effects],
            "error": [err_label[i] for i in comp.eff_s], **{c: res[c] for c in EFFECT_COLUMNS}}
    eff = pd.DataFrame(cols, index=pd.Index(names, name="effect"))
    strata = pd.DataFrame(
        {"ss": res["stratum_ss"], "df": res["stratum_df"].astype(float)}, index=pd.Index(err_label, name="stratum")
    )
    strata["ms"] = strata["ss"] / strata["df"]
    return AnovaTable(
        dv=dv, subject=subject, within=tuple(within), between=tuple(between), alpha=alpha, effects=eff,
        strata=strata, design=prep.design, Y=prep.Y, counts=prep.counts, subjects=prep.subjects, observed=observed,
    )


@dataclass
class ManyResult:
    """Result of :func:`anova_many`: arrays of shape (datasets, effects), columns in ``effects`` order.

    Fields: ``ss, df1, df2, ms, mse, F, p, eta2_partial, eta2_generalized, noncentrality`` and, when
    requested, ``power``, ``eps_gg, p_gg, eps_hf, p_hf, mauchly_w, mauchly_p``.
    """

    effects: list[str]
    arrays: dict[str, np.ndarray]

    def __getattr__(self, key):
        try:
            return self.__dict__["arrays"][key]
        except KeyError:
            raise AttributeError(key) from None

    def frame(self, stat: str = "p") -> pd.DataFrame:
        """One statistic as a DataFrame (datasets × effects)."""
        return pd.DataFrame(self.arrays[stat], columns=self.effects)

    def rejections(self, alpha: float = 0.05, correction: str = "none") -> pd.Series:
        """Number of data sets with p < alpha, per effect (``correction`` none/gg/hf where available; an
        effect with 1 df has no correction and keeps its p; a NaN p is no rejection)."""
        p = self.arrays["p"]
        if correction.lower() != "none":
            key = {"gg": "p_gg", "hf": "p_hf"}[correction.lower()]
            p = np.where(np.isnan(self.arrays[key]), p, self.arrays[key])
        return pd.Series((p < alpha).sum(axis=0), index=self.effects, name="rejections")

    def rejection_rate(self, alpha: float = 0.05, correction: str = "none") -> pd.Series:
        """Share of data sets with p < alpha, per effect (see :meth:`rejections`)."""
        n = self.arrays["p"].shape[0]
        return (self.rejections(alpha, correction) / n).rename("rejection_rate")


def anova_many(
    Y: np.ndarray,
    design: Design | CompiledDesign,
    alpha: float = 0.05,
    sphericity: bool = True,
    power: bool = False,
) -> ManyResult:
    """Vectorised ANOVA of many data sets sharing one design (for power simulation).

    ``Y`` has shape (datasets, subjects, cells) — or (subjects, cells) for one — with cells in
    ``design.cells`` order (C order of the within levels, first factor slowest) and subjects in the
    order of ``design.groups``. Pass a compiled design (``design.compile()``) when calling repeatedly.
    """
    comp = design if isinstance(design, CompiledDesign) else CompiledDesign(design)
    Y = np.asarray(Y, dtype=float)
    if Y.ndim == 2:
        Y = Y[None]
    res = comp.fit(Y, alpha=alpha, sphericity=sphericity, power=power)
    arrays = {k: v for k, v in res.items() if k not in ("stratum_ss", "stratum_df", "eps_hf_raw")}
    return ManyResult(effects=[e.name for e in comp.effects], arrays=arrays)
