"""The one exception type the stimuli package raises for user errors.

The CLI catches it and prints its message (exit code 2); anything else is a bug and keeps its traceback.
"""


class StimuliError(Exception):
    """A user error: bad protocol, bad option, bad input file. The message names the file/field and what was expected."""
