"""Analysis CLI commands. ``register(subparsers)`` adds each of them (see stimuli.cli).

    shapemotion anova DATA.csv --dv COL --subject COL --within A B … --between D …
        [--posthoc tukey] [--abbrev LEVEL=ABBR …] [--alpha .05] [--correction none|gg|hf]
        [--format md|tex|csv|html|json] [--out FILE] [--json FILE] [--all]
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from analysis.errors import AnalysisError

TABLE_FORMATS = ("md", "tex", "csv", "html", "json")


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
                   help="Tukey HSD for every effect shown (Statistica convention)")
    p.add_argument("--abbrev", nargs="+", default=[], metavar="LEVEL=ABBR",
                   help="level abbreviations for post-hoc labels: LEVEL=ABBR or FACTOR:LEVEL=ABBR")
    p.add_argument("--alpha", type=float, default=0.05, help="significance level and power alpha (default 0.05)")
    p.add_argument("--correction", choices=["none", "gg", "hf"], default="none",
                   help="sphericity correction of the p shown (default none, as the paper)")
    p.add_argument("--format", choices=TABLE_FORMATS, default="md", help="table format (default md)")
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


def read_csv(path: str):
    """Read a CSV for analysis; the index becomes the CSV line number so that errors point at lines."""
    import csv

    import pandas as pd

    if not Path(path).is_file():
        raise AnalysisError(f"{path}: no such file")
    try:
        with open(path, newline="", encoding="utf-8-sig") as handle:
            header = next(csv.reader(handle), [])
        data = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, csv.Error) as exc:
        raise AnalysisError(f"{path}: not a readable CSV file ({str(exc).strip()})") from None
    # pandas renames a repeated header to "rating.1" and the analysis would silently use the first one
    names = list(header)
    repeated = sorted({h for h in names if names.count(h) > 1})
    if repeated:
        where = "; ".join(f"{h!r} in columns {', '.join(str(i + 1) for i, n in enumerate(names) if n == h)}"
                          for h in repeated)
        raise AnalysisError(f"{path}: line 1: the header names a column more than once ({where}); "
                            f"each column needs its own name")
    data.index = pd.RangeIndex(2, len(data) + 2)  # line 1 is the header
    return data


PRACTICE_TRUE = ("true", "t", "yes", "y", "1", "1.0")
PRACTICE_FALSE = ("false", "f", "no", "n", "0", "0.0", "")


def practice_flags(column, path: str):
    """The ``practice`` column as booleans: true/false, yes/no, y/n, t/f, 1/0, 1.0/0.0 in any case; a blank
    cell is a test trial. Any other value is refused, naming its CSV line: a typo must not turn a practice
    trial into a test trial."""
    import pandas as pd

    text = column.astype(object).where(column.notna(), "").astype(str).str.strip().str.lower()
    known = text.isin(PRACTICE_TRUE + PRACTICE_FALSE)
    if not known.all():
        bad = [(i, column[i]) for i in column.index[~known]]
        shown = ", ".join(f"CSV line {i}: {v!r}" for i, v in bad[:5]) + (
            f" … ({len(bad)} rows in all)" if len(bad) > 5 else "")
        raise AnalysisError(f"{path}: column 'practice' must be true or false (true/false, yes/no, y/n, t/f, "
                            f"1/0, or blank for a test trial), got {shown}")
    return pd.Series(text.isin(PRACTICE_TRUE).to_numpy(), index=column.index)


def check_no_practice_rows(data, path: str, used: list[str]) -> None:
    """Refuse practice trials in the data (e.g. ``analyze``'s ``responses_tidy.csv``): their levels (BODY =
    Prac) would enter the ANOVA as one more level of a factor. A ``practice`` column the user analyses as
    a factor or measure is theirs to use."""
    if "practice" not in data or "practice" in used:
        return
    import pandas as pd

    # the cells as written: pandas would read "nan", "NA" or "null" as a blank (test) cell
    raw = pd.read_csv(path, usecols=["practice"], dtype=str, keep_default_na=False)["practice"]
    raw.index = data.index
    flags = practice_flags(raw, path)
    if not flags.any():
        return
    lines = [str(i) for i in data.index[flags]]
    shown = ", ".join(lines[:5]) + (f" … ({len(lines)} rows in all)" if len(lines) > 5 else "")
    raise AnalysisError(f"{path}: {len(lines)} of {len(data)} rows are practice trials (column 'practice' is true "
                        f"on CSV lines {shown}); the ANOVA would count their levels as conditions. Analyse the "
                        f"report's cell_values.csv (test trials only, one value per participant and cell) or "
                        f"drop the practice rows first")


def _write(path: str, text: str) -> None:
    target = Path(path)
    if target.parent and not target.parent.exists():
        target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(f".{target.name}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, target)


def run_anova(args: argparse.Namespace) -> int:
    from analysis.anova import anova
    from analysis.io_files import check_output_file
    from analysis.posthoc import tukey_all
    from analysis.tables import render

    for option, path in (("--out", args.out), ("--json", args.json)):
        if path:
            check_output_file(path, option, [args.data])
    abbreviations = parse_abbreviations(args.abbrev)
    data = read_csv(args.data)
    check_no_practice_rows(data, args.data, [args.dv, args.subject, *args.within, *args.between])
    try:
        table = anova(data, dv=args.dv, subject=args.subject, within=args.within, between=args.between,
                      alpha=args.alpha)
    except AnalysisError as exc:
        raise AnalysisError(f"{args.data}: {str(exc).replace('at row index', 'on CSV line')}") from None
    check_abbreviations(abbreviations, data, [*args.within, *args.between])
    if args.posthoc == "tukey":
        effects = list(table.effects.index) if args.all else table.significant(correction=args.correction)
        tukey_all(table, effects=effects, abbreviations=abbreviations)
    text = render(table, args.format, all_rows=args.all, correction=args.correction)
    if args.out:
        _write(args.out, text)
    else:
        sys.stdout.write(text)
    if args.json:
        _write(args.json, table.to_json() + "\n")
    return 0
