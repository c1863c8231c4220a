"""Shared test helpers: the repository root, bundled protocols and an in-process CLI runner."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROTOCOLS = ROOT / "protocols"
os.environ.setdefault("SHAPEMOTION_CACHE", str(ROOT / ".cache"))


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
