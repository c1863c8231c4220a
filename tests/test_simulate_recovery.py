"""Large-N recovery: simulate → export → import → measures reproduce the cell values the generative model
implies (computed here in closed form, independently of the simulator), and the analysis finds exactly the
planted effects."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from analysis.anova import anova
from analysis.io_design import load_design
from analysis.io_writers import export_text
from analysis.measures import anova_input
from analysis.model_spec import load_model
from analysis.responses import import_responses
from analysis.simulate import simulate_responses

ROOT = Path(__file__).resolve().parents[1]
N = 240


def _design(tmp_path, name):
    from stimuli.cli import main
    assert main(["design", str(ROOT / "protocols" / f"{name}.yaml"), "--out", str(tmp_path / name)]) == 0
    return load_design(tmp_path / name)


def _eta(model, levels: dict) -> float:
    return model.intercept + sum(t.values.get(":".join(levels[f] for f in t.factors), 0.0) for t in model.effects)


def expected_rating(model, levels: dict) -> float:
    """Ordered probit: E[rating] = 1 + Σ_j Φ((η − τ_j)/s), s² = residual² + intercept² + slope² (marginal)."""
    s = np.sqrt(model.residual_sd ** 2 + model.random.intercept_sd ** 2 + sum(v ** 2 for v in model.random.slopes.values()))
    return 1.0 + float(sum(stats.norm.cdf((_eta(model, levels) - t) / s) for t in model.thresholds))


def expected_choice(model, levels: dict, first: str, second: str, alt: str) -> float:
    """P(first chosen) = E[σ(Δη + b1 − b2)], b ~ N(0, slope_sd²) per level: Gauss–Hermite quadrature."""
    delta = _eta(model, levels | {alt: first}) - _eta(model, levels | {alt: second})
    sd = np.sqrt(2.0) * model.random.slopes.get(alt, 0.0)
    x, w = np.polynomial.hermite_e.hermegauss(40)
    return float(np.sum(w * (1.0 / (1.0 + np.exp(-(delta + sd * x))))) / np.sqrt(2 * np.pi))


@pytest.mark.slow
def test_exp1_ratings_recover_the_model_and_the_planted_effects(tmp_path):
    design = _design(tmp_path, "exp1_shape_motion")
    model = load_model(None, design)
    sim = simulate_responses(design, model, N, seed=21)
    path = tmp_path / "q.csv"
    path.write_text(export_text(sim, design, "qualtrics", seed=21))
    cells = anova_input(import_responses(path, design).data, design)
    means = cells.data.groupby(["SEX", "GAIT", "BODY", "MOTION"])["rating"].agg(["mean", "sem"])
    z = [(row["mean"] - expected_rating(model, dict(zip(["SEX", "GAIT", "BODY", "MOTION"], key)))) / row["sem"]
         for key, row in means.iterrows()]
    assert np.max(np.abs(z)) < 4.0 and abs(np.mean(z)) < 1.0
    table = anova(cells.data, "rating", "participant", cells.within, cells.between)
    planted = {"GAIT", "BODY", "GAIT:SEX", "BODY:SEX", "BODY:MOTION"}
    assert planted <= set(table.significant(0.001))
    # MOTION alone is planted only through BODY:MOTION (balanced): it and the 3-/4-way terms stay null
    assert not {"MOTION", "MOTION:SEX", "GAIT:BODY:MOTION:SEX"} & set(table.significant(0.001))


@pytest.mark.slow
def test_exp2_choices_recover_the_model_and_the_planted_effects(tmp_path):
    design = _design(tmp_path, "exp2_com_vs_average")
    model = load_model(None, design)
    sim = simulate_responses(design, model, N, seed=22)
    path = tmp_path / "j.json"
    path.write_text(export_text(sim, design, "jspsych", ".json"))
    cells = anova_input(import_responses(path, design).data, design)
    nocom = cells.data[cells.data["METHOD"] == "NoCOM"]
    for (sex, gait), group in nocom.groupby(["SEX", "GAIT"]):
        per_person = group.groupby("participant")["percent"].mean()
        expected = 100 * expected_choice(model, {"SEX": sex, "GAIT": gait}, "NoCOM", "COM", "METHOD")
        assert abs(per_person.mean() - expected) < 4 * per_person.sem(), (sex, gait)
    table = anova(cells.data, "percent", "participant", cells.within, [])
    significant = {e for e in table.significant(0.01) if "METHOD" in e}
    assert {"METHOD", "SEX:METHOD", "GAIT:METHOD"} <= significant
    assert not {"BODY:METHOD", "GAIT:SEX:BODY:METHOD"} & significant
