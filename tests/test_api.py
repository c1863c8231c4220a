"""``import shapemotion as sm``: the steps under the CLI's names, loaded lazily, their examples run."""

from __future__ import annotations

import doctest
import inspect
import subprocess
import sys
from pathlib import Path

import pytest

import shapemotion
from shapemotion import api

ROOT = Path(__file__).resolve().parents[1]


def test_the_docstring_examples_run():
    """Every example in shapemotion.api (a study from init to report, a body fit, one quick clip) and in
    the package's docstring; ~10 s of CPU, most of it the body fit, the clip and the report."""
    attempted = {}
    for module in (api, shapemotion):
        result = doctest.testmod(module, optionflags=doctest.ELLIPSIS)
        assert result.failed == 0, module.__name__
        attempted[module.__name__] = result.attempted
    assert attempted["shapemotion.api"] >= 40 and attempted["shapemotion"] >= 2


def test_the_steps_carry_the_commands_names():
    from stimuli.cli import STAGES

    commands = {name for stage in STAGES.values() for name in stage}
    steps = {"init", "schema", "validate", "design", "render", "survey", "simulate", "power", "analyze", "anova"}
    assert steps <= commands and steps <= set(shapemotion.__all__)
    assert {"load_protocol", "fit_body", "import_responses"} <= set(shapemotion.__all__)


def test_every_step_has_an_example():
    for name in shapemotion.__all__:
        step = getattr(shapemotion, name)
        assert step is getattr(api, name)
        if inspect.isfunction(step) and name != "analyze":   # analyze: the module's example, a whole study
            assert ">>> " in (step.__doc__ or ""), f"sm.{name} has no example"
    assert "sm.analyze(" in api.__doc__


def test_import_is_light_and_lazy():
    """``stimuli`` and ``analysis`` import ``shapemotion.execution``: the package must not import them back."""
    code = ("import sys, shapemotion; print(sorted(m for m in ('stimuli', 'analysis', 'shapemotion.api', 'pandas') "
            "if m in sys.modules)); print(sorted(set(shapemotion.__all__) - set(dir(shapemotion))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.split("\n")[:2] == ["[]", "[]"]
    with pytest.raises(AttributeError, match="has no attribute 'desing'"):
        shapemotion.desing
