"""Shared test helpers: the repository root, bundled protocols and an in-process CLI runner."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROTOCOLS = ROOT / "protocols"
os.environ.setdefault("SHAPEMOTION_CACHE", str(ROOT / ".cache"))
# Ctrl-C as at a terminal, however pytest was started: a shell script's background job (``make test &``)
# starts with SIGINT ignored, which the commands keep (stimuli.interrupts) and the Ctrl-C tests, and
# the commands they start, would inherit.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def buttons_enabled(selector: str) -> str:
    """A ``page.wait_for_function`` predicate: true once the first element matching ``selector`` exists and is
    enabled. Null-safe: between two jsPsych trials the answer buttons are briefly absent, and a bare
    ``document.querySelector(...).disabled`` then throws (a CI run failed on it)."""
    return f"() => {{ const b = document.querySelector('{selector}'); return b !== null && !b.disabled; }}"


def write_small_exp2(path: Path, waist_of_f_hi1: float | None = None) -> Path:
    """Exp 2 cut to the walk and two actors per sex (F_Hi1, F_Lo2, M_Hi1, M_Lo2), without practice or
    familiarization, written to ``path`` (optionally with F_Hi1's waist); returns ``path``."""
    import yaml

    data = yaml.safe_load((PROTOCOLS / "exp2_com_vs_average.yaml").read_text())
    data["actors"] = [a for a in data["actors"] if a["id"] in ("F_Hi1", "F_Lo2", "M_Hi1", "M_Lo2")]
    if waist_of_f_hi1:
        data["actors"][0]["waist_m"] = waist_of_f_hi1
    data["factors"] = [f for f in data["factors"] if f["name"] != "GAIT"]
    for factor in data["factors"]:
        if factor["name"] == "BODY":
            factor.update(levels=["Hi1", "Lo2"], abbreviations={"Hi1": "H1", "Lo2": "L2"})
    data.update(gaits={"walk": data["gaits"]["walk"]}, blocks={"by": ["SEX"], "order": "counterbalanced"})
    for key in ("practice", "familiarization"):
        data.pop(key)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.fixture
def root() -> Path:
    return ROOT


@pytest.fixture
def protocol_path():
    return lambda name: PROTOCOLS / f"{name}.yaml"


@pytest.fixture
def run_cli(capsys):
    """Run ``shapemotion ARGS`` in-process; return (exit code, stdout, stderr)."""
    from stimuli.cli import main

    def run(*args):
        code = main([str(a) for a in args])
        out = capsys.readouterr()
        return code, out.out, out.err

    return run


@pytest.fixture
def jspsych_folder():
    """Write simulated jsPsych files, one per participant plus a second copy of participant 1's (as a
    lab's server collects them), into a new folder; return it."""
    from analysis.io_writers import export_text
    from analysis.model_spec import load_model
    from analysis.simulate import simulate_responses

    def write(design, folder: Path, participants: int, seed: int, prefix: str = "p") -> Path:
        sim = simulate_responses(design, load_model(None, design), participants, seed=seed)
        folder.mkdir()
        for participant, rows in sim.groupby("participant"):
            (folder / f"{prefix}{participant}.csv").write_text(export_text(rows, design, "jspsych"))
        (folder / f"{prefix}1_again.csv").write_text(export_text(sim[sim["participant"] == 1], design, "jspsych"))
        return folder

    return write
