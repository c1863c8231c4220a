"""shapemotion.stimuli: protocol → design → bodies → motions → physics → render → survey export."""

from stimuli.errors import StimuliError

__all__ = ["StimuliError"]
__version__ = "0.1.0"
