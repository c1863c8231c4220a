"""The generative model of synthetic participants, as written in YAML (``analysis/default_models/*.yaml``).

A model is a linear predictor on a latent scale per stimulus (and, for k-AFC and rankings, per
alternative shown), plus participant random effects::

    name: exp1_default
    intercept: 0.0
    effects:                      # additive terms; levels not listed contribute 0
      - term: SEX:BODY            # factors joined by ':'
        values: {F:Lo1: 0.6, F:Lo2: 0.6, M:Hi1: 0.4}
    random:
      intercept_sd: 0.5           # participant random intercept (Likert)
      slopes: {BODY: 0.2}         # per-participant deviation for each level of a factor (sd)
    residual_sd: 1.0              # Likert: trial noise before the thresholds (ordered probit)
    thresholds: [-1.5, -0.5, 0.5, 1.5]   # Likert: k-1 increasing cut points → ratings 1…k
    choice: {position_bias: 0.0}  # k-AFC / ranking: utility added to the first (left) position

k-AFC answers are multinomial-logit choices among the alternatives (logistic for 2AFC); rankings are
Plackett–Luce orders (the same utilities, Gumbel noise, sorted).
"""

from __future__ import annotations

from pathlib import Path

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from analysis.errors import AnalysisError
from analysis.io_design import DesignInfo
from analysis.io_yaml import load_bounded, yaml_problem

DEFAULT_MODELS = Path(__file__).parent / "default_models"


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Term(_Strict):
    term: str
    values: dict[str, float]

    @field_validator("values", mode="before")
    @classmethod
    def _keys_as_text(cls, value):
        return {str(k): v for k, v in value.items()} if isinstance(value, dict) else value

    @property
    def factors(self) -> list[str]:
        return [f.strip() for f in self.term.split(":")]


class Random(_Strict):
    intercept_sd: float = Field(default=0.0, ge=0)
    slopes: dict[str, float] = {}


class Choice(_Strict):
    position_bias: float = 0.0


class GenerativeModel(_Strict):
    name: str = "model"
    description: str = ""
    intercept: float = 0.0
    effects: list[Term] = []
    random: Random = Random()
    residual_sd: float = Field(default=1.0, gt=0)
    thresholds: list[float] = []
    choice: Choice = Choice()


def parse_model(data: dict, source: str, design: DesignInfo) -> GenerativeModel:
    """Validate a model against a design: known factors and levels, k−1 increasing thresholds."""
    try:
        model = GenerativeModel.model_validate(data or {})
    except ValidationError as exc:
        problems = "; ".join(f"{'.'.join(map(str, e['loc'])) or '(top)'}: {e['msg']}" for e in exc.errors())
        raise AnalysisError(f"{source}: invalid generative model: {problems}") from None
    names = {f.name: f for f in design.factors}
    for i, term in enumerate(model.effects):
        for f in term.factors:
            if f not in names:
                raise AnalysisError(f"{source}: effects[{i}].term {term.term!r}: unknown factor {f!r} "
                                    f"(factors: {sorted(names)})")
        for key in term.values:
            levels = key.split(":")
            if len(levels) != len(term.factors):
                raise AnalysisError(f"{source}: effects[{i}].values: key {key!r} needs one level per factor of "
                                    f"{term.term!r}, joined by ':'")
            for f, level in zip(term.factors, levels):
                if level not in names[f].levels:
                    raise AnalysisError(f"{source}: effects[{i}].values: {level!r} is not a level of {f} "
                                        f"{names[f].levels}")
    for f in model.random.slopes:
        if f not in names:
            raise AnalysisError(f"{source}: random.slopes: unknown factor {f!r}")
    if design.response_type == "likert":
        t = model.thresholds
        if len(t) != design.k - 1 or any(b <= a for a, b in zip(t, t[1:])):
            raise AnalysisError(f"{source}: thresholds: a {design.k}-point scale needs {design.k - 1} increasing "
                                f"cut points, got {t}")
    return model


def load_model(path: str | Path | None, design: DesignInfo) -> GenerativeModel:
    """Read a model file; ``None`` picks the bundled default for the design (or a null model)."""
    if path is None:
        return default_model(design)
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
        data, _ = load_bounded(text)   # limits on size, nodes and aliases; a key given twice is refused
    except FileNotFoundError:
        raise AnalysisError(f"{path}: model file not found") from None
    except (IsADirectoryError, UnicodeDecodeError) as exc:
        raise AnalysisError(f"{path}: not a UTF-8 YAML model file ({exc})") from None
    except yaml.YAMLError as exc:
        raise AnalysisError(f"{path}:{yaml_problem(exc, text)}") from None
    return parse_model(data, str(path), design)


def default_model(design: DesignInfo) -> GenerativeModel:
    """The bundled ``default_models/<design name>.yaml``, or a null model (no effects) for other designs."""
    name = str(design.protocol.get("name") or "")
    path = DEFAULT_MODELS / f"{name}.yaml"
    if path.exists():
        return load_model(path, design)
    return null_model(design)


def null_model(design: DesignInfo, intercept_sd: float = 0.5) -> GenerativeModel:
    """No condition effects: every test keeps its nominal α under this model."""
    k = design.k
    thresholds = [round(-1.5 + 3.0 * i / (k - 2), 6) for i in range(k - 1)] if k > 2 else [0.0]
    data = {"name": "null", "random": {"intercept_sd": intercept_sd},
            "thresholds": thresholds if design.response_type == "likert" else []}
    return parse_model(data, "<null model>", design)
