"""Synthetic participants: every export format round-trips through the importer; default models show the
paper's patterns; the vectorised measures equal the ones computed from imported files."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.errors import AnalysisError
from analysis.io_design import load_design
from analysis.io_writers import export_text
from analysis.measures import anova_input, measure_arrays, within_levels
from analysis.model_spec import load_model, parse_model
from analysis.responses import import_responses
from analysis.simulate import draw, simulate_responses, trial_plan

ROOT = Path(__file__).resolve().parents[1]
PROTOCOLS = ["exp1_shape_motion", "exp2_com_vs_average", "thesis_pointlight", "thesis_mesh", "thesis_validation"]
FORMATS = [("long", ".csv"), ("qualtrics", ".csv"), ("qualtrics-numeric", ".csv"), ("qualtrics-legacy", ".csv"),
           ("jspsych", ".csv"), ("jspsych", ".json")]


@pytest.fixture(scope="module")
def designs(tmp_path_factory):
    """Design directories of the bundled protocols, written by `shapemotion design` (the real contract)."""
    from stimuli.cli import main
    out = {}
    for name in PROTOCOLS:
        folder = tmp_path_factory.mktemp(name)
        assert main(["design", str(ROOT / "protocols" / f"{name}.yaml"), "--participants", "16", "--seed", "3",
                     "--out", str(folder)]) == 0
        out[name] = load_design(folder)
    return out


def _expected(sim, design) -> dict:
    """(participant, stimulus, repetition) → the score the importer must find."""
    out = {}
    for rec in sim.to_dict("records"):
        key = (str(rec["participant"]), rec["stimulus_id"], int(rec["repetition"]))
        arrangement = design.arrangement(rec["stimulus_id"])
        if design.response_type == "likert":
            out[key] = int(rec["rating"])
        elif design.response_type == "afc":
            out[key] = arrangement[int(rec["position"]) - 1]
        else:
            out[key] = ">".join(arrangement[int(p) - 1] for p in str(rec["order"]).split("|"))
    return out


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("fmt, suffix", FORMATS)
def test_every_format_round_trips(designs, protocol, fmt, suffix, tmp_path):
    design = designs[protocol]
    sim = simulate_responses(design, load_model(None, design), participants=16, seed=5)
    path = tmp_path / f"responses{suffix}"
    path.write_text(export_text(sim, design, fmt, suffix, seed=5), encoding="utf-8")
    result = import_responses(path, design)
    assert result.reconciles
    assert result.data["participant"].nunique() == 16
    assert set(result.exclusions["reason"]) <= {"not a stimulus trial"}   # only jsPsych's consent/end rows
    column = {"likert": "rating", "afc": "chosen", "ranking": "ranking"}[design.response_type]
    found = {(r["participant"], r["stimulus_id"], int(r["repetition"])): (int(r[column]) if column == "rating"
                                                                          else r[column])
             for r in result.data.to_dict("records")}
    assert found == _expected(sim, design)


def test_simulation_is_deterministic(designs, run_cli, tmp_path):
    design_dir = str(designs["exp2_com_vs_average"].directory)
    paths = [tmp_path / f"{i}.csv" for i in range(3)]
    for path, seed in zip(paths, (1, 1, 2)):
        code, out, _ = run_cli("simulate", design_dir, "--participants", "16", "--seed", str(seed),
                               "--format", "qualtrics", "--out", str(path))
        assert code == 0 and "1024 test answers" in out
    assert paths[0].read_bytes() == paths[1].read_bytes()
    assert paths[0].read_bytes() != paths[2].read_bytes()


def test_vectorised_measures_equal_the_imported_ones(designs, tmp_path):
    """draw()+measure_arrays (power path) and file→import→anova_input (analyze path) agree exactly."""
    for name, design in designs.items():
        model = load_model(None, design)
        plan = trial_plan(design, 16)
        Y = measure_arrays(design, plan.test, draw(design, model, plan, np.random.default_rng(9), sims=1))[0]
        sim = simulate_responses(design, model, 16, seed=9)
        path = tmp_path / f"{name}.csv"
        path.write_text(export_text(sim, design, "long"))
        cells = anova_input(import_responses(path, design).data, design)
        levels = within_levels(design)
        index = {c: i for i, c in enumerate(itertools.product(*levels.values()))}
        M = np.full_like(Y, np.nan)
        for rec in cells.data.to_dict("records"):
            M[int(rec["participant"]) - 1, index[tuple(str(rec[f]) for f in levels)]] = rec[cells.dv]
        np.testing.assert_allclose(M, Y, err_msg=name)


def _means(design, participants=160, seed=2):
    sim = simulate_responses(design, load_model(None, design), participants, seed)
    return sim[~sim["practice"]].merge(design.conditions.drop(columns=["practice"]), on="stimulus_id",
                                       suffixes=("", "_c"))


def test_default_exp1_model_shows_the_figure4_pattern(designs):
    data = _means(designs["exp1_shape_motion"])
    by = data.groupby(["SEX", "BODY"])["rating"].mean()
    assert min(by["F"]["Lo1"], by["F"]["Lo2"]) > max(by["F"]["Hi1"], by["F"]["Hi2"]) + 0.3
    assert by["M"].idxmax() == "Hi1"
    gait = data.groupby(["SEX", "GAIT"])["rating"].mean()
    assert gait["F"]["walk"] > gait["F"]["jog"] + 0.1
    same_group = data["BODY"].str[:2] == data["MOTION"].str[:2]
    assert data[same_group]["rating"].mean() > data[~same_group]["rating"].mean()


def test_default_exp2_model_shows_the_figure9_pattern(designs):
    design = designs["exp2_com_vs_average"]
    data = _means(design)
    data["chosen"] = [design.arrangement(s)[int(p) - 1]
                      for s, p in zip(data["stimulus_id"], data["position"])]
    nocom = (data["chosen"] == "NoCOM").groupby(data["SEX"]).mean()
    overall = (data["chosen"] == "NoCOM").mean()
    assert 0.64 < overall < 0.76
    assert nocom["F"] + 0.08 < nocom["M"]
    assert abs((data["position"] == 1).mean() - 0.5) < 0.03     # no side bias in the default model


def test_custom_model_effect_is_planted(designs, tmp_path):
    design = designs["exp1_shape_motion"]
    path = tmp_path / "m.yaml"
    path.write_text("name: motion_only\neffects:\n  - term: MOTION\n    values: {Lo2: 1.5}\n"
                    "residual_sd: 0.5\nthresholds: [-1.5, -0.5, 0.5, 1.5]\n")
    sim = simulate_responses(design, load_model(path, design), 32, 1)
    data = sim[~sim["practice"]].merge(design.conditions[["stimulus_id", "MOTION"]], on="stimulus_id")
    means = data.groupby("MOTION")["rating"].mean()
    assert means["Lo2"] > means.drop("Lo2").max() + 1.0
    assert means.drop("Lo2").max() - means.drop("Lo2").min() < 0.2


@pytest.mark.parametrize("text, message", [
    ("effects:\n  - term: COLOUR\n    values: {red: 1}\nthresholds: [-1, 0, 1, 2]\n", "unknown factor 'COLOUR'"),
    ("effects:\n  - term: BODY\n    values: {Hi9: 1}\nthresholds: [-1, 0, 1, 2]\n", "'Hi9' is not a level of BODY"),
    ("effects:\n  - term: BODY:SEX\n    values: {Hi1: 1}\nthresholds: [-1, 0, 1, 2]\n", "one level per factor"),
    ("thresholds: [0, 1]\n", "needs 4 increasing cut points"),
    ("thresholds: [-1, 0, 1, 2]\nresidual_sd: -1\n", "residual_sd"),
    ("thresholds: [-1, 0, 1, 2]\nnoise: 1\n", "noise"),
    ("effects: [\n", "YAML syntax error"),
])
def test_bad_models_are_refused_with_the_field(designs, tmp_path, text, message):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(AnalysisError, match=message) as info:
        load_model(path, designs["exp1_shape_motion"])
    assert "bad.yaml" in str(info.value)


def test_cli_refuses_unbalanced_participants(designs, run_cli, tmp_path):
    code, _, err = run_cli("simulate", str(designs["exp1_shape_motion"].directory), "--participants", "5",
                           "--seed", "1", "--out", str(tmp_path / "x.csv"))
    assert code == 2 and "multiple of 2" in err
    assert not (tmp_path / "x.csv").exists()


def test_null_model_has_no_condition_effects(designs):
    design = designs["exp2_com_vs_average"]
    model = parse_model({"name": "null"}, "<test>", design)
    plan = trial_plan(design, 64)
    values = measure_arrays(design, plan.test, draw(design, model, plan, np.random.default_rng(1), sims=20))
    assert abs(values.mean() - 50.0) < 1.0   # each METHOD chosen half of the time


def test_simulating_more_participants_than_the_design_notes_the_reused_lists(designs, run_cli, tmp_path):
    """32 simulated people on a design made for 16: a note names the design's N and which lists are reused;
    the file is the same bytes as without the note (the API writes no note)."""
    design = designs["exp2_com_vs_average"]
    code, out, err = run_cli("simulate", str(design.directory), "--participants", "32", "--seed", "4",
                             "--format", "long", "--out", str(tmp_path / "r.csv"))
    err = " ".join(err.split())   # the CLI wraps long messages
    assert code == 0 and "2048 test answers" in out
    assert "lists trials for 16 participants" in err and "simulating 32 reuses their lists (each used 2 times)" in err
    assert "17→1, 18→2, 19→3, …, 32→16" in err and "--participants 32" in err
    sim = simulate_responses(design, load_model(None, design), 32, seed=4)
    assert (tmp_path / "r.csv").read_text() == export_text(sim, design, "long")
    code, _, err = run_cli("simulate", str(design.directory), "--participants", "16", "--seed", "4",
                           "--out", str(tmp_path / "s.csv"))
    assert code == 0 and "reuses" not in err


@pytest.mark.parametrize("protocol", ["thesis_pointlight", "thesis_mesh"])
def test_default_thesis_models_vote_for_the_stronger_walkers(designs, protocol):
    """Both 6-AFC surveys have a bundled model (the mesh survey had none: a null model, flat votes)."""
    sim = simulate_responses(designs[protocol], load_model(None, designs[protocol]), 120, seed=4)
    chosen = [positions.split("|")[int(position) - 1] for positions, position in zip(sim["positions"], sim["position"])]
    votes = pd.Series(chosen).value_counts()
    assert votes["58"] > 2 * votes["0.5"], votes.to_dict()
