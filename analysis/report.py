"""``shapemotion analyze``: responses + design directory → tables, figures, exclusions and one ``report.html``.

Steps: import (explicit exclusions) → the design's dependent measure → the protocol's analysis (mixed /
repeated-measures ANOVA with Tukey post-hoc for Likert and 2AFC designs; χ², Friedman and binomial
tests for k-AFC votes and rankings, participants as the unit: :mod:`analysis.choice_sections`) → paper-style
tables (md, tex, csv, html, json) → figures (PNG, SVG, PDF) → the additional modern models → for choices, a
position-bias check (:mod:`analysis.position_bias`) → ``report.html`` (self-contained: figures inlined as PNG
data).
Everything is written into a staging folder and moved into place at the end, so an error leaves no
partial report.

>>> summary = analyze("demo_output/exp1_shape_motion",
...                   "demo_output/exp1_shape_motion/results/responses.csv", "report")   # doctest: +SKIP
>>> sorted(summary), summary["import"]["participants"]                                    # doctest: +SKIP
(['design', 'import', 'sections'], 16)
"""

from __future__ import annotations

import base64
import dataclasses
import json
import platform
import shutil
import tempfile
from pathlib import Path

import pandas as pd

from analysis.errors import AnalysisError
from analysis.io_design import DesignInfo, load_design
from analysis.io_files import check_output_folder, replace_directory
from analysis.choice_sections import ranking_section, votes_section
from analysis.measures import anova_input
from analysis.position_bias import position_section
from analysis.responses import ImportResult, import_responses
from analysis.result_tables import json_safe
from analysis.simulate import simulated_export
from analysis.tables import SIMULATED_BANNER

TABLE_FORMATS = ("md", "tex", "csv", "html", "json")
MAX_INTERACTION_FIGURES = 8


def analyze(design_dir: str | Path, responses: str | Path, out: str | Path, models: bool = True) -> dict:
    """Run the whole analysis; returns the summary written to ``summary.json``."""
    # checked before any work: the report folder replaces what is there, so it must never be a file or an input
    check_output_folder(out, "--out", [design_dir, responses])
    design = load_design(design_dir)
    imported = import_responses(responses, design)
    if imported.data.empty or (~imported.data["practice"]).sum() == 0:
        raise AnalysisError(f"{responses}: no participant is left after the exclusions "
                            f"({imported.summary()['excluded_by_reason']}); nothing to analyse. "
                            f"{exclusion_examples(imported.exclusions)}")
    _check_between_levels(design, imported, responses)
    simulated = simulated_export(responses)   # the tool's own simulated file: every output says so
    out = Path(out)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent if out.parent.exists() else None))
    try:
        context = _write_all(design, imported, staging, models, simulated)
        replace_directory(staging, out)
    except AnalysisError as exc:   # e.g. too few participants left: name the file and who was excluded
        shutil.rmtree(staging, ignore_errors=True)
        raise AnalysisError(f"{responses}: {exc}. {excluded_participants(imported)}".rstrip(". ")) from None
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return context["summary"]


def _check_between_levels(design: DesignInfo, imported: ImportResult, responses) -> None:
    """A between factor needs two levels among the participants kept; say which exclusions removed the others."""
    kept = imported.data[~imported.data["practice"]]
    for name in design.between:
        left = sorted(set(kept[name]))
        if len(design.factor(name).levels) > 1 and len(left) < 2:
            excluded = excluded_participants(imported)
            found = (f"after the exclusions only {name} = {', '.join(left)} is left" if excluded else
                     f"the responses hold only {name} = {', '.join(left)}")
            raise AnalysisError(f"{responses}: {found}, so the between factor {name} cannot be analysed (it needs "
                                f"at least two levels). {excluded}".rstrip())


def excluded_participants(imported: ImportResult, limit: int = 3) -> str:
    """``Excluded: participant '1' (several between-subject groups: …), …`` — who is missing and why."""
    rows = imported.exclusions.dropna(subset=["row"])
    kept = set(imported.data["participant"])
    gone = rows[(rows["participant"] != "") & ~rows["participant"].isin(kept)].drop_duplicates("participant")
    if gone.empty:
        return ""
    first = gone[["participant", "reason", "detail"]].head(limit).itertuples(index=False)
    shown = "; ".join(f"participant {p!r} ({reason}: {detail})" for p, reason, detail in first)
    more = f"; and {len(gone) - limit} more (exclusions.csv lists them)" if len(gone) > limit else ""
    return f"Excluded: {shown}{more}"


def exclusion_examples(exclusions: pd.DataFrame) -> str:
    """One example row per exclusion reason, with its detail and column, for error messages."""
    rows = exclusions.dropna(subset=["row"])
    parts = []
    for reason, group in rows.groupby("reason", sort=False):
        first = group.iloc[0]
        named = first["column"] and first["column"] != "response" and repr(first["column"]) not in first["detail"]
        column = f" [column {first['column']!r}]" if named else ""
        parts.append(f"{reason}: e.g. row {first['row']}: {first['detail']}{column}")
    return ("; ".join(parts) + ".") if parts else ""


def _write_all(design: DesignInfo, imported: ImportResult, out: Path, models: bool, simulated: bool = False) -> dict:
    (out / "figures").mkdir(parents=True, exist_ok=True)
    imported.data.to_csv(out / "responses_tidy.csv", index=False, lineterminator="\n")
    imported.exclusions.to_csv(out / "exclusions.csv", index=False, lineterminator="\n")
    sections = []
    if design.dependent_measure in ("mean_rating", "percent_chosen"):
        sections.append(_anova_section(design, imported.data, out, simulated))
    elif design.dependent_measure == "votes":
        sections.append(votes_section(design, imported.data, out, simulated))
    else:
        sections.append(ranking_section(design, imported.data, out, simulated))
    sections[0]["note"] = f"{measure_note(design)} {sections[0]['note']}".strip()
    # no variance in the cell values: the models' Wald tests would divide 0 by 0 (the GEE's robust SE is 0)
    if models and not sections[0]["results"].get("not_computed"):
        section = _models_section(design, imported.data, out)
        if section:
            sections.append(section)
    # last: a check of the data (left/right preference), not part of the paper's analysis
    check = position_section(imported.data, design, out, simulated)
    if check:
        sections.append(check)
    summary = json_safe({"simulated": simulated, "import": imported.summary(), "design": _design_summary(design),
                         "sections": [{k: v for k, v in s.items() if k in ("title", "results")} for s in sections]})
    (out / "summary.json").write_text(json.dumps(summary, indent=2, ensure_ascii=False, default=_plain) + "\n")
    context = {"summary": summary, "sections": sections, "imported": imported, "design": design,
               # object first: the Int64 row column cannot hold the "" shown for column-level notes
               "exclusions": imported.exclusions.astype(object).fillna("").to_dict("records"),
               "versions": software_versions()}
    (out / "report.html").write_text(render_report(context, out), encoding="utf-8")
    return context


def _plain(value):
    if hasattr(value, "item"):
        return value.item()
    return str(value)


# -- sections -------------------------------------------------------------------------------------------

def _anova_section(design: DesignInfo, data: pd.DataFrame, out: Path, simulated: bool = False) -> dict:
    """The classic analysis: ANOVA of the cell values, Tukey post-hoc, paper-style tables (also anova.docx, APA
    style), one APA sentence per significant effect, figures. ``simulated``: the files carry the banner."""
    from analysis.anova import anova
    from analysis.docx_tables import write_docx
    from analysis.posthoc import tukey_all
    from analysis.tables import render

    from analysis import figures
    ai = anova_input(data, design)
    ai.data.to_csv(out / "cell_values.csv", index=False, lineterminator="\n")
    values = pd.to_numeric(ai.data[ai.dv], errors="coerce")
    if len(values) and values.notna().all() and values.nunique() == 1:
        return _anova_not_computed(design, data, ai, float(values.iloc[0]))
    table = anova(ai.data, ai.dv, "participant", ai.within, ai.between, alpha=design.alpha)
    table = _testable(table, design)
    abbreviations = {f.name: f.abbreviations for f in design.factors if f.abbreviations}
    if design.posthoc == "tukey":
        tukey_all(table, abbreviations=abbreviations, alpha=design.alpha, followup=design.posthoc_followup,
                  adjust=design.posthoc_adjust, means=design.posthoc_means)
    for fmt in TABLE_FORMATS:
        (out / f"anova.{fmt}").write_text(render(table, fmt, simulated=simulated), encoding="utf-8")
    (out / "anova_all.md").write_text(render(table, "md", all_rows=True, simulated=simulated), encoding="utf-8")
    (out / "anova_gg.md").write_text(render(table, "md", correction="gg", simulated=simulated), encoding="utf-8")
    write_docx(table, out / "anova.docx", simulated=simulated)
    figs = []
    if any(f.maps_to == "body" for f in design.factors) and any(f.maps_to == "motion" for f in design.factors) \
            and design.response_type == "likert":
        figs.append(("Figure 4 style: mean rating per BODY × MOTION", figures.figure4(ai.data, design,
                                                                                      out / "figures" / "figure4")))
    if design.response_type == "afc":
        figs.append((f"Figure 9 style: % of trials each {design.alternatives.name} was chosen",
                     figures.figure9(ai.data, design, out / "figures" / "figure9")))
    if not figs:   # no paper figure fits this design: show the cell means all the same
        figs.append((f"Mean {ai.dv} per {' × '.join(ai.within + ai.between)} (± SE)",
                     figures.cell_means_plot(ai.data, ai.dv, ai.within, ai.between, design,
                                             out / "figures" / "cell_means")))
    for effect in table.significant()[:MAX_INTERACTION_FIGURES]:
        factors = list(table.effects.loc[effect, "factors"])
        stem = out / "figures" / ("effect_" + "_".join(factors))
        figs.append((f"{' × '.join(factors)} (significant)",
                     figures.interaction_plot(ai.data, ai.dv, factors, design, stem)))
    significant = table.significant()
    results = {"dv": ai.dv, "within": ai.within, "between": ai.between, "significant": significant,
               "effects": json.loads(table.to_json()), "apa": apa_report(table),
               "posthoc": {e: table.posthoc[e].summary if not table.posthoc[e].untestable
                           else f"not tested: {table.posthoc[e].untestable}" for e in table.posthoc},
               "posthoc_method": {e: table.posthoc[e].method for e in table.posthoc}}
    short = short_cells(ai, design)
    if short:
        results["cells_with_fewer_answers"] = short
    (out / "anova_summary.json").write_text(json.dumps(results, indent=2, ensure_ascii=False) + "\n")
    kind = "Mixed" if ai.between else "Repeated-measures"
    corrected = ("<details><summary>Sphericity: the same table with Greenhouse–Geisser corrected degrees of "
                 "freedom and p (Mauchly's W, ε and Huynh–Feldt in anova.json)</summary>"
                 f"{render(table, 'html', correction='gg')}</details>\n")
    note = _anova_note(design) + (f" {short_cells_note(short)}" if short else "")
    return {"title": f"{kind} ANOVA of {ai.dv} (the paper's analysis)", "html": render(table, "html") + corrected,
            "note": note, "figures": figs, "results": results,
            "files": [f"anova.{f}" for f in TABLE_FORMATS] + ["anova.docx", "anova_all.md", "anova_gg.md",
                                                              "cell_values.csv"]}


def apa_report(table, correction: str = "none") -> dict[str, str]:
    """The APA sentence of each significant effect (plain text, as in the tables' APA list), for the JSON."""
    from analysis.tables import table_context
    return {r["name"]: r["apa"] for s in table_context(table, correction=correction)["sections"] for r in s["rows"]
            if r["apa"]}


def planned_answers(design: DesignInfo, keys: list[str]) -> pd.DataFrame | None:
    """Answers the design plans per participant × cell: the test clips a participant sees in the cell ×
    repetitions — every arrangement of a condition, or one when arrangements are counterbalanced between
    participants (conditions.csv lists each arrangement as a stimulus of its own).

    ``keys`` are the cell's factors (between and within); conditions.csv is grouped by those of them it
    has (a between factor it lacks does not change which stimuli a participant sees). Column ``planned``;
    None when conditions.csv names none of the factors but some are asked for.
    """
    tests = design.test_conditions
    one_arrangement = ((design.protocol.get("alternatives") or {}).get("counterbalance") == "between"
                       and "condition_id" in tests.columns)
    present = [k for k in keys if k in tests.columns]
    if keys and not present:
        return None

    def seen(rows: pd.DataFrame) -> int:
        return rows["condition_id"].nunique() if one_arrangement else len(rows)

    if not present:
        return pd.DataFrame({"planned": [seen(tests) * design.repetitions]})
    groups = tests.astype({k: str for k in present}).groupby(present, observed=True)
    frame = groups["condition_id"].nunique() if one_arrangement else groups.size()
    return (frame * design.repetitions).rename("planned").reset_index()


def short_cells(ai, design: DesignInfo, limit: int = 5) -> dict | None:
    """Participant × cell values that rest on fewer answers than the design plans (a missing repetition is
    otherwise averaged away silently: the mean of 1 answer sits beside means of 2). None when there are none.

    Returns ``count`` (values short), ``cells`` (participant × cell values in all) and ``examples`` (up to
    ``limit``: participant, cell, answers ``n`` and ``planned``).
    """
    keys = [*ai.between, *[f for f in ai.within if f in design.within]]
    if "n" not in ai.data:
        return None
    values = ai.data.drop_duplicates(["participant", *keys])[["participant", *keys, "n"]]
    planned = planned_answers(design, keys)
    if planned is None:
        return None
    on = [k for k in keys if k in planned.columns]
    merged = (values.astype({k: str for k in on}).merge(planned, on=on, how="left") if on
              else values.assign(planned=int(planned["planned"].iloc[0])))
    short = merged[merged["planned"].notna() & (merged["n"] < merged["planned"])]
    if short.empty:
        return None
    examples = [{"participant": str(r["participant"]), "cell": "/".join(str(r[k]) for k in keys),
                 "n": int(r["n"]), "planned": int(r["planned"])} for _, r in short.head(limit).iterrows()]
    return {"count": int(len(short)), "cells": int(len(merged)), "examples": examples}


def short_cells_note(short: dict) -> str:
    """The report's sentence on participant × cell values with fewer answers than planned."""
    shown = "; ".join(f"participant {e['participant']}, {e['cell']} ({e['n']} of {e['planned']})"
                      for e in short["examples"])
    more = f"; and {short['count'] - len(short['examples'])} more" if short["count"] > len(short["examples"]) else ""
    values = "value rests" if short["count"] == 1 else "values rest"
    return (f"{short['count']} of {short['cells']} participant × cell {values} on fewer answers than the design "
            f"plans and {'is' if short['count'] == 1 else 'are'} the mean of the answers there are: {shown}{more} "
            f"(cell_values.csv, column n).")


def _anova_not_computed(design: DesignInfo, data: pd.DataFrame, ai, value: float) -> dict:
    """The ANOVA section when the cell values have no variance at all (e.g. every participant always chose
    the left clip, so each METHOD level got 50 % in every cell): the report is still written — the
    position-bias check and the other sections say what happened — and the section says why there is no
    ANOVA."""
    import html

    reason = (f"every value of {ai.dv} in cell_values.csv is {value:g} (every participant, every cell), so there "
              f"is no variance to analyse")
    tests = data[~data["practice"].astype(bool)]
    if design.response_type == "afc" and "position" in tests and tests["position"].notna().all() and len(tests):
        per_person = tests.groupby("participant")["position"].nunique()
        if (per_person == 1).all():
            from analysis.position_bias import position_names
            names = position_names(design)
            chosen = tests.groupby("participant")["position"].first().astype(int).value_counts().sort_index()
            where = ", ".join(f"{names[p - 1] if 0 < p <= len(names) else p} by {n} participant"
                              f"{'s' if n != 1 else ''}" for p, n in chosen.items())
            alt = design.alternatives.name
            reason += (f": every participant chose the same screen position on every test trial ({where}). "
                       f"The design shows each {alt} level at each position equally often, so these choices "
                       f"carry no information about {alt} (see the position-bias check)")
    reason = (f"{reason}. The additional models (mixed, ordinal, GEE) are left out for the same reason: their "
              f"tests would divide a zero effect by a zero standard error.")
    results = {"dv": ai.dv, "within": ai.within, "between": ai.between, "significant": None,
               "not_computed": reason}
    return {"title": f"ANOVA of {ai.dv} (the paper's analysis): not computed",
            "html": f"<p><strong>The ANOVA of {ai.dv} cannot be computed:</strong> {html.escape(reason)}</p>\n",
            "note": _anova_note(design), "figures": [], "results": results, "files": ["cell_values.csv"]}


def measure_note(design: DesignInfo) -> str:
    """Which dependent measure the report uses and where it came from (the default when design.json sets none)."""
    from analysis.io_design import MEASURES_OF_TYPE
    measure = design.dependent_measure
    if design.dependent_measure_source != "default":
        return f"Dependent measure: {measure}, as set by design.json field '{design.dependent_measure_source}'."
    others = [m for m in MEASURES_OF_TYPE.get(design.response_type, ()) if m != measure]
    also = (f" ({' or '.join(others)} would also fit this design: set the protocol's analysis.dependent_measure "
            f"and run `shapemotion design` again to use it)") if others else ""
    return (f"Dependent measure: {measure}, the default for response type {design.response_type}, as design.json sets "
            f"no dependent_measure{also}.")


def _testable(table, design: DesignInfo):
    """Drop effects a constant-sum measure cannot test (those without the alternatives factor)."""
    from analysis.power import informative_effects
    keep = informative_effects(design, list(table.effects.index))
    return dataclasses.replace(table, effects=table.effects.loc[keep])


def _anova_note(design: DesignInfo) -> str:
    common = (" Tukey HSD over all pairs of the cell means of each significant effect (its own error term). "
              "Uncorrected p as in the paper. Observed power is a function of p and adds nothing to it; it is "
              "shown only because the paper reports it.")
    if design.response_type == "likert":
        return "Ratings averaged over repetitions per participant and cell." + common
    return (f"Percentage of trials each {design.alternatives.name} level was chosen per participant and cell. "
            f"The levels' percentages sum to 100 in every cell, so only effects that involve "
            f"{design.alternatives.name} are testable and shown." + common)


def _models_section(design: DesignInfo, data: pd.DataFrame, out: Path) -> dict | None:
    from analysis.models import additional_models
    table = additional_models(data, design)
    if table.empty:
        return None
    table.to_csv(out / "additional_models.csv", index=False, lineterminator="\n")
    html = "".join(_frame_html(_model_table(g), f"{model} — {g['note'].iloc[0]}", index=False)
                   for model, g in table.groupby("model", sort=False))
    return {"title": "Additional analyses (modern alternatives, not in the paper)", "html": html, "figures": [],
            "note": "Mixed models of the single answers with a random intercept per participant, as R fits them "
                    "(the caption of each table names the R call it reproduces): F tests with Satterthwaite df "
                    "for the linear mixed model, Wald χ² per term for the others. These complement the classic "
                    "ANOVA above; they are not the paper's analysis.",
            "results": {"terms": table.to_dict("records")}, "files": ["additional_models.csv"]}


def _model_table(rows: pd.DataFrame) -> pd.DataFrame:
    """One model's rows as shown: F(df, df_den) for F tests, χ²(df) otherwise; p in APA style."""
    from analysis.tables import format_p_apa
    shown = pd.DataFrame({"term": rows["term"]})
    if rows["F"].notna().any():
        shown["F"], shown["df"], shown["df_den"] = rows["F"].round(3), rows["df"], rows["df_den"].round(2)
    elif rows["chi2"].notna().any():
        shown["χ²"], shown["df"] = rows["chi2"].round(3), rows["df"]
    if rows["p"].notna().any():
        shown["p"] = rows["p"].map(format_p_apa)
    return shown


def _frame_html(frame: pd.DataFrame, caption: str, index: bool = True) -> str:
    import html as html_lib
    body = frame.to_html(index=index, border=0, classes="result", na_rep="")
    return f"<figure class=\"table\"><figcaption>{html_lib.escape(caption)}</figcaption>{body}</figure>\n"


# -- report ---------------------------------------------------------------------------------------------

def _design_summary(design: DesignInfo) -> dict:
    return {"name": design.protocol.get("name", ""), "participants_planned": design.participants,
            "seed": design.seed, "response": design.response_type, "labels": design.labels, "k": design.k,
            "dependent_measure": design.dependent_measure,
            "dependent_measure_source": design.dependent_measure_source,
            "dependent_measure_note": measure_note(design), "alpha": design.alpha,
            "factors": [{"name": f.name, "role": f.role, "levels": f.levels} for f in design.factors]}


def software_versions() -> dict:
    """Versions of the libraries the numbers depend on (no timestamps: reports stay reproducible)."""
    import matplotlib
    import numpy
    import scipy
    import statsmodels
    return {"shapemotion": "0.1.0", "python": platform.python_version(), "numpy": numpy.__version__,
            "scipy": scipy.__version__, "pandas": pd.__version__, "statsmodels": statsmodels.__version__,
            "matplotlib": matplotlib.__version__}


def render_report(context: dict, out: Path) -> str:
    """The self-contained ``report.html`` (figures inlined as base64 PNG)."""
    import jinja2
    from markupsafe import Markup

    from analysis.tables import TEMPLATE_DIR
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATE_DIR)), autoescape=True,
                             trim_blocks=True, lstrip_blocks=True, undefined=jinja2.StrictUndefined)
    sections = []
    for s in context["sections"]:
        figs = [{"caption": caption, "png": _data_uri(next(p for p in paths if p.suffix == ".png")),
                 "files": [str(p.relative_to(out)) for p in paths]} for caption, paths in s["figures"]]
        sections.append({**s, "figures": figs, "html": Markup(s["html"])})
    return env.get_template("report.html.j2").render(
        summary=context["summary"], sections=sections, exclusions=context["exclusions"],
        versions=context["versions"], design=context["summary"]["design"], imported=context["summary"]["import"],
        banner=SIMULATED_BANNER if context["summary"]["simulated"] else "")


def _data_uri(path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def demo_report(design_dir: str | Path, out: str | Path, participants: int | None = None, seed: int = 1,
                fmt: str = "qualtrics") -> Path:
    """For ``shapemotion demo``: simulate responses from the protocol's default model, then analyse them.

    Writes ``<out>/responses.csv`` (in ``fmt``) and the report folder ``<out>/report``; returns the
    path of ``report.html``.
    """
    from analysis.io_files import atomic_write_text
    from analysis.io_writers import export_text
    from analysis.model_spec import load_model
    from analysis.simulate import simulate_responses

    design = load_design(design_dir)
    out = Path(out)
    n = participants or design.participants or 16
    sim = simulate_responses(design, load_model(None, design), n, seed)
    responses = out / ("responses.json" if fmt == "jspsych-json" else "responses.csv")
    atomic_write_text(responses, export_text(sim, design, fmt.replace("-json", ""), responses.suffix, seed=seed))
    analyze(design_dir, responses, out / "report")
    return out / "report" / "report.html"
