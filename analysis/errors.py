"""The one exception type the analysis package raises for user errors (bad data, bad options)."""


class AnalysisError(Exception):
    """A user error in the analysis half. The message names the file, column or row and what was expected."""
