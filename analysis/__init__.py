"""shapemotion.analysis: responses → tidy data → ANOVA / post-hoc → tables, figures, report.

This package never imports ``stimuli``: the two halves meet only through files.
"""

from analysis.errors import AnalysisError

__all__ = ["AnalysisError"]
