"""ANOVA tables in the paper's layout, rendered from the Jinja2 templates in ``results_templates/``.

Layout (Table 3/4 of the paper): Effect, SS, dof, MS, F, p, η² (partial), nc, power, post-hoc (Tukey),
grouped into main effects / two-way / three-way … interactions, significant rows only unless
``all_rows`` (which also appends the error strata). Text formats print p like the paper (``<0.001``,
``<0.01``, ``<0.05``, else two decimals); CSV and JSON carry exact numbers. JSON is always the complete
DESIGN.md record list (every effect), whatever ``all_rows`` says. Text formats print sums of squares
that are rounding noise (relative to the table's total SS) as 0, ``—`` for an effect whose error term
has no variance (nothing is tested) and ``n.s.`` where Tukey ran but found no pair.
"""

from __future__ import annotations

import csv
import io
import json
import math
from functools import lru_cache
from pathlib import Path

import jinja2

from analysis.anova import EFFECT_COLUMNS, AnovaTable, corrected_p
from analysis.anova_core import NO_VARIANCE
from analysis.errors import AnalysisError

TEMPLATE_DIR = Path(__file__).resolve().parent.parent / "results_templates"
FORMATS = ("md", "tex", "csv", "html", "json")
ORDER_TITLES = {1: "Main effects", 2: "Two-way interaction effects", 3: "Three-way interaction effects",
                4: "Four-way interaction effects", 5: "Five-way interaction effects"}
HEADERS = ["Effect", "SS", "dof", "MS", "F", "p", "η²", "nc", "power"]
CSV_COLUMNS = ["section", "effect", "factors"] + EFFECT_COLUMNS + ["p_reported", "posthoc"]
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


def effect_statistics(row, p: float, noise: float) -> dict[str, str]:
    """F, p, η², nc and power of one effect as printed.

    ``—`` where F is undefined (no error variance or df: nothing is tested), ∞ where only the error term
    is rounding noise (the engine's F = ∞, so that the JSON, with F null, p 0 and power 1, says the same),
    0 where the effect's own SS is (its F, η² and nc are then noise too).
    """
    if math.isnan(float(row["F"])):
        return dict.fromkeys(("F", "p", "eta2", "nc", "power"), UNTESTABLE)
    shown = {"p": format_p(p), "power": format_num(row["power"])}
    if math.isinf(float(row["F"])):   # a ratio to rounding noise: F → ∞ and observed power → 1
        return shown | {"F": "∞", "eta2": format_num(row["eta2_partial"]), "nc": "∞"}
    if abs(row["ss"]) <= noise:
        return shown | dict.fromkeys(("F", "eta2", "nc"), format_num(0.0))
    return shown | {"F": format_num(row["F"]), "eta2": format_num(row["eta2_partial"]),
                    "nc": format_num(row["noncentrality"])}


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
    env.filters.update(tex=tex_escape, csvrow=_csv_row, json=_json)
    return env


def default_caption(table: AnovaTable, all_rows: bool, alpha: float, correction: str) -> str:
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
    corr = {"gg": ", Greenhouse–Geisser corrected p", "hf": ", Huynh–Feldt corrected p"}.get(correction, "")
    return (f"{kind} of {table.dv} ({'; '.join(parts)}; N = {table.n_subjects}): {rows}, with effect size "
            f"(partial η²), non-centrality (nc) and observed power (α = {table.alpha:g}){corr}.")


def table_context(table: AnovaTable, all_rows: bool = False, correction: str = "none", alpha: float | None = None,
                  caption: str | None = None, sep: str = "*") -> dict:
    """The data the templates see: sections of formatted rows, error strata, headers, caption, records."""
    correction = (correction or "none").lower()
    if correction not in ("none", "gg", "hf"):
        raise AnalysisError(f"unknown sphericity correction {correction!r}; use none, gg or hf")
    a = table.alpha if alpha is None else float(alpha)
    noise = noise_level(table)
    sections: dict[int, list] = {}
    for name, row in table.effects.iterrows():
        p = corrected_p(row, correction)
        if not all_rows and not p < a:
            continue
        eps = float(row["eps_gg" if correction == "gg" else "eps_hf"]) if correction != "none" else float("nan")
        scale = eps if not math.isnan(eps) else 1.0
        sections.setdefault(int(row["order"]), []).append({
            "effect": sep.join(row["factors"]),
            "name": name,
            "factors": list(row["factors"]),
            "ss": format_ss(row["ss"], noise),
            "dof": f"{format_df(row['df1'] * scale)}, {format_df(row['df2'] * scale)}",
            "ms": format_ss(row["ms"], noise),
            **effect_statistics(row, p, noise),
            "eps": format_eps(eps, within_df(table, row["factors"])) if correction != "none" else "",
            "posthoc": posthoc_text(table.posthoc.get(name), not math.isnan(float(row["F"]))),
            "numbers": [None if math.isnan(float(row[c])) else float(row[c]) for c in EFFECT_COLUMNS],
            "p_reported": None if math.isnan(p) else p,   # blank in CSV, as the other undefined numbers
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
    headers = list(HEADERS) + (["ε"] if correction != "none" else []) + (["post-hoc (Tukey)"] if show_posthoc else [])
    return {
        "caption": caption if caption is not None else default_caption(table, all_rows, a, correction) + (
            f" Tukey: {', '.join(untested)} not tested (—), their error term has no variance." if untested else ""),
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
           caption: str | None = None, alpha: float | None = None) -> str:
    """Render an :class:`AnovaTable` as ``md``, ``tex`` (booktabs), ``csv``, ``html`` or ``json``.

    Significant effects only (p < alpha, after ``correction`` none/gg/hf) unless ``all_rows``; post-hoc
    summaries appear when ``analysis.posthoc.tukey``/``tukey_all`` ran on the table.
    """
    fmt = fmt.lower().lstrip(".")
    if fmt == "markdown":
        fmt = "md"
    if fmt == "latex":
        fmt = "tex"
    if fmt not in FORMATS:
        raise AnalysisError(f"unknown table format {fmt!r}; choose one of {', '.join(FORMATS)}")
    ctx = table_context(table, all_rows=all_rows, correction=correction, alpha=alpha, caption=caption,
                        sep="*")
    if fmt == "csv":   # no caption in CSV: the post-hoc cell of an untested Tukey says why
        for row in (r for section in ctx["sections"] for r in section["rows"]):
            ph = table.posthoc.get(row["name"])
            if ph is not None and ph.untestable:
                row["posthoc"] = f"{UNTESTABLE} ({ph.untestable})"
    if fmt == "tex":   # pdflatex has no text glyph for ∞
        for row in (r for section in ctx["sections"] for r in section["rows"]):
            row.update({key: row[key].replace("∞", r"$\infty$") for key in ("F", "nc")})
    return _env().get_template(f"anova.{fmt}.j2").render(**ctx)
