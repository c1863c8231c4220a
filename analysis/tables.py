"""ANOVA tables in the paper's layout, rendered from the Jinja2 templates in ``results_templates/``.

Layout (Table 3/4 of the paper): Effect, SS, dof, MS, F, p, η² (partial), nc, power, post-hoc (Tukey),
grouped into main effects / two-way / three-way … interactions, significant rows only unless
``all_rows`` (which also appends the error strata). Text formats print p like the paper (``<0.001``,
``<0.01``, ``<0.05``, else two decimals); CSV and JSON carry exact numbers. JSON is always the complete
DESIGN.md record list (every effect), whatever ``all_rows`` says.
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
from analysis.errors import AnalysisError

TEMPLATE_DIR = Path(__file__).resolve().parent.parent / "results_templates"
FORMATS = ("md", "tex", "csv", "html", "json")
ORDER_TITLES = {1: "Main effects", 2: "Two-way interaction effects", 3: "Three-way interaction effects",
                4: "Four-way interaction effects", 5: "Five-way interaction effects"}
HEADERS = ["Effect", "SS", "dof", "MS", "F", "p", "η²", "nc", "power"]
CSV_COLUMNS = ["section", "effect", "factors"] + EFFECT_COLUMNS + ["p_reported", "posthoc"]


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
        return "∞"
    if x != 0 and abs(x) < 0.5 * 10**-digits:
        return f"{x:.2g}"
    return f"{x:.{digits}f}"


def format_df(x: float) -> str:
    return f"{x:.0f}" if float(x).is_integer() else f"{x:.2f}"


def _order_title(order: int) -> str:
    return ORDER_TITLES.get(order, f"{order}-way interaction effects")


def _tex_escape(s: str) -> str:
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
    env.filters.update(tex=_tex_escape, csvrow=_csv_row, json=_json)
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
    sections: dict[int, list] = {}
    for name, row in table.effects.iterrows():
        p = corrected_p(row, correction)
        if not all_rows and not p < a:
            continue
        eps = float(row["eps_gg" if correction == "gg" else "eps_hf"]) if correction != "none" else float("nan")
        scale = eps if not math.isnan(eps) else 1.0
        ph = table.posthoc.get(name)
        sections.setdefault(int(row["order"]), []).append({
            "effect": sep.join(row["factors"]),
            "name": name,
            "factors": list(row["factors"]),
            "ss": format_num(row["ss"]),
            "dof": f"{format_df(row['df1'] * scale)}, {format_df(row['df2'] * scale)}",
            "ms": format_num(row["ms"]),
            "F": format_num(row["F"]),
            "p": format_p(p),
            "eta2": format_num(row["eta2_partial"]),
            "nc": format_num(row["noncentrality"]),
            "power": format_num(row["power"]),
            "eps": format_num(eps, 3),
            "posthoc": ph.summary if ph is not None else "",
            "numbers": [None if math.isnan(float(row[c])) else float(row[c]) for c in EFFECT_COLUMNS],
            "p_reported": p,
            "significant": p < a,
        })
    sec_list = [{"order": o, "title": _order_title(o), "rows": sections[o]} for o in sorted(sections)]
    strata = []
    if all_rows:
        for label, s in table.strata.iterrows():
            strata.append({"effect": label, "ss": format_num(s["ss"]), "dof": format_df(s["df"]),
                           "ms": format_num(s["ms"]), "raw": {"ss": float(s["ss"]), "df": float(s["df"]),
                                                              "ms": float(s["ms"])}})
    show_posthoc = bool(table.posthoc)
    headers = list(HEADERS) + (["ε"] if correction != "none" else []) + (["post-hoc (Tukey)"] if show_posthoc else [])
    return {
        "caption": caption if caption is not None else default_caption(table, all_rows, a, correction),
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
    return _env().get_template(f"anova.{fmt}.j2").render(**ctx)
