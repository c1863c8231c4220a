"""Griffe extension for the API reference: docstring examples written as bare doctests (``>>>`` lines,
as the doctests in CI read them) are shown as Python console code blocks, not as Markdown text
(where ``>>>`` would become nested quotes and ``x[0]`` a link). Loaded by mkdocs.yml's mkdocstrings
options."""

from __future__ import annotations

import griffe


def fence_doctests(text: str) -> str:
    r"""Wrap each run of doctest lines (a ``>>>`` line up to the next blank line) in a ``pycon`` fence.

    >>> fence_doctests("Add.\n\n>>> 1 + 1\n2\n\nDone.").splitlines()
    ['Add.', '', '```pycon', '>>> 1 + 1', '2', '```', '', 'Done.']
    """
    out, in_doctest, in_fence = [], False, False
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("```") and not in_doctest:
            in_fence = not in_fence
        elif not in_fence and not in_doctest and stripped.startswith(">>>"):
            out.append("```pycon")
            in_doctest = True
        elif in_doctest and not stripped:
            out.append("```")
            in_doctest = False
        out.append(line)
    if in_doctest:
        out.append("```")
    return "\n".join(out)


class FenceDoctests(griffe.Extension):
    def on_instance(self, *, obj: griffe.Object, **kwargs) -> None:  # noqa: ARG002 (griffe's signature)
        if obj.docstring is not None:
            obj.docstring.value = fence_doctests(obj.docstring.value)
