"""ANOVA tables in the paper's layout, rendered from the Jinja2 templates in ``results_templates/``.

Layout (Table 3/4 of the paper): Effect, SS, dof, MS, F, p, η² (partial), nc, power, post-hoc (Tukey),
grouped into main effects / two-way / three-way … interactions, significant rows only unless
``all_rows`` (which also appends the error strata). Text formats print p like the paper (``<0.001``,
``<0.01``, ``<0.05``, else two decimals); CSV and JSON carry exact numbers. JSON is always the complete
DESIGN.md record list (every effect), whatever ``all_rows`` says. Text formats print sums of squares
that are rounding noise (relative to the table's total SS) as 0, ``—`` for an effect whose error term
has no variance (nothing is tested) and ``n.s.`` where Tukey ran but found no pair.

``style="apa"`` prints p as APA does (``< .001``, ``.031``: no leading zero for numbers that cannot exceed 1,
also η² and power); md and html follow the table with one APA sentence per reported effect
(``F(1.84, 25.8) = 4.12, p = .031, ηp² = .23``, with the corrected df under a correction), in either style.
Every piece of user text (factor names, level abbreviations, captions) goes into md through
:func:`md_escape` (no ``<`` that could open raw HTML, ``|`` escaped), so a label cannot inject markup or
break a row; html autoescapes.
"""

from __future__ import annotations

import csv
import html
import io
import json
import math
import re
from functools import lru_cache
from pathlib import Path

import jinja2

from analysis.anova import EFFECT_COLUMNS, AnovaTable, reported_statistics
from analysis.anova_core import NO_VARIANCE
from analysis.errors import AnalysisError

TEMPLATE_DIR = Path(__file__).resolve().parent.parent / "results_templates"
FORMATS = ("md", "tex", "csv", "html", "json")
ORDER_TITLES = {1: "Main effects", 2: "Two-way interaction effects", 3: "Three-way interaction effects",
                4: "Four-way interaction effects", 5: "Five-way interaction effects"}
HEADERS = ["Effect", "SS", "dof", "MS", "F", "p", "η²", "nc", "power"]
# *_reported: the numbers the row reports under --correction (df × ε, corrected p, nc and power as
# --corrected-power reads them); equal to the uncorrected columns without a correction
CSV_COLUMNS = ["section", "effect", "factors"] + EFFECT_COLUMNS + ["p_reported", "posthoc", "df1_reported",
                                                                   "df2_reported", "nc_reported", "power_reported"]
STYLES = ("paper", "apa")
SIMULATED_BANNER = ("SIMULATED DATA: these responses were drawn by shapemotion simulate from a generative model; "
                    "no participant gave them. Do not report these numbers as results.")
UNTESTABLE = "—"        # F = 0/0: the error term has no variance (or no df), so there is no test
NOT_SIGNIFICANT = "n.s."  # Tukey ran on the effect but no pair of its cells differs


def format_p(p: float) -> str:
    """The paper's p: ``<0.001``, ``<0.01``, ``<0.05``, else two decimals (three below 0.1)."""
    if p is None or math.isnan(p):
        return ""
    for cut in (0.001, 0.01, 0.05):
        if p < cut:
            return f"<{cut:g}"
    return f"{p:.3f}" if p < 0.1 else f"{p:.2f}"


def format_p_apa(p: float) -> str:
    """p as APA 7 prints it: three decimals without the leading zero, ``< .001`` below that (never ``.000``).

    >>> [format_p_apa(p) for p in (0.0004, 0.031, 0.5, 0.99971)]
    ['< .001', '.031', '.500', '> .999']
    """
    if p is None or math.isnan(p):
        return ""
    if p < 0.001:
        return "< .001"
    if p >= 0.9995:
        return "> .999"
    return f"{p:.3f}".lstrip("0")


def format_unit_apa(x: float, digits: int = 2) -> str:
    """A number that cannot exceed 1 (η², power) without its leading zero, as APA asks.

    >>> format_unit_apa(0.2291), format_unit_apa(0.99971), format_unit_apa(0.004)
    ('.23', '1.00', '.00')
    """
    if x is None or math.isnan(x):
        return ""
    text = f"{x:.{digits}f}"
    return text[1:] if text.startswith("0.") else text


def format_df_apa(x: float) -> str:
    """Degrees of freedom in a sentence: whole numbers as such, corrected ones to 3 significant digits.

    >>> [format_df_apa(x) for x in (14.0, 1.8412, 25.78, 125.6)]
    ['14', '1.84', '25.8', '126']
    """
    if float(x).is_integer():
        return f"{x:.0f}"
    return f"{x:.2f}" if x < 10 else f"{x:.1f}" if x < 100 else f"{x:.0f}"


def apa_parts(stats: dict, eta2: float) -> list[tuple[str, bool]]:
    """The APA report of one effect as (text, italic) pieces, for :func:`apa_sentence` and the .docx writer;
    ``[]`` for an untestable effect (F = 0/0). ``stats``: F and :func:`analysis.anova.reported_statistics`."""
    F = stats["F"]
    if F is None or math.isnan(F):
        return []
    shown_p = format_p_apa(stats["p"])
    relation = shown_p if shown_p[0] in "<>" else f"= {shown_p}"
    shown_f = "∞" if math.isinf(F) else f"{F:.2f}"
    return [("F", True), (f"({format_df_apa(stats['df1'])}, {format_df_apa(stats['df2'])}) = {shown_f}, ", False),
            ("p", True), (f" {relation}, ηp² = {format_unit_apa(eta2)}", False)]


def apa_sentence(stats: dict, eta2: float, markup: str = "text") -> str:
    """The APA report of one effect, from :func:`analysis.anova.reported_statistics` and its partial η².

    ``markup``: ``text`` (plain), ``md`` (*F*, *p* in italics) or ``html`` (``<i>``, text escaped). ``""``
    for an untestable effect (F = 0/0).

    >>> apa_sentence({"F": 4.1234, "df1": 1.8412, "df2": 25.78, "p": 0.0312}, 0.2291)
    'F(1.84, 25.8) = 4.12, p = .031, ηp² = .23'
    >>> apa_sentence({"F": 33.76, "df1": 1.0, "df2": 14.0, "p": 4.5e-05}, 0.7068, markup="html")
    '<i>F</i>(1, 14) = 33.76, <i>p</i> &lt; .001, ηp² = .71'
    """
    wrap, plain = {"text": ("{}", str), "md": ("*{}*", str), "html": ("<i>{}</i>", html.escape)}[markup]
    return "".join(wrap.format(text) if italic else plain(text) for text, italic in apa_parts(stats, eta2))


MARKUP_OPENER = re.compile(r"<(?=[A-Za-z/!?])")


def md_escape(text) -> str:
    """User text for a Markdown table cell: ``|`` escaped, line breaks folded and every ``<`` that could open
    raw HTML written as ``&lt;``, so that a label can neither inject markup nor break the row; ``*`` and ``_``
    are escaped too, so that an interaction written the Statistica way (``SEX*GAIT*BODY``) is not read as
    emphasis (renderers showed ``GAIT`` in italics and the stars disappeared).

    Markdown passes raw HTML through; in CommonMark a tag, comment, declaration or autolink starts with
    ``<`` followed by a letter, ``/``, ``!`` or ``?``, so those are the ``<`` escaped. Others (``p < 0.05``,
    ``<0.001``) and ``>`` (``W > J``) cannot start markup mid-line and stay readable in the file.

    >>> print(md_escape("<img src=x onerror=alert(1)> | a\\nb, p < .05"))
    &lt;img src=x onerror=alert(1)> \\| a b, p < .05
    >>> print(md_escape("SEX*GAIT*my_factor"))
    SEX\\*GAIT\\*my\\_factor
    """
    flat = " ".join(str(text).splitlines())
    return MARKUP_OPENER.sub("&lt;", flat).replace("|", "\\|").replace("*", "\\*").replace("_", "\\_")


def format_num(x: float, digits: int = 2) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return ""
    if math.isinf(x):
        return "∞" if x > 0 else "−∞"
    if x != 0 and abs(x) < 0.5 * 10**-digits:
        return f"{x:.2g}"
    return f"{x:.{digits}f}"


def noise_level(table: AnovaTable) -> float:
    """Sums of squares at or below this are rounding noise (e.g. % NoCOM + % COM = 100 leaves 1e-27 where 0 is
    exact): the engine's NO_VARIANCE relative to the table's total SS."""
    return NO_VARIANCE * (float(table.effects["ss"].sum()) + float(table.strata["ss"].sum()))


def format_ss(x: float, noise: float) -> str:
    """An SS or MS as printed: 0 when it is rounding noise, else :func:`format_num`."""
    return format_num(0.0 if abs(x) <= noise else x)


def effect_statistics(row, reported: dict, noise: float, style: str = "paper") -> dict[str, str]:
    """F, p, η², nc and power of one effect as printed (p, nc and power from ``reported``, i.e.
    :func:`analysis.anova.reported_statistics`; ``style`` paper or apa).

    ``—`` where F is undefined (no error variance or df: nothing is tested), ∞ where only the error term
    is rounding noise (the engine's F = ∞, so that the JSON, with F null, p 0 and power 1, says the same),
    0 where the effect's own SS is (its F, η² and nc are then noise too).
    """
    if math.isnan(float(row["F"])):
        return dict.fromkeys(("F", "p", "eta2", "nc", "power"), UNTESTABLE)
    apa = style == "apa"
    unit = format_unit_apa if apa else format_num
    shown = {"p": (format_p_apa if apa else format_p)(reported["p"]), "power": unit(reported["power"])}
    if math.isinf(float(row["F"])):   # a ratio to rounding noise: F → ∞ and observed power → 1
        return shown | {"F": "∞", "eta2": unit(row["eta2_partial"]), "nc": "∞"}
    if abs(row["ss"]) <= noise:
        return shown | {"F": format_num(0.0), "eta2": unit(0.0), "nc": format_num(0.0)}
    return shown | {"F": format_num(row["F"]), "eta2": unit(row["eta2_partial"]), "nc": format_num(reported["nc"])}


def posthoc_header(table: AnovaTable) -> str:
    """The post-hoc column's header says how its pairs were tested: ``post-hoc (Tukey, univariate, emmeans
    means)``; under the statistica convention with a mixed effect it adds that pairs across between groups
    are not protected there."""
    results = list(table.posthoc.values())
    text = "post-hoc (" + " / ".join(dict.fromkeys(ph.label for ph in results))
    if any(ph.unprotected for ph in results):
        text += "; pairs across between groups not protected"
    return text + ")"


def posthoc_text(ph, testable: bool) -> str:
    """The post-hoc cell: the paper's summary, ``n.s.`` when Tukey found no pair, ``—`` for an untested effect
    (its F is 0/0, or Tukey found its error term without variance)."""
    if ph is None:
        return ""
    if not testable or ph.untestable:
        return UNTESTABLE
    return ph.summary or NOT_SIGNIFICANT


def within_df(table: AnovaTable, factors) -> int:
    """Contrast dimension d of an effect's within part: ε and Mauchly exist only where d ≥ 2."""
    return math.prod(len(table.design.within[f]) - 1 for f in factors if f in table.design.within)


def format_eps(eps: float, d: int) -> str:
    """ε as printed: blank where no correction applies (d < 2), ``—`` where it applies but the error SSCP
    is singular (no variance in some contrast: ε would be a ratio of rounding noise; p and dof uncorrected)."""
    if math.isnan(eps):
        return UNTESTABLE if d >= 2 else ""
    return format_num(eps, 3)


def format_df(x: float) -> str:
    return f"{x:.0f}" if float(x).is_integer() else f"{x:.2f}"


def _order_title(order: int) -> str:
    return ORDER_TITLES.get(order, f"{order}-way interaction effects")


def tex_escape(s: str) -> str:
    """Text for pdflatex: LaTeX's special characters escaped, η², α, ×, ε and – as TeX."""
    repl = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_",
            "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}", "^": r"\textasciicircum{}", "<": r"$<$", ">": r"$>$"}
    out = "".join(repl.get(c, c) for c in str(s))
    for u, t in (("η²", r"$\eta^2$"), ("α", r"$\alpha$"), ("×", r"$\times$"), ("ε", r"$\varepsilon$"), ("–", "--")):
        out = out.replace(u, t)
    return out


def _csv_row(values) -> str:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="").writerow(["" if v is None else v for v in values])
    return buf.getvalue()


def _json(obj) -> str:
    return json.dumps(obj, indent=2, ensure_ascii=False, allow_nan=False)


@lru_cache(maxsize=1)
def _env() -> jinja2.Environment:
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(TEMPLATE_DIR)),
        autoescape=lambda name: bool(name) and name.endswith(".html.j2"),
        trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True, undefined=jinja2.StrictUndefined,
    )
    env.filters.update(tex=tex_escape, csvrow=_csv_row, json=_json, md=md_escape)
    return env


def default_caption(table: AnovaTable, all_rows: bool, alpha: float, correction: str,
                    corrected_power: str = "spss") -> str:
    kind = "Mixed ANOVA" if table.within and table.between else (
        "Repeated-measures ANOVA" if table.within else "Between-subjects ANOVA")
    parts = []
    if table.between:
        parts.append("between " + " × ".join(table.between))
    if table.within:
        parts.append("within " + " × ".join(table.within))
    lo, hi = table.rows_per_cell
    if hi > 1:
        parts.append(f"{lo}" + (f"–{hi}" if hi > lo else "") + " rows averaged per subject × cell")
    rows = "all effects" if all_rows else f"significant effects (p < {alpha:g})"
    corr = {"gg": ", Greenhouse–Geisser", "hf": ", Huynh–Feldt"}.get(correction, "")
    if corr:
        corr += (" corrected dof and p (nc and power from the corrected dof, as SPSS)" if corrected_power == "spss"
                 else " corrected dof and p (nc and power uncorrected)")
    return (f"{kind} of {table.dv} ({'; '.join(parts)}; N = {table.n_subjects}): {rows}, with effect size "
            f"(partial η²), non-centrality (nc) and observed power (α = {table.alpha:g}){corr}.")


def _finite_or_none(x: float):
    return None if math.isnan(x) else x


def table_context(table: AnovaTable, all_rows: bool = False, correction: str = "none", alpha: float | None = None,
                  caption: str | None = None, sep: str = "*", corrected_power: str = "spss", style: str = "paper",
                  simulated: bool = False) -> dict:
    """The data the templates see: sections of formatted rows, error strata, headers, caption, records,
    one APA sentence per row (``apa``: plain text, ``apa_md``, ``apa_html``) and the simulated-data banner."""
    correction = (correction or "none").lower()
    if correction not in ("none", "gg", "hf"):
        raise AnalysisError(f"unknown sphericity correction {correction!r}; use none, gg or hf")
    if style not in STYLES:
        raise AnalysisError(f"unknown table style {style!r}; use {' or '.join(STYLES)}")
    a = table.alpha if alpha is None else float(alpha)
    noise = noise_level(table)
    sections: dict[int, list] = {}
    for name, row in table.effects.iterrows():
        rep = reported_statistics(row, correction, corrected_power, table.alpha)
        p = rep["p"]
        if not all_rows and not p < a:
            continue
        sentence = {"F": float(row["F"]), **rep}
        sections.setdefault(int(row["order"]), []).append({
            "effect": sep.join(row["factors"]),
            "label": " × ".join(row["factors"]),   # the APA sentences' name of the effect
            "name": name,
            "factors": list(row["factors"]),
            "ss": format_ss(row["ss"], noise),
            "dof": f"{format_df(rep['df1'])}, {format_df(rep['df2'])}",
            "ms": format_ss(row["ms"], noise),
            **effect_statistics(row, rep, noise, style),
            "eps": format_eps(rep["eps"], within_df(table, row["factors"])) if correction != "none" else "",
            "posthoc": posthoc_text(table.posthoc.get(name), not math.isnan(float(row["F"]))),
            "numbers": [None if math.isnan(float(row[c])) else float(row[c]) for c in EFFECT_COLUMNS],
            "p_reported": _finite_or_none(p),   # blank in CSV, as the other undefined numbers
            "reported": [rep["df1"], rep["df2"], _finite_or_none(rep["nc"]), _finite_or_none(rep["power"])],
            "apa": apa_sentence(sentence, float(row["eta2_partial"])),
            "apa_parts": apa_parts(sentence, float(row["eta2_partial"])),
            "apa_md": apa_sentence(sentence, float(row["eta2_partial"]), "md"),
            "apa_html": apa_sentence(sentence, float(row["eta2_partial"]), "html"),
            "significant": p < a,
        })
    sec_list = [{"order": o, "title": _order_title(o), "rows": sections[o]} for o in sorted(sections)]
    untested = [r["effect"] for s in sec_list for r in s["rows"]
                if getattr(table.posthoc.get(r["name"]), "untestable", "")]
    strata = []
    if all_rows:
        for label, s in table.strata.iterrows():
            strata.append({"effect": label, "ss": format_ss(s["ss"], noise), "dof": format_df(s["df"]),
                           "ms": format_ss(s["ms"], noise) if s["df"] > 0 else UNTESTABLE,
                           "raw": {"ss": float(s["ss"]), "df": float(s["df"]),
                                                              "ms": float(s["ms"])}})
    show_posthoc = bool(table.posthoc)
    headers = (list(HEADERS) + (["ε"] if correction != "none" else [])
               + ([posthoc_header(table)] if show_posthoc else []))
    return {
        "caption": caption if caption is not None else default_caption(table, all_rows, a, correction,
                                                                        corrected_power) + (
            f" Tukey: {', '.join(untested)} not tested (—), their error term has no variance." if untested else ""),
        "banner": SIMULATED_BANNER if simulated else "",
        "apa_title": "APA-style report" + {"gg": " (Greenhouse–Geisser corrected)",
                                            "hf": " (Huynh–Feldt corrected)"}.get(correction, ""),
        "sections": sec_list,
        "strata": strata,
        "headers": headers,
        "show_eps": correction != "none",
        "show_posthoc": show_posthoc,
        "ncols": len(headers),
        "alpha": a,
        "correction": correction,
        "records": table.to_records(),
        "csv_columns": CSV_COLUMNS,
        "dv": table.dv,
        "empty": not sec_list,
    }


def render(table: AnovaTable, fmt: str = "md", all_rows: bool = False, correction: str = "none",
           caption: str | None = None, alpha: float | None = None, corrected_power: str = "spss",
           style: str = "paper", simulated: bool = False) -> str:
    """Render an :class:`AnovaTable` as ``md``, ``tex`` (booktabs), ``csv``, ``html`` or ``json``.

    Significant effects only (p < alpha, after ``correction`` none/gg/hf) unless ``all_rows``; post-hoc
    summaries appear when ``analysis.posthoc.tukey``/``tukey_all`` ran on the table. ``corrected_power``
    (spss or uncorrected) is how nc and power read on corrected rows (:func:`analysis.anova.reported_statistics`);
    ``style`` paper (``<0.001``) or apa (``< .001``); ``simulated`` puts the simulated-data banner on md,
    html and tex. ``.docx``: :func:`analysis.docx_tables.write_docx`.
    """
    fmt = fmt.lower().lstrip(".")
    if fmt == "markdown":
        fmt = "md"
    if fmt == "latex":
        fmt = "tex"
    if fmt not in FORMATS:
        raise AnalysisError(f"unknown table format {fmt!r}; choose one of {', '.join(FORMATS)}")
    ctx = table_context(table, all_rows=all_rows, correction=correction, alpha=alpha, caption=caption,
                        sep="*", corrected_power=corrected_power, style=style, simulated=simulated)
    if fmt == "csv":   # no caption in CSV: the post-hoc cell of an untested Tukey says why
        for row in (r for section in ctx["sections"] for r in section["rows"]):
            ph = table.posthoc.get(row["name"])
            if ph is not None and ph.untestable:
                row["posthoc"] = f"{UNTESTABLE} ({ph.untestable})"
    if fmt == "tex":   # pdflatex has no text glyph for ∞
        for row in (r for section in ctx["sections"] for r in section["rows"]):
            row.update({key: row[key].replace("∞", r"$\infty$") for key in ("F", "nc")})
    return _env().get_template(f"anova.{fmt}.j2").render(**ctx)
