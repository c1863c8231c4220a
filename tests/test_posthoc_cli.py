"""Post-hoc options end to end: `shapemotion anova --followup/--adjust/--means`, the protocol's analysis block
(followup, adjust, means) and the report's tables."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from analysis import commands, posthoc
from analysis.errors import AnalysisError

ROOT = Path(__file__).resolve().parents[1]
FIXTURES = Path(__file__).parent / "fixtures" / "anova"
EXP1 = ["--dv", "rating", "--subject", "participant", "--within", "GAIT", "BODY", "MOTION", "--between", "SEX"]


def test_cli_choices_are_the_packages():
    assert commands.POSTHOC_FOLLOWUPS == posthoc.FOLLOWUPS
    assert commands.POSTHOC_ADJUSTMENTS == posthoc.ADJUSTMENTS
    assert commands.POSTHOC_MEANS == posthoc.MEANS_TYPES


def test_default_posthoc_is_univariate_tukey_with_emmeans_means(run_cli, tmp_path):
    out_json = tmp_path / "a.json"
    code, out, err = run_cli("anova", FIXTURES / "exp1.csv", *EXP1, "--posthoc", "tukey", "--json", out_json)
    assert code == 0, err
    assert "post-hoc (Tukey, univariate, emmeans means)" in out
    body_sex = next(r for r in json.loads(out_json.read_text()) if r["effect"] == "BODY:SEX")
    pair = next(p for p in body_sex["posthoc"] if (p["a"], p["b"]) == ("F/L1b", "M/L1b"))
    assert pair["kind"] == "between" and 14 < pair["df"] < 42 and pair["followup"] == "univariate"
    assert pair["lower"] < pair["diff"] < pair["upper"] and pair["effect_size_type"] == "g"


def test_statistica_holm_observed_from_the_cli(run_cli):
    code, out, err = run_cli("anova", FIXTURES / "exp1.csv", *EXP1, "--followup", "statistica", "--adjust", "holm")
    assert code == 0, err     # --followup alone turns the post-hoc on
    assert "post-hoc (Holm, statistica, observed means; pairs across between groups not protected)" in out


def test_bad_followup_is_refused_by_argparse(run_cli):
    with pytest.raises(SystemExit) as exc:
        run_cli("anova", FIXTURES / "exp1.csv", *EXP1, "--followup", "spss")
    assert exc.value.code == 2


@pytest.fixture(scope="module")
def exp1_design(tmp_path_factory):
    from stimuli.cli import main
    folder = tmp_path_factory.mktemp("exp1") / "design"
    assert main(["design", str(ROOT / "protocols" / "exp1_shape_motion.yaml"), "--out", str(folder)]) == 0
    return folder


def test_protocol_analysis_block_chooses_the_followup(exp1_design, tmp_path):
    from analysis.io_design import load_design
    default = load_design(exp1_design)
    assert (default.posthoc_followup, default.posthoc_adjust, default.posthoc_means) == ("univariate", "tukey", None)
    meta = json.loads((exp1_design / "design.json").read_text())
    assert "followup" not in meta["protocol"]["analysis"]          # designs written before stay byte-identical
    meta["protocol"]["analysis"] |= {"followup": "statistica", "adjust": "bonferroni", "means": "observed"}
    copy = tmp_path / "design"
    copy.mkdir()
    for f in exp1_design.iterdir():
        if f.is_file():
            (copy / f.name).write_bytes(f.read_bytes())
    (copy / "design.json").write_text(json.dumps(meta))
    chosen = load_design(copy)
    assert (chosen.posthoc_followup, chosen.posthoc_adjust, chosen.posthoc_means) == ("statistica", "bonferroni",
                                                                                     "observed")
    meta["protocol"]["analysis"]["followup"] = "spss"
    (copy / "design.json").write_text(json.dumps(meta))
    with pytest.raises(AnalysisError, match="analysis.followup is 'spss'"):
        load_design(copy)


def test_protocol_schema_accepts_the_post_hoc_keys(tmp_path):
    from stimuli.protocol import load_protocol
    text = (ROOT / "protocols" / "exp1_shape_motion.yaml").read_text()
    assert "  posthoc: tukey\n" in text
    path = tmp_path / "p.yaml"
    path.write_text(text.replace("  posthoc: tukey\n", "  posthoc: tukey\n  followup: statistica\n  adjust: holm\n"))
    p = load_protocol(path)
    assert (p.analysis.followup, p.analysis.adjust, p.analysis.means) == ("statistica", "holm", None)
    assert p.to_json_dict()["analysis"]["followup"] == "statistica" and "means" not in p.to_json_dict()["analysis"]
