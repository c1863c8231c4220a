"""The console script: help everywhere, real exit codes, the demo."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from stimuli.cli import build_parser

SCRIPT = Path(sys.executable).with_name("shapemotion")


def subcommands(parser, prefix=()):
    for action in parser._subparsers._group_actions if parser._subparsers else []:
        for name, sub in action.choices.items():
            yield prefix + (name,)
            if sub._subparsers:
                yield from subcommands(sub, prefix + (name,))


def test_help_everywhere(run_cli):
    commands = list(subcommands(build_parser()))
    assert ("design",) in commands and ("validate",) in commands and ("demo",) in commands
    for command in commands:
        with pytest.raises(SystemExit) as exit_info:
            run_cli(*command, "--help")
        assert exit_info.value.code == 0


def test_console_script_exit_codes(tmp_path):
    ok = subprocess.run([SCRIPT, "validate", "protocols/exp1_shape_motion.yaml"], capture_output=True, text=True)
    assert ok.returncode == 0 and "valid protocol" in ok.stdout
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nseed: 1\n")
    failed = subprocess.run([SCRIPT, "design", bad, "--out", tmp_path / "o"], capture_output=True, text=True)
    assert failed.returncode == 2 and "Traceback" not in failed.stderr and "required field is missing" in failed.stderr


def test_an_error_is_one_line_in_a_log_and_wrapped_between_words_on_a_terminal(tmp_path, monkeypatch, capsys):
    """The CLI's wrapping once split "1 clip(s) do not verify" where the temporary folder's length
    put the 100th column, so a test passed or failed by the run's number (pytest-1 or pytest-542)."""
    import io

    from stimuli.cli import print_user_error

    path = tmp_path / ("a-long-folder-name-" * 6) / "manifest.csv"
    message = f"{path}: 1 clip(s) do not verify; run 'shapemotion render --out DIR --verify' to list them"
    print_user_error(message)
    assert capsys.readouterr().err == f"shapemotion: error: {message}\n"

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    print_user_error(message)
    lines = terminal.getvalue().splitlines()
    assert len(lines) > 1 and all(line.startswith("  ") for line in lines[1:])
    assert str(path) + ":" in [word for line in lines for word in line.split()]   # the path whole, on one line
    assert " ".join(terminal.getvalue().split()) == f"shapemotion: error: {message}"


@pytest.mark.parametrize("interrupted, code", [(True, 130), (False, None)])
def test_ctrl_c_that_comes_back_as_another_error_is_the_interrupt(interrupted, code, run_cli, monkeypatch):
    """PyOpenGL's calls go through ctypes, which reports an interrupt raised while it converts an
    argument as ``ctypes.ArgumentError``: after Ctrl-C that is exit 130, without it a bug (traceback)."""
    import ctypes
    import signal

    from stimuli.commands import render_cmd

    def preview(args):
        if interrupted:
            try:                        # the interrupt, turned into ctypes' error by the GL call
                signal.raise_signal(signal.SIGINT)
            except KeyboardInterrupt:
                pass
        raise ctypes.ArgumentError("argument 2: KeyboardInterrupt: ")

    monkeypatch.setattr(render_cmd, "run_preview", preview)
    if code is None:
        with pytest.raises(ctypes.ArgumentError):
            run_cli("preview", "--stepping", "--body", "sex=M,height=1.8,bmi=25", "--out", "x.mp4")
    else:
        assert run_cli("preview", "--stepping", "--body", "sex=M,height=1.8,bmi=25", "--out", "x.mp4") == (130, "", "shapemotion: interrupted\n")
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_ctrl_c_the_process_was_started_to_ignore_stays_ignored(run_cli, monkeypatch):
    """A script's background job starts with SIGINT ignored; a command keeps it so, as Python does."""
    import signal

    from stimuli.commands import render_cmd

    seen = []

    def preview(args):
        seen.append(signal.getsignal(signal.SIGINT))
        signal.raise_signal(signal.SIGINT)      # ignored: no KeyboardInterrupt, no exit 130
        return 0

    monkeypatch.setattr(render_cmd, "run_preview", preview)
    before = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        code, _, err = run_cli("preview", "--stepping", "--body", "sex=M,height=1.8,bmi=25", "--out", "x.mp4")
        assert (code, err) == (0, "") and seen == [signal.SIG_IGN]
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, before)


def test_the_interrupt_module_examples_run():
    import doctest

    from stimuli import interrupts

    result = doctest.testmod(interrupts)
    assert result.failed == 0 and result.attempted >= 5


@pytest.mark.slow
def test_demo_runs_the_whole_chain(tmp_path, run_cli):
    code, out, _ = run_cli("demo", "--out", tmp_path, "--quick")
    assert code == 0
    for step in ("design", "bodies", "physics", "render", "survey", "analysis"):
        assert f"[{step}] done" in out
    assert (tmp_path / "bodies" / "contact_sheet.png").stat().st_size > 10_000
    # the bundled 4-s loops show the walk at 120 steps/min, not 112: the demo says so, as render does
    assert "warning: gaits.walk: 112 steps/min does not fill the 4 s clip" in " ".join(out.split())
    assert (tmp_path / "exp2_com_vs_average" / "physics" / "fig7_walk.png").is_file()
    for name in ("exp1_shape_motion", "exp2_com_vs_average"):
        clips = list((tmp_path / "quick_clips" / name / "clips").glob("*.mp4"))
        assert len(clips) == 4 and all(c.stat().st_size > 1000 for c in clips)
    for name in ("exp1_shape_motion", "exp2_com_vs_average", "thesis_pointlight", "thesis_mesh", "thesis_validation"):
        assert (tmp_path / name / "trials.csv").stat().st_size > 0
        assert (tmp_path / name / "survey" / "survey.qsf").is_file()
        assert "<table" in (tmp_path / name / "results" / "report" / "report.html").read_text()


def test_help_lists_every_command_by_stage_with_an_example_that_parses():
    """``shapemotion --help`` lists the commands in the order of the data flow, each with an example;
    every example is a valid command line (parsed, not run)."""
    import shlex

    from stimuli.cli import STAGES

    parser = build_parser()
    overview = parser.format_help()
    commands = [name for stage in STAGES.values() for name in stage]
    assert sorted(commands) == sorted({c[0] for c in subcommands(parser)}), "place every command in cli.STAGES"
    assert "\nother:" not in overview
    listed = [line.split()[0] for line in overview.split("commands, in the order of the data flow:")[1].splitlines()
              if line.startswith("  ") and not line.startswith("   ")]
    assert listed == commands and commands[:3] == ["init", "schema", "validate"]
    for stage in STAGES.values():
        for name, example in stage.items():
            assert f"e.g. {example}" in overview
            words = shlex.split(example.split(" > ")[0])
            assert words[:2] == ["shapemotion", name]
            assert build_parser().parse_args(words[1:]).func
