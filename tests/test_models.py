"""The additional models inside the report: analytic gradients, Exp.-1/Exp.-2-size fits in seconds, the table's
columns, and data that do not allow a model. (Agreement with R: tests/test_models_r.py.)"""

from __future__ import annotations

import io
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.io_design import load_design
from analysis.io_writers import export_text
from analysis.model_spec import load_model
from analysis.models import MODEL_NAMES, additional_models, lmer_anova, not_computed_models
from analysis.models.random_intercept import BernoulliLogit, CumulativeLogit, _Objective
from analysis.responses import import_responses
from analysis.simulate import simulate_responses

ROOT = Path(__file__).resolve().parents[1]


def _toy(seed=1, n=300, q=10):
    rng = np.random.default_rng(seed)
    groups = rng.integers(0, q, n)
    X = np.column_stack([np.ones(n), rng.normal(size=(n, 2))])
    person = rng.normal(size=q)[groups]
    binary = (rng.random(n) < 1 / (1 + np.exp(-(X @ [0.3, 0.5, -0.4] + person)))).astype(float)
    ordinal = np.digitize(X[:, 1:] @ [0.5, -0.4] + person + rng.logistic(size=n), [-1.5, -0.3, 0.6, 1.8]) + 1
    return groups, X, binary, ordinal


@pytest.mark.parametrize("family_name", ["binomial", "cumulative"])
@pytest.mark.parametrize("n_agq", [1, 5])
def test_analytic_gradient_equals_finite_differences(family_name, n_agq):
    """The gradient runs through the conditional modes and their curvature (third derivatives): check it."""
    groups, X, binary, ordinal = _toy()
    family = BernoulliLogit(X, binary) if family_name == "binomial" else CumulativeLogit(X[:, 1:], ordinal, 5)
    objective = _Objective(family, groups, n_agq)
    psi = np.concatenate([family.start() + 0.1, [0.8]])
    value, grad = objective.value_and_gradient(psi)
    numeric = np.array([(objective.value_and_gradient(psi + h)[0] - objective.value_and_gradient(psi - h)[0]) / 2e-6
                        for h in np.eye(len(psi)) * 1e-6])
    assert np.isfinite(value) and np.abs(grad - numeric).max() < 1e-5 * max(1.0, np.abs(grad).max())


def test_thresholds_out_of_order_have_no_likelihood():
    """The optimiser must see such a point as the worst, never the best (P(Y = j) < 0 there)."""
    groups, X, _, ordinal = _toy()
    family = CumulativeLogit(X[:, 1:], ordinal, 5)
    objective = _Objective(family, groups, 1)
    psi = np.concatenate([family.start(), [0.8]])
    psi[[1, 2]] = psi[[2, 1]]
    assert objective.value_and_gradient(psi)[0] == -np.inf


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """Exp. 1 (Likert, SEX between × 3 within) and Exp. 2 (2AFC) with 16 simulated participants."""
    from stimuli.cli import main
    out = {}
    for name in ("exp1_shape_motion", "exp2_com_vs_average"):
        folder = tmp_path_factory.mktemp(name)
        assert main(["design", str(ROOT / "protocols" / f"{name}.yaml"), "--participants", "16", "--seed", "1",
                     "--out", str(folder / "design")]) == 0
        design = load_design(folder / "design")
        sim = simulate_responses(design, load_model(None, design), 16, seed=8)
        (folder / "responses.csv").write_text(export_text(sim, design, "long"))
        out[name] = (import_responses(folder / "responses.csv", design).data, design)
    return out


def test_exp1_models_fit_in_seconds_with_f_and_chi2_columns(simulated):
    data, design = simulated["exp1_shape_motion"]
    start = time.perf_counter()
    table = additional_models(data, design)
    assert time.perf_counter() - start < 15     # ~1 s here; R's clmm takes ~7 s of CPU on the same data
    lmm = table[table["model"] == MODEL_NAMES["mixed_model"]].set_index("term")
    ordinal = table[table["model"] == MODEL_NAMES["ordinal_model"]].set_index("term")
    assert len(lmm) == len(ordinal) == 15 and not not_computed_models(table)
    assert lmm["chi2"].isna().all() and lmm["F"].notna().all() and ordinal["F"].isna().all()
    # SEX is between participants: 16 participants in 2 groups leave 14 df; within terms get the residual df
    assert lmm.loc["SEX", "df_den"] == pytest.approx(14, abs=1e-6)
    assert lmm.loc["BODY", "df_den"] > 500 and lmm.loc["BODY:MOTION", "df"] == 9
    assert ordinal.loc["SEX:BODY", "p"] < 1e-3 and "participant random-intercept SD" in ordinal["note"].iloc[0]


def test_exp2_glmer_terms_are_interactions_with_the_alternatives(simulated):
    data, design = simulated["exp2_com_vs_average"]
    start = time.perf_counter()
    table = additional_models(data, design)
    assert time.perf_counter() - start < 15
    glmm = table[table["model"] == MODEL_NAMES["choice_mixed"]].set_index("term")
    assert glmm.index[0] == "METHOD" and all(t.endswith(":METHOD") for t in glmm.index[1:])
    assert glmm.loc["METHOD", "p"] < 1e-3 and glmm.loc["BODY:METHOD", "df"] == 3


def test_lmm_without_residual_variance_is_not_computed():
    frame = pd.DataFrame({"participant": np.repeat(["p1", "p2", "p3"], 4), "A": ["a1", "a2"] * 6})
    frame["rating"] = np.where(frame["A"] == "a1", 2.0, 4.0)
    with pytest.raises(ValueError, match="residual variance is 0"):
        lmer_anova(frame, "rating", ["A"])


def test_extreme_cell_makes_the_ordinal_model_not_computed(simulated):
    data, design = simulated["exp1_shape_motion"]
    data = data.copy()
    cell = (data["BODY"] == "Hi1") & (data["MOTION"] == "Hi1") & (data["GAIT"] == "walk") & (data["SEX"] == "F")
    data.loc[cell, "rating"] = design.k
    reasons = not_computed_models(additional_models(data, design))
    assert list(reasons) == [MODEL_NAMES["ordinal_model"]]
    reason = reasons[MODEL_NAMES["ordinal_model"]]
    assert "every answer in the lowest or highest category (e.g. F/walk/Hi1/Hi1)" in reason


def test_design_cell_without_answers_is_named(simulated):
    data, design = simulated["exp1_shape_motion"]
    data = data[~((data["BODY"] == "Lo2") & (data["MOTION"] == "Hi1"))]
    reasons = not_computed_models(additional_models(data, design))
    assert set(reasons) == {MODEL_NAMES["mixed_model"], MODEL_NAMES["ordinal_model"]}
    assert all("4 design cell(s) (SEX × GAIT × BODY × MOTION) have no answers (e.g. F/jog/Lo2/Hi1" in reason
               for reason in reasons.values())


def test_models_csv_reads_back(simulated, tmp_path):
    data, design = simulated["exp1_shape_motion"]
    table = additional_models(data, design)
    text = table.to_csv(index=False)
    back = pd.read_csv(io.StringIO(text))
    assert list(back.columns) == ["model", "term", "df", "chi2", "p", "note", "F", "df_den"]
