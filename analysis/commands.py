"""Analysis CLI commands. ``register(subparsers)`` adds each of them (see stimuli.cli).

    shapemotion anova DATA.csv --dv COL --subject COL --within A B … --between D …
        [--posthoc tukey] [--followup univariate|multivariate|statistica] [--adjust tukey|holm|bonferroni|none]
        [--means emmeans|observed] [--abbrev LEVEL=ABBR …] [--alpha .05] [--correction none|gg|hf]
        [--format md|tex|csv|html|json|docx] [--out FILE] [--json FILE] [--all]
        [--style paper|apa] [--corrected-power spss|uncorrected]
"""

from __future__ import annotations

import argparse
import sys

from analysis.errors import AnalysisError

# analysis.posthoc's FOLLOWUPS, ADJUSTMENTS and MEANS_TYPES, spelled out: importing it here would load the
# ANOVA stack for every shapemotion command (tests/test_posthoc.py checks they agree)
POSTHOC_FOLLOWUPS = ("univariate", "multivariate", "statistica")
POSTHOC_ADJUSTMENTS = ("tukey", "holm", "bonferroni", "none")
POSTHOC_MEANS = ("emmeans", "observed")
TABLE_FORMATS = ("md", "tex", "csv", "html", "json", "docx")


def register(subparsers) -> None:
    """Add the analysis commands to the ``shapemotion`` sub-parsers."""
    _register_anova(subparsers)


# ---------------------------------------------------------------------------------------------- anova
def _register_anova(subparsers) -> None:
    p = subparsers.add_parser(
        "anova",
        help="split-plot (mixed) ANOVA with sphericity corrections, effect sizes, power and Tukey post-hoc",
        description=(
            "Type III split-plot ANOVA of a long-format CSV (one row per subject x within cell; several rows "
            "of a cell are averaged) for any number of within and between factors, in the paper's table "
            "layout. Prints the significant effects unless --all."
        ),
    )
    p.add_argument("data", help="long-format CSV file")
    p.add_argument("--dv", required=True, metavar="COL", help="dependent variable column (numeric)")
    p.add_argument("--subject", required=True, metavar="COL", help="subject / participant id column")
    p.add_argument("--within", nargs="+", default=[], metavar="FACTOR", help="within-subject factor columns")
    p.add_argument("--between", nargs="+", default=[], metavar="FACTOR", help="between-subjects factor columns")
    p.add_argument("--posthoc", choices=["tukey", "none"], default="none",
                   help="pairwise comparisons of every effect shown (Tukey-adjusted unless --adjust); any of "
                        "--followup/--adjust/--means also turns them on")
    p.add_argument("--followup", choices=POSTHOC_FOLLOWUPS, default=None,
                   help="how pairs are tested: univariate (default; emmeans on afex's aov: pooled error and "
                        "Satterthwaite df for pairs across between groups), multivariate (emmeans on afex's mlm) "
                        "or statistica (each effect's own error term, as the paper's tables; pairs across "
                        "between groups not protected)")
    p.add_argument("--adjust", choices=POSTHOC_ADJUSTMENTS, default=None,
                   help="p adjustment over each effect's pairs: tukey (default), holm, bonferroni, none")
    p.add_argument("--means", choices=POSTHOC_MEANS, default=None,
                   help="marginal means: emmeans (equal weights over groups; default) or observed (n-weighted; "
                        "the default with --followup statistica)")
    p.add_argument("--abbrev", nargs="+", default=[], metavar="LEVEL=ABBR",
                   help="level abbreviations for post-hoc labels: LEVEL=ABBR or FACTOR:LEVEL=ABBR")
    p.add_argument("--alpha", type=float, default=0.05, help="significance level and power alpha (default 0.05)")
    p.add_argument("--correction", choices=["none", "gg", "hf"], default="none",
                   help="sphericity correction of the p shown (default none, as the paper)")
    p.add_argument("--format", choices=TABLE_FORMATS, default="md",
                   help="table format (default md); docx (Word, APA style) needs --out")
    p.add_argument("--style", choices=["paper", "apa"], default="paper",
                   help="p as the paper prints it (<0.001, default) or as APA does (< .001, no leading zero)")
    p.add_argument("--corrected-power", choices=["spss", "uncorrected"], default="spss",
                   help="with --correction gg|hf: nc and observed power from the corrected dof, as SPSS (default), "
                        "or uncorrected")
    p.add_argument("--out", metavar="FILE", help="write the table to FILE instead of standard output")
    p.add_argument("--json", metavar="FILE", help="also write every effect as JSON (DESIGN.md schema)")
    p.add_argument("--all", action="store_true", help="show every effect and the error strata, not only significant ones")
    p.set_defaults(func=run_anova)


def parse_abbreviations(items: list[str]) -> dict:
    """``["Walk=W", "GAIT:Jog=J"]`` → ``{"Walk": "W", "GAIT": {"Jog": "J"}}``."""
    out: dict = {}
    for item in items:
        key, sep, abbr = item.partition("=")
        if not sep or not key or not abbr:
            raise AnalysisError(f"--abbrev {item!r}: expected LEVEL=ABBR or FACTOR:LEVEL=ABBR")
        factor, colon, level = key.partition(":")
        if colon:
            out.setdefault(factor, {})[level] = abbr
        else:
            out[key] = abbr
    return out


def check_abbreviations(abbreviations: dict, data, factors: list[str]) -> None:
    """Every ``--abbrev`` must name a factor of the analysis and one of its levels (else it would do nothing)."""
    levels = {f: {str(v) for v in data[f].dropna().unique()} for f in factors if f in data}
    for key, value in abbreviations.items():
        if isinstance(value, dict):
            if key not in levels:
                raise AnalysisError(f"--abbrev {key}:…: {key!r} is not a factor of the analysis "
                                    f"(factors: {', '.join(factors)})")
            for level in value:
                if level not in levels[key]:
                    raise AnalysisError(f"--abbrev {key}:{level}={value[level]}: {level!r} is not a level of {key} "
                                        f"(levels: {', '.join(sorted(levels[key]))})")
        elif not any(key in found for found in levels.values()):
            known = "; ".join(f"{f}: {', '.join(sorted(v))}" for f, v in levels.items())
            raise AnalysisError(f"--abbrev {key}={value}: {key!r} is not a level of any factor ({known})")


def run_anova(args: argparse.Namespace) -> int:
    from analysis.anova import anova
    from analysis.anova_data import read_anova_csv
    from analysis.io_files import atomic_write_text, check_output_file
    from analysis.posthoc import tukey_all
    from analysis.tables import render

    if args.format == "docx" and not args.out:
        raise AnalysisError("--format docx writes a Word file: give --out FILE.docx")
    for option, path in (("--out", args.out), ("--json", args.json)):
        if path:
            check_output_file(path, option, [args.data])
    abbreviations = parse_abbreviations(args.abbrev)
    data = read_anova_csv(args.data, used=[args.dv, args.subject, *args.within, *args.between])
    try:
        table = anova(data, dv=args.dv, subject=args.subject, within=args.within, between=args.between,
                      alpha=args.alpha)
    except AnalysisError as exc:
        raise AnalysisError(f"{args.data}: {exc}") from None
    check_abbreviations(abbreviations, data, [*args.within, *args.between])
    if args.posthoc == "tukey" or any(v is not None for v in (args.followup, args.adjust, args.means)):
        effects = list(table.effects.index) if args.all else table.significant(correction=args.correction)
        tukey_all(table, effects=effects, abbreviations=abbreviations, followup=args.followup or "univariate",
                  adjust=args.adjust or "tukey", means=args.means)
    options = dict(all_rows=args.all, correction=args.correction, corrected_power=args.corrected_power)
    if args.format == "docx":   # always APA style: the Word table is the one pasted into a paper
        from analysis.docx_tables import write_docx
        write_docx(table, args.out, **options)
    elif args.out:
        atomic_write_text(args.out, render(table, args.format, style=args.style, **options))
    else:
        sys.stdout.write(render(table, args.format, style=args.style, **options))
    if args.json:
        atomic_write_text(args.json, table.to_json() + "\n")
    return 0
