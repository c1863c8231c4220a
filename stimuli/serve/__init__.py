"""``shapemotion serve``: run the study from this tool alone, on a small server.

A Starlette app (:mod:`stimuli.serve.app`) on uvicorn serves the jsPsych page of a design or render
folder and its clips, assigns each new participant the least-filled design list
(:mod:`stimuli.serve.assign`), stores every answer as it is given in SQLite (:mod:`stimuli.serve.db`),
resumes a reloaded page at its next unanswered trial, hands Prolific participants back with the
completion code, and exports the answers in the format ``analyze`` reads (:mod:`stimuli.serve.export`).
See ``docs/readme_serve.md``.
"""

from stimuli.serve.study import Study, load_study

__all__ = ["Study", "load_study"]
