"""Read a design directory written by the stimuli side: ``design.json``, ``conditions.csv``, ``trials.csv``.

The analysis half never imports ``stimuli``; everything it knows about an experiment (factor roles and
levels, the response scale, the dependent measure, the stimuli and their left/right placement) comes
from these files. :func:`load_design` returns one :class:`DesignInfo`.

>>> from analysis.io_design import load_design            # doctest: +SKIP
>>> d = load_design("demo_output/exp1_shape_motion")       # doctest: +SKIP
>>> d.between, d.within, d.response_type                   # doctest: +SKIP
(['SEX'], ['GAIT', 'BODY', 'MOTION'], 'likert')
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from analysis.errors import AnalysisError
from analysis.practice import practice_flags

# the measures each response type can give, its default first: a rating has no chosen level, a choice no
# rating or ranking
MEASURES_OF_TYPE = {"likert": ("mean_rating",), "afc": ("percent_chosen", "votes"), "ranking": ("rank_points",)}


@dataclass(frozen=True)
class FactorInfo:
    """One independent variable: name, role (between | within | alternatives), levels in order."""

    name: str
    role: str
    levels: list[str]
    abbreviations: dict[str, str] = field(default_factory=dict)
    maps_to: str = "none"

    def abbreviation(self, level: str) -> str:
        return self.abbreviations.get(level, level)


@dataclass
class DesignInfo:
    """Everything the analysis needs to know about one experiment, read from its design directory."""

    directory: Path
    protocol: dict
    factors: list[FactorInfo]
    response_type: str
    labels: list[str]
    k: int
    dependent_measure: str
    chosen_factor: str | None
    participants: int
    seed: int
    conditions: pd.DataFrame
    trials: pd.DataFrame | None
    manifest: pd.DataFrame | None = None
    alpha: float = 0.05
    position_labels: list[str] = field(default_factory=list)
    posthoc: str = "tukey"
    # how the post-hoc pairs are tested (protocol analysis: followup, adjust, means; see analysis.posthoc)
    posthoc_followup: str = "univariate"
    posthoc_adjust: str = "tukey"
    posthoc_means: str | None = None
    # where the dependent measure came from: "dependent_measure", "protocol.analysis.dependent_measure" or
    # "default" (neither set: the response type's first measure)
    dependent_measure_source: str = "default"
    _rows: dict | None = field(default=None, repr=False)

    # -- factor look-ups ------------------------------------------------------------------------
    def factor(self, name: str) -> FactorInfo:
        for f in self.factors:
            if f.name == name:
                return f
        raise KeyError(name)

    @property
    def between(self) -> list[str]:
        return [f.name for f in self.factors if f.role == "between"]

    @property
    def within(self) -> list[str]:
        """Within-participant factors shown on one screen (not the alternatives factor)."""
        return [f.name for f in self.factors if f.role == "within"]

    @property
    def alternatives(self) -> FactorInfo | None:
        """The factor whose levels are the choices of a k-AFC or ranking trial (e.g. METHOD)."""
        if self.chosen_factor:
            return self.factor(self.chosen_factor)
        return next((f for f in self.factors if f.role == "alternatives"), None)

    @property
    def cell_factors(self) -> list[str]:
        """Factors that define one stimulus (between + within, not the alternatives)."""
        return self.between + self.within

    def arrangement(self, stimulus_id: str) -> list[str]:
        """Alternatives levels of a multi-clip stimulus in screen order, left to right ([] for one clip)."""
        row = self._by_id().get(stimulus_id)
        if row is None:
            raise KeyError(stimulus_id)
        return arrangement_of(row)

    def _by_id(self) -> dict:
        if self._rows is None:
            self._rows = {r["stimulus_id"]: r for r in self.conditions.to_dict("records")}
        return self._rows

    @property
    def test_conditions(self) -> pd.DataFrame:
        return self.conditions[~self.conditions["practice"]].reset_index(drop=True)

    @property
    def repetitions(self) -> int:
        return int(self.protocol.get("repetitions", 1) or 1)

    def stimulus_table(self) -> pd.DataFrame:
        """conditions.csv indexed by stimulus_id."""
        return self.conditions.set_index("stimulus_id", drop=False)


def arrangement_of(row: dict) -> list[str]:
    """Screen order of the alternatives in one conditions/trials row (``left``/``right`` or ``positions``)."""
    if row.get("left") and row.get("right"):
        return [str(row["left"]), str(row["right"])]
    if row.get("positions"):
        return str(row["positions"]).split("|")
    return []


def load_design(directory: str | Path) -> DesignInfo:
    """Read ``design.json`` + ``conditions.csv`` (+ ``trials.csv``, ``manifest.csv`` when present)."""
    directory = Path(directory)
    if not directory.is_dir():
        raise AnalysisError(f"{directory}: design directory not found (run `shapemotion design PROTOCOL --out DIR`)")
    meta = _read_json(directory / "design.json")
    conditions = _read_csv(directory / "conditions.csv", required=["stimulus_id"])
    trials_path = directory / "trials.csv"
    trials = _read_csv(trials_path, required=["participant", "stimulus_id"]) if trials_path.exists() else None
    manifest_path = directory / "manifest.csv"
    manifest = _read_csv(manifest_path, required=["stimulus_id"]) if manifest_path.exists() else None
    return design_from_parts(meta, conditions, trials, manifest, directory)


def design_from_parts(meta: dict, conditions: pd.DataFrame, trials: pd.DataFrame | None,
                      manifest: pd.DataFrame | None, directory: Path) -> DesignInfo:
    """Build a :class:`DesignInfo` from already-read parts; checks the fields the analysis relies on."""
    where = directory / "design.json"
    if not isinstance(meta, dict):
        raise AnalysisError(f"{where}: expected a JSON object with fields factors, response, protocol, …; "
                            f"got a {type(meta).__name__}")
    protocol = dict(_mapping(meta, "protocol", where))
    # a design.json from another tool may carry these at the top level only; the analysis reads them from
    # the protocol (the name picks the bundled simulation model, repetitions the valid repetition numbers)
    for key in ("name", "repetitions"):
        if protocol.get(key) is None and meta.get(key) is not None:
            protocol[key] = meta[key]
    factors = [_factor(f, where) for f in _need(meta, "factors", where, protocol)]
    response = _mapping(meta, "response", where) or _mapping(protocol, "response", where, "protocol.")
    rtype = response.get("type")
    if rtype not in MEASURES_OF_TYPE:
        raise AnalysisError(f"{where}: response.type must be likert, afc or ranking, got {rtype!r}")
    labels = [str(x) for x in response.get("labels") or []]
    _check_labels(labels, "response.labels", where)
    _check_labels([str(x) for x in response.get("position_labels") or []], "response.position_labels", where)
    analysis = _mapping(protocol, "analysis", where, "protocol.")
    measure, measure_source = _measure(meta, analysis, rtype, where)
    chosen = meta.get("chosen_factor") or next((f.name for f in factors if f.role == "alternatives"), None)
    if rtype in ("afc", "ranking") and chosen is None:
        raise AnalysisError(f"{where}: a {rtype} design needs chosen_factor or a factor with role 'alternatives'")
    names = {f.name for f in factors}
    if chosen is not None and chosen not in names:
        raise AnalysisError(f"{where}: chosen_factor {chosen!r} is not one of the factors {sorted(names)}")
    k = int(response.get("k") or (len(labels) if rtype == "likert" else 0) or
            (len(next(f.levels for f in factors if f.name == chosen)) if chosen else 0))
    if rtype == "likert" and k < 2:
        raise AnalysisError(f"{where}: a likert response needs at least 2 labels or k >= 2")
    conditions = _normalise_conditions(conditions, factors, directory / "conditions.csv")
    _check_trial_stimuli(trials, conditions, directory / "trials.csv")
    return DesignInfo(directory=directory, protocol=protocol, factors=factors, response_type=rtype, labels=labels,
                      k=k, dependent_measure=measure, chosen_factor=chosen,
                      participants=int(meta.get("participants") or protocol.get("participants") or 0),
                      seed=int(meta.get("seed") if meta.get("seed") is not None else protocol.get("seed", 0)),
                      conditions=conditions, trials=trials, manifest=manifest,
                      alpha=float((_mapping(meta, "analysis", where) or analysis).get("alpha", 0.05)),
                      position_labels=[str(x) for x in response.get("position_labels") or []],
                      posthoc=str((_mapping(meta, "analysis", where) or analysis).get("posthoc", "tukey")),
                      **_posthoc_settings(_mapping(meta, "analysis", where), analysis, where),
                      dependent_measure_source=measure_source)


POSTHOC_CHOICES = {"followup": ("univariate", "multivariate", "statistica"),
                   "adjust": ("tukey", "holm", "bonferroni", "none"), "means": ("emmeans", "observed")}


def _posthoc_settings(meta_analysis: dict, protocol_analysis: dict, where: Path) -> dict:
    """The post-hoc follow-up, adjustment and means type from ``analysis`` (design.json's, else the protocol's);
    absent keys keep analysis.posthoc's defaults, unknown values are refused with the field's name."""
    out = {}
    for key, choices in POSTHOC_CHOICES.items():
        value = meta_analysis.get(key, protocol_analysis.get(key))
        if value is None:
            continue
        if value not in choices:
            raise AnalysisError(f"{where}: analysis.{key} is {value!r}; expected one of {', '.join(choices)}")
        out[f"posthoc_{key}"] = str(value)
    return out


def _measure(meta: dict, analysis: dict, rtype: str, where: Path) -> tuple[str, str]:
    """The dependent measure (default: the response type's first) and the field it came from ("default" when
    none is set); refused when the responses cannot give it."""
    if meta.get("dependent_measure"):
        field_name, measure = "dependent_measure", meta["dependent_measure"]
    elif analysis.get("dependent_measure"):
        field_name, measure = "protocol.analysis.dependent_measure", analysis["dependent_measure"]
    else:
        return MEASURES_OF_TYPE[rtype][0], "default"
    allowed = MEASURES_OF_TYPE[rtype]
    if measure not in allowed:
        raise AnalysisError(f"{where}: field {field_name!r} is {measure!r}, but response.type {rtype!r} allows only "
                            f"{' or '.join(allowed)}; fix the protocol's analysis.dependent_measure and run "
                            f"`shapemotion design` again")
    return measure, field_name


def _check_labels(labels: list[str], field: str, where: Path) -> None:
    """Answers are matched to labels ignoring case and spacing: a blank or repeated label (a design.json
    from another tool; the protocol loader refuses them too) would read some answers as others."""
    from analysis.responses.scoring import _norm   # the readers' own matching

    seen: dict[str, int] = {}
    for index, label in enumerate(labels):
        if not label.strip():
            raise AnalysisError(f"{where}: {field}.{index}: label {index + 1} is blank; every answer needs a label")
        if _norm(label) in seen:
            first = seen[_norm(label)]
            raise AnalysisError(f"{where}: {field}.{index}: label {index + 1} {label[:60]!r} repeats label "
                                f"{first + 1} ({labels[first][:60]!r}); answers are matched to labels ignoring case "
                                "and spacing, so every answer needs a label of its own")
        seen[_norm(label)] = index


def _factor(raw: dict, where: Path) -> FactorInfo:
    try:
        return FactorInfo(name=str(raw["name"]), role=str(raw["role"]), levels=[str(x) for x in raw["levels"]],
                          abbreviations={str(k): str(v) for k, v in (raw.get("abbreviations") or {}).items()},
                          maps_to=str(raw.get("maps_to") or "none"))
    except (KeyError, TypeError) as exc:
        raise AnalysisError(f"{where}: each factor needs name, role and levels; got {raw!r} ({exc})") from None


def _mapping(meta: dict, key: str, where: Path, prefix: str = "") -> dict:
    """An optional JSON object field (``{}`` when absent); anything else is refused with its name."""
    value = meta.get(key)
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise AnalysisError(f"{where}: field {prefix}{key!r} must be a JSON object, got {type(value).__name__} "
                            f"{str(value)[:40]!r}")
    return value


def _check_trial_stimuli(trials: pd.DataFrame | None, conditions: pd.DataFrame, where: Path) -> None:
    """Every trial shows a stimulus of conditions.csv (else simulation and survey cannot place it)."""
    if trials is None:
        return
    known = set(conditions["stimulus_id"])
    unknown = ~trials["stimulus_id"].astype(str).isin(known)
    if unknown.any():
        i = int(unknown.to_numpy().argmax())
        more = f" ({int(unknown.sum())} rows in all)" if unknown.sum() > 1 else ""
        raise AnalysisError(f"{where}: row {i + 2}: stimulus_id {trials['stimulus_id'].iloc[i]!r} is not a stimulus "
                            f"of conditions.csv{more}")


def _need(meta: dict, key: str, where: Path, protocol: dict):
    value = meta.get(key) or protocol.get(key)
    if not value:
        raise AnalysisError(f"{where}: field {key!r} is missing")
    return value


def _normalise_conditions(conditions: pd.DataFrame, factors: list[FactorInfo], where: Path) -> pd.DataFrame:
    """Levels as text, ``practice`` as bool; every non-practice stimulus carries its factor levels."""
    out = conditions.copy()
    out["stimulus_id"] = out["stimulus_id"].astype(str)
    out["practice"] = practice_flags(out["practice"], where, line_offset=2) if "practice" in out else False
    for f in factors:
        if f.name in out:
            out[f.name] = out[f.name].astype("string").fillna("").astype(str)
    if out["stimulus_id"].duplicated().any():
        dup = out.loc[out["stimulus_id"].duplicated(), "stimulus_id"].iloc[0]
        raise AnalysisError(f"{where}: stimulus_id {dup!r} appears twice")
    return out


def _read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise AnalysisError(f"{path}: not found (a design directory holds design.json, conditions.csv, trials.csv)") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise AnalysisError(f"{path}: not valid UTF-8 JSON ({exc})") from None


def _read_csv(path: Path, required: list[str]) -> pd.DataFrame:
    try:
        frame = pd.read_csv(path, dtype=str, keep_default_na=False)
    except FileNotFoundError:
        raise AnalysisError(f"{path}: not found") from None
    except (pd.errors.ParserError, UnicodeDecodeError, pd.errors.EmptyDataError) as exc:
        raise AnalysisError(f"{path}: not a readable CSV file ({exc})") from None
    missing = [c for c in required if c not in frame.columns]
    if missing:
        raise AnalysisError(f"{path}: missing column(s) {missing}; found {list(frame.columns)}")
    return frame
