"""The ``practice`` column, read the same way in every file the analysis reads.

``conditions.csv`` and ``trials.csv`` of a design (``load_design``, ``simulate``) and the long CSV given to
``shapemotion anova`` all mark practice trials in a ``practice`` column; one reader keeps them agreeing (a
``1.0`` is a practice trial everywhere) and refuses a value it cannot read rather than guessing.

>>> import pandas as pd
>>> practice_flags(pd.Series(["1", "0", "True", "no", "", "1.0"]), "trials.csv", line_offset=2).tolist()
[True, False, True, False, False, True]
>>> practice_flags(pd.Series(["yes", "maybe"]), "trials.csv", line_offset=2)   # doctest: +ELLIPSIS
Traceback (most recent call last):
analysis.errors.AnalysisError: trials.csv: column 'practice' must be true or false (...), got CSV line 3: 'maybe'
"""

from __future__ import annotations

import pandas as pd

from analysis.errors import AnalysisError

PRACTICE_TRUE = ("true", "t", "yes", "y", "1", "1.0")
PRACTICE_FALSE = ("false", "f", "no", "n", "0", "0.0", "")


def practice_flags(column: pd.Series, where, line_offset: int = 0) -> pd.Series:
    """The ``practice`` column as booleans (same index): true/false, yes/no, y/n, t/f, 1/0, 1.0/0.0 in any
    case; a blank cell is a test trial. Any other value is refused, naming ``where`` (the file) and the CSV
    line (index label + ``line_offset``: 2 for a frame indexed from 0 under a header line, 0 for one indexed
    by CSV line): a typo must not turn a practice trial into a test trial."""
    text = column.astype(object).where(column.notna(), "").astype(str).str.strip().str.lower()
    known = text.isin(PRACTICE_TRUE + PRACTICE_FALSE)
    if not known.all():
        bad = [(i + line_offset, column[i]) for i in column.index[~known]]
        shown = ", ".join(f"CSV line {i}: {v!r}" for i, v in bad[:5]) + (
            f" … ({len(bad)} rows in all)" if len(bad) > 5 else "")
        raise AnalysisError(f"{where}: column 'practice' must be true or false (true/false, yes/no, y/n, t/f, "
                            f"1/0, or blank for a test trial), got {shown}")
    return pd.Series(text.isin(PRACTICE_TRUE).to_numpy(), index=column.index, name=column.name)
