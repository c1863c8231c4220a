"""shapemotion: the pipeline's steps as a Python API (``import shapemotion as sm``) and the
execution layer shared by the heavy steps. The ``stimuli`` and ``analysis`` packages stay the
implementation; this package only presents them."""
