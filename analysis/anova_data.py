"""Long-format data → the subjects × cells matrix of cell means that the ANOVA engine analyses; and
:func:`read_anova_csv`, the CSV reader of ``shapemotion anova``.

All checks of the input live here, each raising ``AnalysisError`` with a message that names the column,
subject, cell or rows at fault. Uses integer codes and ``np.bincount`` rather than pandas group-bys so
that one Experiment-1-sized analysis stays in the low milliseconds.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from pandas._libs.parsers import STR_NA_VALUES  # the cells pd.read_csv reads as missing by default

from analysis.anova_core import Design
from analysis.errors import AnalysisError
from analysis.practice import practice_flags

# the index name of a frame read by read_anova_csv: its labels are CSV lines, and messages say so
CSV_LINE = "CSV line"


@dataclass(frozen=True)
class PreparedData:
    design: Design
    Y: np.ndarray  # subjects × cells, mean of the rows of each subject × cell
    counts: np.ndarray  # subjects × cells, number of rows averaged
    subjects: tuple[str, ...]  # subject labels, in row order of Y


def _rows(idx, limit: int = 5) -> str:
    idx = list(idx)
    shown = ", ".join(str(i) for i in idx[:limit])
    return shown + (f" … ({len(idx)} rows)" if len(idx) > limit else "")


def _at(index: pd.Index, idx) -> str:
    """Where rows are: "on CSV line 3, 7" for a frame from :func:`read_anova_csv`, else "at row index 3, 7"."""
    return f"{'on CSV line' if index.name == CSV_LINE else 'at row index'} {_rows(idx)}"


def read_anova_csv(path: str | Path, used: list[str] | tuple[str, ...] = ()) -> pd.DataFrame:
    """Read a long-format CSV for :func:`analysis.anova.anova`, in one pass over the file.

    The index is the CSV line (line 1 is the header, index name ``"CSV line"``), so that the engine's
    messages name lines. Refused: a header naming a column twice (pandas would rename the second
    ``rating.1`` and the analysis would silently use the first), and practice rows (see
    :func:`check_no_practice_rows`) unless ``practice`` is one of the ``used`` columns.
    """
    path = Path(path)
    if not path.is_file():
        raise AnalysisError(f"{path}: no such file")
    try:
        with open(path, newline="", encoding="utf-8-sig") as handle:
            text = handle.read()
        header = next(csv.reader(io.StringIO(text, newline="")), [])
        _check_header(header, path)
        # the practice cells as written: pandas would read "nan", "NA" or "null" as a blank (test) cell
        raw_practice = "practice" in header and "practice" not in used
        options = dict(keep_default_na=False, dtype={"practice": str},
                       na_values={c: list(STR_NA_VALUES) for c in header if c != "practice"}) if raw_practice else {}
        data = pd.read_csv(io.StringIO(text, newline=""), **options)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, csv.Error) as exc:
        raise AnalysisError(f"{path}: not a readable CSV file ({str(exc).strip()})") from None
    data.index = pd.RangeIndex(2, len(data) + 2, name=CSV_LINE)
    if raw_practice:
        check_no_practice_rows(data, path)
    return data


def _check_header(header: list[str], path: Path) -> None:
    repeated = sorted({h for h in header if header.count(h) > 1})
    if repeated:
        where = "; ".join(f"{h!r} in columns {', '.join(str(i + 1) for i, n in enumerate(header) if n == h)}"
                          for h in repeated)
        raise AnalysisError(f"{path}: line 1: the header names a column more than once ({where}); "
                            f"each column needs its own name")


def check_no_practice_rows(data: pd.DataFrame, path: str | Path) -> None:
    """Refuse practice trials (``practice`` true, :func:`analysis.practice.practice_flags`) in a table indexed
    by CSV line (e.g. ``analyze``'s ``responses_tidy.csv``): their levels (BODY = Prac) would enter the
    ANOVA as one more level of a factor."""
    flags = practice_flags(data["practice"], path)
    if not flags.any():
        return
    lines = [str(i) for i in data.index[flags]]
    shown = ", ".join(lines[:5]) + (f" … ({len(lines)} rows in all)" if len(lines) > 5 else "")
    raise AnalysisError(f"{path}: {len(lines)} of {len(data)} rows are practice trials (column 'practice' is true "
                        f"on CSV lines {shown}); the ANOVA would count their levels as conditions. Analyse the "
                        f"report's cell_values.csv (test trials only, one value per participant and cell) or "
                        f"drop the practice rows first")


def _sort_key(values: np.ndarray) -> np.ndarray:
    try:
        return np.argsort(values.astype(float), kind="stable")
    except (TypeError, ValueError):
        return np.argsort(values.astype(str), kind="stable")


def factor_codes(col: pd.Series) -> tuple[np.ndarray, tuple[str, ...]]:
    """Integer codes and level labels of a factor column. Level order: the categories' order for a
    pandas Categorical, otherwise sorted (numerically when all levels are numbers)."""
    if isinstance(col.dtype, pd.CategoricalDtype):
        cats = col.cat.categories
        codes = col.cat.codes.to_numpy()
        used = np.unique(codes)
        remap = np.full(len(cats), -1)
        remap[used] = np.arange(len(used))
        return remap[codes], tuple(str(c) for c in cats[used])
    codes, uniques = pd.factorize(col, sort=False)
    uniques = np.asarray(uniques, dtype=object)
    order = _sort_key(uniques)
    rank = np.empty(len(order), dtype=int)
    rank[order] = np.arange(len(order))
    return rank[codes], tuple(str(u) for u in uniques[order])


def _rare_levels(index, codes: dict, levels: dict, within, scode: np.ndarray, subjects, limit: int = 3) -> str:
    """Within levels that fewer subjects have than the factor's other levels, with their rows: one odd
    level (a typo such as 'wlak') is why every subject then misses cells."""
    notes = []
    for f in within:
        have = [len(np.unique(scode[codes[f] == i])) for i in range(len(levels[f]))]
        for i, n_subjects in enumerate(have):
            if n_subjects <= max(have) / 2:   # clearly odd, not one subject short of a common level
                rows = index[codes[f] == i]
                who = ", ".join(repr(subjects[j]) for j in np.unique(scode[codes[f] == i])[:limit])
                notes.append(f"level {levels[f][i]!r} of {f} appears only {_at(index, rows)} "
                             f"(subject{'s' if n_subjects > 1 else ''} {who}{' …' if n_subjects > limit else ''})")
    shown = "; ".join(notes[:limit])
    return shown + (f"; and {len(notes) - limit} more such level(s)" if len(notes) > limit else "")


def prepare(
    data: pd.DataFrame,
    dv: str,
    subject: str,
    within: list[str] | tuple[str, ...] = (),
    between: list[str] | tuple[str, ...] = (),
) -> PreparedData:
    """Validate long-format data and reduce it to one mean per subject × within cell."""
    if not isinstance(data, pd.DataFrame):
        raise AnalysisError(f"expected a pandas DataFrame, got {type(data).__name__}")
    within, between = tuple(within or ()), tuple(between or ())
    factors = within + between
    if not factors:
        raise AnalysisError("no factors given: name at least one within (--within) or between (--between) factor")
    names = (dv, subject) + factors
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise AnalysisError(f"column(s) {', '.join(map(repr, dup))} named in more than one role (dv, subject, within, between)")
    missing = [n for n in names if n not in data.columns]
    if missing:
        raise AnalysisError(
            f"column(s) {', '.join(map(repr, missing))} not in the data; columns are: {', '.join(map(str, data.columns))}"
        )
    if len(data) == 0:
        raise AnalysisError("the data has no rows")
    for n in names:
        na = data[n].isna().to_numpy()
        if na.any():
            raise AnalysisError(
                f"column {n!r} has {int(na.sum())} missing value(s) (NaN/empty) {_at(data.index, data.index[na])}; "
                "drop or fill them before the ANOVA"
            )
    raw = data[dv]
    if raw.dtype == bool:
        raw = raw.astype(float)
    y = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=float)
    bad = ~np.isfinite(y)
    if bad.any():
        vals = ", ".join(repr(v) for v in pd.unique(raw[bad])[:3])
        raise AnalysisError(
            f"dependent variable {dv!r} must be numeric: {int(bad.sum())} value(s) are not finite numbers "
            f"(e.g. {vals}) {_at(data.index, data.index[bad])}"
        )
    if np.ptp(y) == 0:
        raise AnalysisError(f"dependent variable {dv!r} is constant (every value is {y[0]:g}): there is no variance to analyse")

    codes, levels = {}, {}
    for f in factors:
        codes[f], levels[f] = factor_codes(data[f])
        if len(levels[f]) < 2:
            raise AnalysisError(f"factor {f!r} has only one level ({levels[f][0]!r}); a factor needs at least two levels")
    scode, subjects = factor_codes(data[subject])
    n = len(subjects)

    # between: each subject in exactly one group
    bshape = tuple(len(levels[f]) for f in between)
    if between:
        bcode = np.ravel_multi_index(tuple(codes[f] for f in between), bshape)
        lo = np.full(n, np.iinfo(np.int64).max)
        hi = np.full(n, -1)
        np.minimum.at(lo, scode, bcode)
        np.maximum.at(hi, scode, bcode)
        two = np.flatnonzero(lo != hi)
        if len(two):
            s = two[0]

            def lab(c):
                return ", ".join(f"{f}={levels[f][i]}" for f, i in zip(between, np.unravel_index(c, bshape)))

            raise AnalysisError(
                f"subject {subjects[s]!r} appears in two between-subjects groups ({lab(lo[s])} and {lab(hi[s])})"
                + (f"; {len(two)} subjects are affected" if len(two) > 1 else "")
                + "; a between factor must be constant within a subject"
            )
        groups = np.stack(np.unravel_index(lo, bshape), axis=1).astype(int)
    else:
        groups = np.zeros((n, 0), dtype=int)

    # within: cell means and counts
    wshape = tuple(len(levels[f]) for f in within)
    K = int(np.prod(wshape)) if within else 1
    wcode = np.ravel_multi_index(tuple(codes[f] for f in within), wshape) if within else np.zeros(len(y), dtype=int)
    flat = scode * K + wcode
    counts = np.bincount(flat, minlength=n * K).reshape(n, K)
    sums = np.bincount(flat, weights=y, minlength=n * K).reshape(n, K)
    if (counts == 0).any():
        subj_missing = np.flatnonzero((counts == 0).any(axis=1))
        s = subj_missing[0]
        cells = np.flatnonzero(counts[s] == 0)

        def cell(c):
            return ", ".join(f"{f}={levels[f][i]}" for f, i in zip(within, np.unravel_index(c, wshape)))

        more = f" and {len(cells) - 1} more cell(s)" if len(cells) > 1 else ""
        others = f"; {len(subj_missing)} subjects have missing cells" if len(subj_missing) > 1 else ""
        rare = _rare_levels(data.index, codes, levels, within, scode, subjects)
        raise AnalysisError(
            f"subject {subjects[s]!r} has no data for cell {cell(cells[0])}{more}{others}"
            + (f"; {rare}" if rare else "")
            + "; a repeated-measures ANOVA needs every subject in every within cell"
        )
    design = Design(
        within={f: levels[f] for f in within},
        between={f: levels[f] for f in between},
        groups=groups,
    )
    return PreparedData(design=design, Y=sums / counts, counts=counts, subjects=subjects)
