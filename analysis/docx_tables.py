"""ANOVA tables as Word documents (``.docx``, python-docx), in APA style, for pasting into a paper.

The same rows as the md/html tables (:func:`analysis.tables.table_context` with ``style="apa"``: p as
``< .001`` / ``.031``, η² and power without the leading zero), laid out the APA way — a bold table number, an
italic title, horizontal rules only (above and below the header, below the last row), italic *F* and *p* — and
followed by one APA sentence per reported effect (italic *F* and *p*). A table of simulated responses starts with
the simulated-data banner.

>>> from analysis.anova import anova                                          # doctest: +SKIP
>>> write_docx(anova(data, "rating", "participant", ["GAIT"], ["SEX"]), "anova.docx")   # doctest: +SKIP
"""

from __future__ import annotations

import io
from pathlib import Path

from docx import Document
from docx.enum.text import WD_ALIGN_PARAGRAPH
from docx.oxml import OxmlElement
from docx.oxml.ns import qn
from docx.shared import Pt, RGBColor

from analysis.anova import AnovaTable
from analysis.io_files import atomic_write_bytes
from analysis.tables import table_context

ITALIC_HEADERS = {"F", "p"}
HEADER_TEXT = {"η²": "ηp²"}   # the table's η² is partial η²; APA names it so


def docx_bytes(table: AnovaTable, all_rows: bool = False, correction: str = "none", corrected_power: str = "spss",
               caption: str | None = None, alpha: float | None = None, simulated: bool = False,
               number: int = 1) -> bytes:
    """The ``.docx`` file of ``table`` (arguments as :func:`analysis.tables.render`; ``number``: "Table N")."""
    ctx = table_context(table, all_rows=all_rows, correction=correction, alpha=alpha, caption=caption, sep=" × ",
                        corrected_power=corrected_power, style="apa", simulated=simulated)
    doc = Document()
    doc.styles["Normal"].font.name = "Times New Roman"
    doc.styles["Normal"].font.size = Pt(11)
    if ctx["banner"]:
        run = doc.add_paragraph().add_run(ctx["banner"])
        run.bold = True
        run.font.color.rgb = RGBColor(0xB0, 0x00, 0x00)
    doc.add_paragraph().add_run(f"Table {number}").bold = True
    doc.add_paragraph().add_run(ctx["caption"]).italic = True
    _table(doc, ctx)
    if ctx["empty"]:
        doc.add_paragraph(f"No effect reaches p < {ctx['alpha']:g}.")
    reported = [r for s in ctx["sections"] for r in s["rows"] if r["apa_parts"]]
    if reported:
        doc.add_paragraph(f"{ctx['apa_title']}:")
        for r in reported:
            par = doc.add_paragraph(style="List Bullet")
            par.add_run(f"{r['label']}: ")
            for text, italic in r["apa_parts"]:
                par.add_run(text).italic = italic
    buffer = io.BytesIO()
    doc.save(buffer)
    return buffer.getvalue()


def write_docx(table: AnovaTable, path: str | Path, **kwargs) -> None:
    """Write :func:`docx_bytes` to ``path`` atomically (a failed run leaves no partial file)."""
    atomic_write_bytes(path, docx_bytes(table, **kwargs))


def _table(doc, ctx: dict) -> None:
    headers = ctx["headers"]
    keys = ["effect", "ss", "dof", "ms", "F", "p", "eta2", "nc", "power"] + (["eps"] if ctx["show_eps"] else []) + (
        ["posthoc"] if ctx["show_posthoc"] else [])
    numeric_until = len(keys) - ctx["show_posthoc"]
    grid = doc.add_table(rows=1, cols=len(headers))
    for cell, h in zip(grid.rows[0].cells, headers):
        run = cell.paragraphs[0].add_run(HEADER_TEXT.get(h, h))
        run.italic = h in ITALIC_HEADERS
    _rule(grid.rows[0], "top")
    _rule(grid.rows[0], "bottom")
    for section in ctx["sections"]:
        row = grid.add_row()
        merged = row.cells[0].merge(row.cells[-1])
        merged.paragraphs[0].add_run(section["title"]).italic = True
        for r in section["rows"]:
            _values(grid.add_row(), [r[k] for k in keys], numeric_until)
    if ctx["strata"]:
        row = grid.add_row()
        row.cells[0].merge(row.cells[-1]).paragraphs[0].add_run("Error").italic = True
        for s in ctx["strata"]:
            _values(grid.add_row(), [s["effect"], s["ss"], s["dof"], s["ms"]] + [""] * (len(headers) - 4),
                    numeric_until)
    _rule(grid.rows[-1], "bottom")


def _values(row, values: list[str], numeric_until: int) -> None:
    """Fill a row; columns 1 … numeric_until − 1 hold numbers and are right-aligned, as in the md table."""
    for i, (cell, value) in enumerate(zip(row.cells, values)):
        cell.text = str(value)
        if 0 < i < numeric_until:
            cell.paragraphs[0].alignment = WD_ALIGN_PARAGRAPH.RIGHT


def _rule(row, side: str) -> None:
    """A horizontal rule (APA tables have no vertical lines) on one side of every cell of ``row``."""
    for cell in row.cells:
        borders = cell._tc.get_or_add_tcPr().first_child_found_in("w:tcBorders")
        if borders is None:
            borders = OxmlElement("w:tcBorders")
            cell._tc.get_or_add_tcPr().append(borders)
        edge = OxmlElement(f"w:{side}")
        for key, value in (("val", "single"), ("sz", "8"), ("space", "0"), ("color", "000000")):
            edge.set(qn(f"w:{key}"), value)
        borders.append(edge)
