"""`shapemotion anova`: tables on stdout or in files, JSON, post-hoc, and exit code 2 with one paragraph on bad data."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

FIXTURES = Path(__file__).parent / "fixtures" / "anova"
EXP1 = ["--dv", "rating", "--subject", "participant", "--within", "GAIT", "BODY", "MOTION", "--between", "SEX"]


def flat(text: str) -> str:
    """The CLI wraps its one-paragraph error message; compare with whitespace collapsed."""
    return " ".join(text.split())


def test_anova_markdown_with_posthoc(run_cli):
    code, out, err = run_cli("anova", FIXTURES / "exp1.csv", *EXP1, "--posthoc", "tukey")
    assert code == 0, err
    assert "| GAIT | 14.28 | 1, 14 |" in out
    assert "W > J" in out
    assert "BODY\\*SEX" in out   # stars escaped in md: not emphasis


def test_anova_json_and_out_files(run_cli, tmp_path):
    out_file, json_file = tmp_path / "t" / "table.tex", tmp_path / "anova.json"
    code, out, err = run_cli("anova", FIXTURES / "exp1.csv", *EXP1, "--format", "tex", "--out", out_file,
                             "--json", json_file, "--posthoc", "tukey", "--abbrev", "W=Walk", "GAIT:J=Jog")
    assert code == 0, err
    assert out == ""
    assert r"\toprule" in out_file.read_text()
    recs = json.loads(json_file.read_text())
    gait = next(r for r in recs if r["effect"] == "GAIT")
    assert gait["summary"] == "Walk > Jog"
    assert len(recs) == 15


def test_anova_all_and_correction(run_cli):
    code, out, _ = run_cli("anova", FIXTURES / "obk.csv", "--dv", "value", "--subject", "id", "--within", "phase", "hour",
                           "--between", "treatment", "gender", "--all", "--correction", "hf", "--format", "csv")
    assert code == 0
    df = pd.read_csv(pd.io.common.StringIO(out))
    assert len(df) == 15 + 4  # 15 effects and 4 error strata
    assert set(df["section"]) >= {"Main effects", "Error"}


def test_bad_data_exit_2_with_line_numbers(run_cli, tmp_path):
    d = pd.read_csv(FIXTURES / "mixed11.csv")
    d["score"] = d["score"].astype(object)
    d.loc[4, "score"] = "oops"
    bad = tmp_path / "bad.csv"
    d.to_csv(bad, index=False)
    code, out, err = run_cli("anova", bad, "--dv", "score", "--subject", "subject", "--within", "time", "--between", "group")
    assert code == 2
    assert "Traceback" not in err
    err = flat(err)
    assert "bad.csv" in err and "'oops'" in err and "CSV line 6" in err


def test_missing_cell_and_two_groups_exit_2(run_cli, tmp_path):
    d = pd.read_csv(FIXTURES / "mixed11.csv")
    p = tmp_path / "missing.csv"
    d.drop(index=[5]).to_csv(p, index=False)
    code, _, err = run_cli("anova", p, "--dv", "score", "--subject", "subject", "--within", "time", "--between", "group")
    assert code == 2 and "subject 'm02' has no data for cell time=t3" in flat(err)
    d.loc[0, "group"] = "trt"
    d.to_csv(p, index=False)
    code, _, err = run_cli("anova", p, "--dv", "score", "--subject", "subject", "--within", "time", "--between", "group")
    assert code == 2 and "two between-subjects groups" in flat(err)


def test_user_errors_exit_2(run_cli, tmp_path):
    code, _, err = run_cli("anova", tmp_path / "nope.csv", "--dv", "y", "--subject", "s", "--within", "a")
    assert code == 2 and "no such file" in flat(err)
    code, _, err = run_cli("anova", FIXTURES / "exp1.csv", *EXP1, "--abbrev", "W")
    assert code == 2 and "LEVEL=ABBR" in flat(err)
    code, _, err = run_cli("anova", FIXTURES / "exp1.csv", "--dv", "rating", "--subject", "participant")
    assert code == 2 and "no factors" in flat(err)
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    code, _, err = run_cli("anova", empty, "--dv", "y", "--subject", "s", "--within", "a")
    assert code == 2 and "not a readable CSV" in flat(err)


def test_console_script_help():
    """The real entry point lists the command (subprocess: checks registration in stimuli.cli)."""
    r = subprocess.run([sys.executable, "-m", "stimuli.cli", "anova", "--help"], capture_output=True, text=True,
                       cwd=Path(__file__).resolve().parents[1])
    assert r.returncode == 0
    assert "--posthoc" in r.stdout and "--between" in r.stdout
