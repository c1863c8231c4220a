"""shapemotion: the pipeline's steps as a Python API (``import shapemotion as sm``) and the
execution layer shared by the heavy steps. The ``stimuli`` and ``analysis`` packages stay the
implementation; this package only presents them.

The steps carry the CLI's names (``sm.init``, ``sm.validate``, ``sm.design``, ``sm.render``,
``sm.simulate``, ``sm.analyze``, …: :mod:`shapemotion.api`). They are loaded on first use, so that
``stimuli`` and ``analysis`` can import ``shapemotion.execution`` without importing themselves.

>>> import shapemotion as sm
>>> sm.load_protocol(sm.bundled_protocol("exp2_com_vs_average")).response.type
'afc'
"""

from __future__ import annotations

# The steps, in the order of the data flow (as `shapemotion --help` lists the commands).
__all__ = [
    "init", "schema", "bundled_protocol", "load_protocol", "validate", "Validation", "design",
    "fit_body", "render", "survey",
    "simulate", "power", "import_responses", "analyze", "anova",
]


def __getattr__(name: str):
    """PEP 562: ``sm.design`` and the other steps come from :mod:`shapemotion.api` on first use."""
    if name in __all__:
        from shapemotion import api

        return getattr(api, name)
    raise AttributeError(f"module 'shapemotion' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
