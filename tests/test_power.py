"""Simulation-based power: null effects keep α, planted effects are found, the sweep answers 'how many?'."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
from scipy import stats

from analysis.errors import AnalysisError
from analysis.io_design import load_design
from analysis.model_spec import load_model, null_model
from analysis.power import clopper_pearson, power_analysis, power_sweep, required_participants, required_text

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def designs(tmp_path_factory):
    from stimuli.cli import main
    out = {}
    for name in ["exp1_shape_motion", "exp2_com_vs_average", "thesis_pointlight", "thesis_validation"]:
        folder = tmp_path_factory.mktemp(name)
        assert main(["design", str(ROOT / "protocols" / f"{name}.yaml"), "--out", str(folder)]) == 0
        out[name] = load_design(folder)
    return out


def test_clopper_pearson_matches_the_beta_quantiles():
    low, high = clopper_pearson(7, 40)
    assert low == pytest.approx(stats.beta.ppf(0.025, 7, 34))
    assert high == pytest.approx(stats.beta.ppf(0.975, 8, 33))
    assert clopper_pearson(0, 50)[0] == 0.0 and clopper_pearson(50, 50)[1] == 1.0


@pytest.mark.parametrize("name", ["exp1_shape_motion", "exp2_com_vs_average"])
def test_null_effects_keep_alpha(designs, name):
    """Under a model without condition effects every ANOVA effect rejects at ≈ 5 %."""
    design = designs[name]
    result = power_analysis(design, null_model(design), participants=16, sims=2000, seed=11)
    table = result.table
    assert len(table) == (15 if name.startswith("exp1") else 8)
    assert table["power"].between(0.03, 0.07).all(), table
    pooled = table["rejections"].sum() / (table["sims"].sum())
    assert 0.04 < pooled < 0.06
    assert (table["ci_low"] <= table["power"]).all() and (table["power"] <= table["ci_high"]).all()


def test_planted_effects_are_found_and_others_stay_at_alpha(designs):
    design = designs["exp2_com_vs_average"]
    table = power_analysis(design, load_model(None, design), 16, 1000, seed=4).table.set_index("effect")
    assert table.loc["METHOD", "power"] > 0.95 and table.loc["SEX:METHOD", "power"] > 0.95
    assert 0.3 < table.loc["GAIT:METHOD", "power"] < 0.9       # small planted effect: neither 0 nor 1
    for effect in ["BODY:METHOD", "GAIT:SEX:METHOD", "GAIT:BODY:METHOD", "SEX:BODY:METHOD"]:
        assert table.loc[effect, "power"] < 0.08                 # not planted
    assert "GAIT" not in table.index                             # constant-sum: not testable


def test_sweep_answers_how_many_participants(designs):
    design = designs["exp1_shape_motion"]
    sweep = power_sweep(design, load_model(None, design), [8, 16, 32], sims=400, seed=2)
    body_motion = sweep[sweep["effect"] == "BODY:MOTION"].set_index("participants")["power"]
    assert body_motion[8] < body_motion[16] < body_motion[32]
    needed = required_participants(sweep, "MOTION*BODY", target=0.8)
    assert needed in (16, 32)
    assert body_motion[needed] >= 0.8
    assert required_participants(sweep, "MOTION", target=0.8) is None
    with pytest.raises(AnalysisError, match="not one of the effects"):
        required_participants(sweep, "BODY:COLOUR")


def test_answer_is_bounded_by_the_participants_tried():
    """The smallest N tried only bounds the answer from above, the largest tried only from below."""
    sweep = pd.DataFrame({"participants": [16, 8, 24], "effect": ["BODY:MOTION"] * 3, "power": [0.79, 0.42, 0.95]})
    assert required_text(sweep, "MOTION*BODY", 0.8, required_participants(sweep, "MOTION*BODY", 0.8)) == (
        "MOTION*BODY: power 0.8 needs more than 16 and at most 24 participants (N = 24 reaches 0.950; N = 16: 0.790)")
    assert required_text(sweep, "BODY:MOTION", 0.4, 8).startswith(
        "BODY:MOTION: power 0.4 is already reached at the smallest N tried (8: 0.420), so at most 8 participants")
    assert required_text(sweep, "BODY:MOTION", 0.99, None).startswith(
        "BODY:MOTION: none of N = 8, 16, 24 reaches power 0.99 (largest N = 24: 0.950); more than 24 participants")


def test_vote_and_ranking_designs_use_their_tests(designs):
    votes = designs["thesis_pointlight"]
    assert power_analysis(votes, null_model(votes), 16, 600, 1).table["power"].iloc[0] < 0.085
    planted = power_analysis(votes, load_model(None, votes), 16, 200, 1).table
    # the point-light participants vote 10 times each: the report's (and so the power's) test is Friedman of
    # their vote counts, not a χ² that would count one person's votes as independent
    assert planted["effect"].iloc[0] == "STRENGTH (Friedman votes)" and planted["power"].iloc[0] > 0.95
    ranking = designs["thesis_validation"]
    assert power_analysis(ranking, null_model(ranking), 16, 600, 1).table["power"].iloc[0] < 0.085
    assert power_analysis(ranking, load_model(None, ranking), 16, 200, 1).table["power"].iloc[0] > 0.7


def test_power_is_reproducible(designs):
    design = designs["exp2_com_vs_average"]
    a = power_analysis(design, load_model(None, design), 8, 300, seed=5).table
    b = power_analysis(design, load_model(None, design), 8, 300, seed=5).table
    assert a.equals(b)


def test_cli_power_table_json_and_errors(designs, run_cli, tmp_path):
    folder = str(designs["exp2_com_vs_average"].directory)
    code, out, _ = run_cli("power", folder, "--participants", "8", "16", "--sims", "200", "--effect", "SEX:METHOD")
    assert code == 0
    assert "N=8" in out and "N=16" in out
    assert "SEX:METHOD: power 0.8 is already reached at the smallest N tried (8: " in out   # not "8 reach it"
    assert "data sets/s" in out
    code, out, _ = run_cli("power", folder, "--participants", "8", "--sims", "100", "--json",
                           "--csv", str(tmp_path / "p.csv"))
    data = json.loads(out)
    assert code == 0 and {r["effect"] for r in data["rows"]} >= {"METHOD", "SEX:METHOD"}
    assert (tmp_path / "p.csv").read_text().startswith("participants,effect,rejections")
    again = run_cli("power", folder, "--participants", "8", "--sims", "100", "--json", "--csv", str(tmp_path / "q.csv"))
    assert again[1] == out and (tmp_path / "q.csv").read_bytes() == (tmp_path / "p.csv").read_bytes()  # no timings
    # beyond the design's participants every data set repeats its lists: said, as simulate says it
    code, _, err = run_cli("power", folder, "--participants", "8", "64", "--sims", "20")
    assert code == 0 and "simulating 64 reuses their lists" in " ".join(err.split())
    code, _, err = run_cli("power", folder, "--participants", "8", "--sims", "0")
    assert code == 2 and "--sims" in err
    code, _, err = run_cli("power", str(tmp_path / "missing"), "--participants", "8", "--sims", "10")
    assert code == 2 and "not found" in err and "missing" in err


def test_sphericity_correction_is_conservative_under_the_null(designs):
    design = designs["exp1_shape_motion"]
    plain = power_analysis(design, null_model(design), 16, 1000, seed=3).table.set_index("effect")
    gg = power_analysis(design, null_model(design), 16, 1000, seed=3, correction="gg").table.set_index("effect")
    assert (gg["power"] <= plain["power"]).all()                    # same data sets, larger p
    assert gg.loc["GAIT", "power"] == plain.loc["GAIT", "power"]      # 1 df: nothing to correct
    assert gg["power"].between(0.01, 0.07).all()
    with pytest.raises(AnalysisError, match="correction"):
        power_analysis(design, null_model(design), 16, 10, seed=3, correction="xx")
