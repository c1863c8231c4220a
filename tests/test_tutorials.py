"""The tutorials run as written: every ```sh block of a page is run in order in a fresh folder
(holding a copy of the repository's protocols/, as a clone's root does), every ```yaml block titled
with a file name is written there, and every ```text block after a command is checked against that
command's real output, so a page cannot drift from what the tool does.

- ```sh: run with bash (-e -u -o pipefail), `shapemotion` from this interpreter's environment;
- ```yaml title="FILE": FILE does not exist yet → the block is the whole file; FILE exists → the
  block's top-level keys replace those keys in FILE (the edit the page tells the reader to make);
- ```text after a ```sh block: each of its lines, except blank lines and "…", is a line of the
  command's output (stdout and stderr together; surrounding spaces ignored).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TUTORIALS = ROOT / "docs" / "tutorials"
FENCE = re.compile(r"^```(\w+)([^\n]*)\n(.*?)^```\s*$", re.S | re.M)
TOP_KEY = re.compile(r"^([A-Za-z_][\w-]*):")


def blocks(page: Path) -> list[tuple[str, str, str]]:
    """(language, title, body) of every fenced block of a page, in order."""
    found = []
    for lang, info, body in FENCE.findall(page.read_text()):
        title = re.search(r'title="([^"]+)"', info)
        found.append((lang, title.group(1) if title else "", body))
    return found


def replace_top_level_keys(text: str, edit: str) -> str:
    """``text`` with each top-level key that ``edit`` defines replaced by ``edit``'s version of it
    (a key's extent ends where the next top-level key, or the comment lines just above it, start)."""
    def sections(lines):
        starts = [i for i, line in enumerate(lines) if TOP_KEY.match(line)]
        out = {}
        for n, i in enumerate(starts):
            end = starts[n + 1] if n + 1 < len(starts) else len(lines)
            while end - 1 > i and (not lines[end - 1].strip() or lines[end - 1].startswith("#")):
                end -= 1
            out[TOP_KEY.match(lines[i]).group(1)] = (i, end)
        return out

    lines, new = text.splitlines(), edit.rstrip("\n").splitlines()
    new_sections = sections(new)
    assert new_sections, f"the edit defines no top-level key:\n{edit}"
    old_sections = sections(lines)
    missing = set(new_sections) - set(old_sections)
    assert not missing, f"the edit names keys the file does not have: {sorted(missing)}"
    # from the bottom up, so that the line numbers of the keys above stay valid
    for key, (i, end) in sorted(((k, old_sections[k]) for k in new_sections), key=lambda kv: -kv[1][0]):
        a, b = new_sections[key]
        lines[i:end] = new[a:b]
    return "\n".join(lines) + "\n"


def check_excerpt(excerpt: str, output: str, where: str) -> None:
    """Each line the page shows is in the output, lines and breaks aside: a page shows an error as a
    terminal wraps it, and the command run here prints it on one line (its stderr is not a terminal)."""
    have = f" {' '.join(output.split())} "
    for line in excerpt.splitlines():
        if line.strip() and line.strip() != "…":
            shown = " ".join(line.split())
            assert f" {shown} " in have, f"{where}: the page shows {shown!r}, the command did not print it:\n{output[-3000:]}"


def run_tutorial(page: Path, workdir: Path) -> None:
    shutil.copytree(ROOT / "protocols", workdir / "protocols")
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
           "SHAPEMOTION_CACHE": os.environ.get("SHAPEMOTION_CACHE", str(ROOT / ".cache")),
           "COLUMNS": "100"}
    last_output, ran = None, 0
    for n, (lang, title, body) in enumerate(blocks(page)):
        where = f"{page.name}, block {n + 1}"
        if lang == "sh":
            proc = subprocess.run(["bash", "-euo", "pipefail", "-c", body], cwd=workdir, env=env,
                                  capture_output=True, text=True, timeout=600)
            last_output = proc.stdout + proc.stderr
            assert proc.returncode == 0, f"{where} failed ({proc.returncode}):\n{body}\n{last_output[-4000:]}"
            ran += 1
        elif lang == "yaml" and title:
            target = workdir / title
            if target.exists():
                target.write_text(replace_top_level_keys(target.read_text(), body))
            else:
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_text(body)
            last_output = None
        elif lang == "text" and last_output is not None:
            check_excerpt(body, last_output, where)
    assert ran >= 3, f"{page.name} shows only {ran} command blocks"


def test_replace_top_level_keys_edits_only_the_keys_given():
    text = "# head\nname: a\nactors:\n  - id: x\n# about factors\nfactors:\n  - f\n"
    edited = replace_top_level_keys(text, "actors:\n  - id: y\n  - id: z\n")
    assert edited == "# head\nname: a\nactors:\n  - id: y\n  - id: z\n# about factors\nfactors:\n  - f\n"
    with pytest.raises(AssertionError, match="does not have"):
        replace_top_level_keys(text, "gaits: {}\n")


def test_excerpt_check_fails_on_a_line_the_command_did_not_print():
    check_excerpt("a\n…\n  b  \n", "a\nx\nb\n", "page")
    with pytest.raises(AssertionError, match="did not print"):
        check_excerpt("a\nc\n", "a\nb\n", "page")


@pytest.mark.parametrize("name", ["qualtrics", "power"])
def test_tutorial_runs_as_written(name, tmp_path):
    run_tutorial(TUTORIALS / f"{name}.md", tmp_path)


@pytest.mark.slow   # fits three new bodies and renders a clip (tens of seconds on a cold cache)
def test_new_design_tutorial_runs_as_written(tmp_path):
    run_tutorial(TUTORIALS / "new-design.md", tmp_path)


@pytest.mark.slow   # renders the 16 quick clips of a study on captures (about a minute on 2 cores)
def test_own_captures_tutorial_runs_as_written(tmp_path):
    run_tutorial(TUTORIALS / "own-captures.md", tmp_path)
