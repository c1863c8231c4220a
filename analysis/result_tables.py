"""Result tables of the vote and ranking analyses, in the formats of the ANOVA tables: md, tex, csv, html, json.

A result is a list of :class:`ResultTable` (name, caption, a frame with exact numbers). Text formats (md,
tex, html) print p as the paper does (``<0.001`` …) and other numbers with two decimals; CSV (a ``table``
column, then every table's columns) and JSON (``{"tables": [{name, caption, columns, rows}]}``) carry the
exact numbers. JSON has no NaN or ±∞: such cells are ``null`` (as in ``summary.json``), and a table with a
±∞ cell (a t-test without any spread, e.g. every participant chose one position every time) lists them under
``non_finite`` as ``{"row": i, "column": c, "value": "inf" | "-inf"}`` (row counted from 0), so that the
sign is not lost. Text tables print ``∞`` and ``−∞``; CSV writes ``inf`` and ``-inf``.

>>> t = ResultTable("votes", "Votes per level", pd.DataFrame({"level": ["a", "b"], "votes": [7, 3], "p": [0.2, 0.2]}))
>>> print(render_results([t], "md"))
**Votes per level**
<BLANKLINE>
| level | votes | p |
|---|---:|---:|
| a | 7 | 0.20 |
| b | 3 | 0.20 |
<BLANKLINE>
"""

from __future__ import annotations

import html
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.errors import AnalysisError
from analysis.tables import SIMULATED_BANNER, format_num, format_p, md_escape, tex_escape

FORMATS = ("md", "tex", "csv", "html", "json")


@dataclass
class ResultTable:
    """One table of a result: ``name`` (CSV/JSON key), ``caption`` and one row per line of ``frame``."""

    name: str
    caption: str
    frame: pd.DataFrame


def format_cell(value, column: str) -> str:
    """A value as text tables print it: p the paper's way, whole numbers as such, others with two decimals."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return format_p(float(value)) if column == "p" else format_num(float(value))
    return str(value)


def _text_rows(frame: pd.DataFrame) -> list[list[str]]:
    return [[format_cell(v, c) for c, v in zip(frame.columns, row)] for row in frame.itertuples(index=False)]


def _numeric(frame: pd.DataFrame) -> list[bool]:
    return [pd.api.types.is_numeric_dtype(frame[c]) and not pd.api.types.is_bool_dtype(frame[c]) for c in frame]


def _markdown(table: ResultTable) -> str:
    """Caption, column names and cells are user text (position labels, participant ids, level names):
    :func:`analysis.tables.md_escape` keeps raw HTML and ``|`` out of the table."""
    align = "|".join("---:" if numeric else "---" for numeric in _numeric(table.frame))
    lines = [f"**{md_escape(table.caption)}**", "",
             "| " + " | ".join(md_escape(c) for c in table.frame.columns) + " |", f"|{align}|"]
    lines += ["| " + " | ".join(md_escape(cell) for cell in row) + " |" for row in _text_rows(table.frame)]
    return "\n".join(lines) + "\n"


def _latex(table: ResultTable) -> str:
    spec = "".join("r" if numeric else "l" for numeric in _numeric(table.frame))
    rows = [" & ".join(_tex_cell(cell) for cell in row) + r" \\" for row in _text_rows(table.frame)]
    return "\n".join([r"\begin{table}[htbp]", r"\centering", rf"\caption{{{tex_escape(table.caption)}}}",
                      rf"\begin{{tabular}}{{{spec}}}", r"\toprule",
                      " & ".join(tex_escape(c) for c in table.frame.columns) + r" \\", r"\midrule", *rows,
                      r"\bottomrule", r"\end{tabular}", r"\end{table}"]) + "\n"


def _tex_cell(cell: str) -> str:
    """A text cell for pdflatex, which has no glyph for ∞ (or the minus sign in −∞)."""
    return tex_escape(cell).replace("−∞", r"$-\infty$").replace("∞", r"$\infty$")


def _html(table: ResultTable) -> str:
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in table.frame.columns)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(cell)}</td>" for cell in row) + "</tr>\n"
                   for row in _text_rows(table.frame))
    return (f"<figure class=\"table\"><figcaption>{html.escape(table.caption)}</figcaption>\n"
            f"<table class=\"result\"><thead><tr>{head}</tr></thead>\n<tbody>\n{body}</tbody></table></figure>\n")


def _plain(value):
    """JSON value of a cell: numpy scalars as Python numbers; NaN and ±∞ (e.g. a t-test without any spread) as
    null, as JSON has no such numbers.

    >>> _plain(np.float64(0.5)), _plain(float("nan")), _plain(np.float64("inf"))
    (0.5, None, None)
    """
    value = value.item() if hasattr(value, "item") else value
    return None if isinstance(value, float) and not math.isfinite(value) else value


def json_safe(value):
    """``value`` (dicts, lists, numpy scalars) with every number as JSON can hold it: NaN and ±∞ as null.

    >>> json_safe({"t": np.float64("inf"), "rows": [np.int64(3), float("nan")]})
    {'t': None, 'rows': [3, None]}
    """
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return _plain(value)


def non_finite_cells(frame: pd.DataFrame) -> list[dict]:
    """The ±∞ cells of ``frame``, which JSON writes as null: ``[{"row": i, "column": c, "value": "-inf"}]``.

    >>> non_finite_cells(pd.DataFrame({"t": [1.0, float("-inf"), float("nan")]}))
    [{'row': 1, 'column': 't', 'value': '-inf'}]
    """
    cells = []
    for i, row in enumerate(frame.itertuples(index=False)):
        for column, value in zip(frame.columns, row):
            value = value.item() if hasattr(value, "item") else value
            if isinstance(value, float) and math.isinf(value):
                cells.append({"row": i, "column": str(column), "value": "inf" if value > 0 else "-inf"})
    return cells


def _json(tables: list[ResultTable]) -> str:
    out = []
    for t in tables:
        entry = {"name": t.name, "caption": t.caption, "columns": [str(c) for c in t.frame.columns],
                 "rows": [{str(c): _plain(v) for c, v in zip(t.frame.columns, row)}
                          for row in t.frame.itertuples(index=False)]}
        infinite = non_finite_cells(t.frame)
        if infinite:
            entry["non_finite"] = infinite
        out.append(entry)
    return json.dumps({"tables": out}, indent=2, ensure_ascii=False, allow_nan=False) + "\n"


def _csv(tables: list[ResultTable]) -> str:
    # object columns: a count stays a whole number where another table leaves its column empty
    frames = [t.frame.astype(object).assign(table=t.name)[["table", *t.frame.columns]] for t in tables]
    return pd.concat(frames, ignore_index=True).to_csv(index=False, lineterminator="\n")


def _banner(fmt: str) -> str:
    """The simulated-data banner above md, tex and html tables (csv and json stay plain data)."""
    return {"md": f"> **{md_escape(SIMULATED_BANNER)}**\n\n",
            "tex": f"\\noindent\\textbf{{{tex_escape(SIMULATED_BANNER)}}}\n\n",
            "html": f"<p class=\"simulated\"><strong>{html.escape(SIMULATED_BANNER)}</strong></p>\n"}.get(fmt, "")


def render_results(tables: list[ResultTable], fmt: str, simulated: bool = False) -> str:
    """All ``tables`` in one of :data:`FORMATS` (md, tex and html: one after the other, under the
    simulated-data banner when ``simulated``)."""
    if fmt not in FORMATS:
        raise AnalysisError(f"unknown table format {fmt!r}; choose one of {', '.join(FORMATS)}")
    if fmt == "json":
        return _json(tables)
    if fmt == "csv":
        return _csv(tables)
    one = {"md": _markdown, "tex": _latex, "html": _html}[fmt]
    return (_banner(fmt) if simulated else "") + "\n".join(one(t) for t in tables)


def write_results(tables: list[ResultTable], stem: Path, simulated: bool = False) -> list[str]:
    """Write ``stem.md``, ``.tex``, ``.csv``, ``.html`` and ``.json``; returns the file names."""
    for fmt in FORMATS:
        stem.with_suffix(f".{fmt}").write_text(render_results(tables, fmt, simulated), encoding="utf-8")
    return [f"{stem.name}.{fmt}" for fmt in FORMATS]
