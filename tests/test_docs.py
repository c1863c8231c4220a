"""The documentation site builds with no warning (mkdocs --strict: broken links and anchors, pages
left out of the nav), its generated reference parts come from the code, and the README stays a
two-screen page whose links resolve."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("site")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert proc.returncode == 0, proc.stderr[-4000:]
    assert "WARNING" not in proc.stderr, proc.stderr[-4000:]
    return out


def test_strict_build_has_every_page(site):
    for page in ["index.html", "getting-started.html", "limits.html", "reference/cli.html",
                 "reference/protocol.html", "reference/api.html", "tutorials/own-captures.html",
                 "readme_anova.html", "readme_captures.html"]:
        assert (site / page).is_file(), page
    assert (site / "img" / "report_figure4.png").is_file()
    assert not (site / "hooks.py").exists()   # the build hook is not published


def test_cli_reference_is_every_commands_help(site):
    from stimuli.cli import build_parser

    html = (site / "reference" / "cli.html").read_text()
    assert "<!-- generated: cli -->" not in html
    commands = next(a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction").choices
    for name in commands:
        assert f"shapemotion {name}</code>" in html, name
    assert "--participants" in html and "--responses" in html


def test_protocol_fields_come_from_the_models(site):
    html = (site / "reference" / "protocol.html").read_text()
    assert "<!-- generated: protocol-fields -->" not in html
    # one field of each kind of part, with the description the model carries
    for field in ["height_m", "maps_to", "duration_s", "dependent_measure"]:
        assert f"<code>{field}</code>" in html, field


def test_api_reference_is_rendered_from_docstrings(site):
    import shapemotion

    html = (site / "reference" / "api.html").read_text()
    assert ":::" not in html   # every mkdocstrings directive resolved
    assert "analysis.anova.anova" in html and "Split-plot ANOVA" in html
    for name in shapemotion.__all__:
        assert f'id="shapemotion.api.{name}"' in html, name
    # doctest examples are code blocks, not Markdown (where '>>>' would be nested quotes)
    assert "<blockquote>" not in html and "&gt;&gt;&gt;" in html


def test_doc_hooks_examples_run():
    import doctest
    import importlib.util

    for name in ["hooks", "hooks_griffe"]:
        spec = importlib.util.spec_from_file_location(name, ROOT / "docs" / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        result = doctest.testmod(module)
        assert result.failed == 0, name
    assert result.attempted >= 1


def test_no_list_is_rendered_as_part_of_a_paragraph(site):
    """Python-Markdown starts a list only after a blank line: a list written straight under a
    paragraph line renders as that paragraph's text, its dashes inline."""
    swallowed = []
    for page in sorted(site.rglob("*.html")):
        for paragraph in re.findall(r"<p>(.*?)</p>", page.read_text(), re.S):
            if re.search(r"\n(?:- |\d+\. )\S", paragraph):
                swallowed.append(f"{page.relative_to(site)}: {paragraph[:80]!r}")
    assert not swallowed, "\n".join(swallowed)


def test_readme_is_two_screens_with_working_links():
    text = (ROOT / "README.md").read_text()
    lines = text.splitlines()
    assert len(lines) <= 120
    # the title, then the two commands before anything else
    assert lines[0] == "# shapemotion" and lines[2] == "```sh"
    assert lines[3].startswith("make demo") and lines[4].startswith("make test")
    targets = re.findall(r"\]\(([^)\s]+)\)", text)
    local = [t.split("#")[0] for t in targets if not re.match(r"[a-z]+://", t)]
    assert len(local) >= 10
    for target in local:
        assert (ROOT / target).is_file(), f"README links to {target}, which does not exist"
    assert any(t.startswith("docs/img/") for t in local)
