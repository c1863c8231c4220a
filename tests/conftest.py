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
