"""The pipeline's steps as Python functions, named as the CLI's commands (``import shapemotion as sm``).

Each function is a thin layer over the library code the command runs (``stimuli`` and ``analysis``),
takes paths or the objects a previous step returned, and raises ``StimuliError`` or
``AnalysisError`` with the command's message on bad input. The libraries are imported inside the
functions, so ``import shapemotion`` stays light and the execution layer (``shapemotion.execution``)
can be imported by ``stimuli`` and ``analysis`` without a cycle.

A whole study, from a notebook (the examples below run as doctests):

>>> import tempfile
>>> from pathlib import Path
>>> import shapemotion as sm
>>> work = Path(tempfile.mkdtemp())
>>> study = sm.init(work / "mystudy")[0]                       # mystudy/protocol.yaml
>>> sm.validate(study).protocol.name
'mystudy'
>>> design = sm.design(study, out=work / "design")
>>> responses = sm.simulate(work / "design", participants=8, seed=1, out=work / "responses.csv")
>>> summary = sm.analyze(work / "design", work / "responses.csv", work / "report", models=False)
>>> (work / "report" / "report.html").is_file()
True
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:   # for the signatures only: importing these at run time would load the libraries
    import pandas as pd

    from analysis.anova import AnovaTable
    from analysis.io_design import DesignInfo
    from analysis.responses import ImportResult
    from stimuli.bodies.body import Body
    from stimuli.design import Design
    from stimuli.protocol import Protocol
    from stimuli.render.pipeline import RenderReport
    from stimuli.survey import ExportResult

PathLike = str | Path


# -- design the study ---------------------------------------------------------------------------------

def init(folder: PathLike, source: PathLike | None = None, force: bool = False) -> list[Path]:
    """``shapemotion init``: a new study's folder — a commented protocol ``validate`` accepts as written
    (or a copy of ``source``: a bundled protocol's name or a file), its JSON Schema and ``captures/``.
    Returns the files written, the protocol first.

    >>> import tempfile
    >>> files = init(Path(tempfile.mkdtemp()) / "pilot", source="exp1_shape_motion")
    >>> [f.name for f in files]
    ['protocol.yaml', 'protocol.schema.json', 'README.md']
    """
    from stimuli.scaffold import init_study

    return init_study(folder, source, force)


def schema() -> dict:
    """``shapemotion schema``: the protocol's JSON Schema (draft-07), a description on every field.

    >>> schema()["properties"]["participants"]["description"]
    'number of participants; a multiple of the number of between groups'
    """
    from stimuli.protocol_schema import protocol_schema

    return protocol_schema()


def bundled_protocol(name: str) -> Path:
    """The file of a protocol bundled with shapemotion (``exp1_shape_motion``, ``exp2_com_vs_average``,
    ``exp1_own_captures``, ``thesis_pointlight``, ``thesis_mesh``, ``thesis_validation``).

    >>> bundled_protocol("exp1_shape_motion").name
    'exp1_shape_motion.yaml'
    """
    from stimuli.errors import StimuliError
    from stimuli.scaffold import BUNDLED_PROTOCOLS

    path = BUNDLED_PROTOCOLS / f"{name}.yaml"
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in BUNDLED_PROTOCOLS.glob("*.yaml")))
        raise StimuliError(f"no bundled protocol {name!r} (bundled: {known})")
    return path


def load_protocol(path: PathLike) -> Protocol:
    """Read and validate a protocol file (fields and the rules across them).

    >>> p = load_protocol(bundled_protocol("exp1_shape_motion"))
    >>> [f.name for f in p.factors], p.participants
    (['SEX', 'GAIT', 'BODY', 'MOTION'], 16)
    """
    from stimuli.protocol import load_protocol as load

    return load(path)


@dataclass
class Validation:
    """What ``validate`` found: the protocol, the design it makes, a line per actor capture it imported
    and looped, and the warnings and notes it would print."""

    protocol: Protocol
    design: Design
    captures: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def validate(path: PathLike) -> Validation:
    """``shapemotion validate``: everything ``load_protocol`` checks, plus the files the protocol names
    (every capture imported and looped) and the design it makes.

    >>> v = validate(bundled_protocol("exp1_shape_motion"))
    >>> len(v.design.stimuli), v.warnings[0][:46]
    (80, 'gaits.walk: 112 steps/min does not fill the 4 ')
    """
    from stimuli.design import build_design
    from stimuli.motion.captures import check_captures
    from stimuli.protocol import check_capture_files
    from stimuli.render.timing import cadence_warnings

    protocol = load_protocol(path)
    check_capture_files(protocol, path)
    made = build_design(protocol)
    return Validation(protocol, made, check_captures(protocol, path), cadence_warnings(protocol), list(made.notes))


def design(protocol: PathLike | Protocol, participants: int | None = None, seed: int | None = None,
           out: PathLike | None = None) -> Design:
    """``shapemotion design``: the stimuli and each participant's trial list; with ``out``, also
    ``conditions.csv``, ``trials.csv`` and ``design.json`` written there (what the analysis reads).

    >>> d = design(bundled_protocol("exp1_shape_motion"), participants=4, seed=7)
    >>> sum(t.participant == 1 and t.kind == "test" for t in d.trials)
    64
    """
    from stimuli.design import build_design, write_design
    from stimuli.fileio import check_output_dir

    if out is not None:
        check_output_dir(Path(out))
    made = build_design(_protocol(protocol), participants, seed)
    if out is not None:
        write_design(made, out)
    return made


# -- make the stimuli ---------------------------------------------------------------------------------

def fit_body(sex: str, height_m: float, bmi: float, **options) -> Body:
    """``shapemotion bodies``: an Anny body of the given sex, height (m) and BMI (kg/m²), fitted within
    1 cm and 0.5 kg/m² (cached). ``options``: ``waist_m``, ``hip_m``, ``chest_m``, ``age_years``,
    ``on_unreachable="nearest"`` … (:func:`stimuli.bodies.api.fit_body`). A few seconds when not cached.

    >>> body = fit_body("F", 1.60, 28.1)
    >>> round(body.anthropometry.height_m, 2), round(body.anthropometry.bmi, 1)
    (1.6, 28.1)
    """
    from stimuli.bodies.api import fit_body as fit

    return fit(sex, height_m, bmi, **options)


def render(protocol: PathLike, out: PathLike, *, quick: bool = False, only: str | None = None,
           limit: int | None = None, resolution: tuple[int, int] | None = None, fps: int | None = None,
           workers: int | None = None, progress: bool = False, **options) -> RenderReport:
    """``shapemotion render``: every clip of a protocol's design into ``out`` (``clips/``, ``posters/``,
    ``manifest.csv`` and the design files), resumable: clips whose inputs did not change are kept.
    ``quick``: small and fast, for a first look; ``only``/``limit`` choose clips. ``options``: see
    :func:`stimuli.render.pipeline.render_protocol` (``motions_dir``, ``scheduler`` …).

    >>> import tempfile
    >>> report = render(bundled_protocol("exp1_shape_motion"), Path(tempfile.mkdtemp()) / "out", quick=True,
    ...                 limit=1, workers=1, sheet=False)
    >>> len(report.rendered), report.manifest.name
    (1, 'manifest.csv')
    """
    from stimuli.render.pipeline import render_protocol

    return render_protocol(protocol, out, resolution=resolution, fps=fps, limit=limit, only=only, workers=workers,
                           quick=quick, progress=progress, **options)


# -- run the study ------------------------------------------------------------------------------------

def survey(folder: PathLike, format: str, out: PathLike, video_base_url: str | None = None) -> ExportResult:
    """``shapemotion survey``: the survey of a design or render folder as ``qsf``, ``qualtrics-txt``,
    ``jspsych`` (a folder to host) or ``psychopy``.

    >>> import tempfile
    >>> work = Path(tempfile.mkdtemp())
    >>> _ = design(bundled_protocol("exp1_shape_motion"), out=work / "design")
    >>> survey(work / "design", "psychopy", work / "psychopy").format
    'psychopy'
    """
    from stimuli.survey import export_survey

    return export_survey(folder, format, out, video_base_url=video_base_url)


# -- analyse the answers ------------------------------------------------------------------------------

def simulate(design_dir: PathLike, participants: int, seed: int, model: PathLike | None = None,
             out: PathLike | None = None, format: str = "long") -> pd.DataFrame:
    """``shapemotion simulate``: synthetic participants' answers to a design folder's trials, drawn from
    a generative model (``model``: a YAML file; default: the protocol's bundled model, else no effects).
    With ``out``, also written as a ``format`` export (``long``, ``qualtrics``, ``jspsych`` …).

    >>> import tempfile
    >>> work = Path(tempfile.mkdtemp())
    >>> _ = design(bundled_protocol("exp1_shape_motion"), out=work / "design")
    >>> answers = simulate(work / "design", participants=4, seed=1)
    >>> len(answers[~answers["practice"]]), int(answers["rating"].between(1, 5).all())
    (256, 1)
    """
    from analysis.io_files import atomic_write_text, check_output_file
    from analysis.io_writers import export_text
    from analysis.model_spec import load_model
    from analysis.simulate import simulate_responses

    design_info = _design_info(design_dir)
    if out is not None:
        out = check_output_file(out, "out", [Path(design_dir) / "design.json", model])
    answers = simulate_responses(design_info, load_model(model, design_info), participants, seed)
    if out is not None:
        atomic_write_text(out, export_text(answers, design_info, format, Path(out).suffix, seed=seed))
    return answers


def power(design_dir: PathLike, participants: int | list[int], sims: int = 1000, seed: int = 1,
          model: PathLike | None = None, alpha: float | None = None, correction: str = "none") -> pd.DataFrame:
    """``shapemotion power``: the share of ``sims`` simulated studies of N participants in which each
    effect is significant, with a 95 % Clopper-Pearson interval; one row per N × effect.

    >>> import tempfile
    >>> work = Path(tempfile.mkdtemp())
    >>> _ = design(bundled_protocol("exp1_shape_motion"), participants=32, out=work / "design")
    >>> table = power(work / "design", participants=[8, 16], sims=50)
    >>> list(table.columns[:5]), sorted(set(table["participants"]))
    (['participants', 'effect', 'rejections', 'sims', 'power'], [8, 16])
    """
    from analysis.model_spec import load_model
    from analysis.power import power_sweep

    design_info = _design_info(design_dir)
    counts = [participants] if isinstance(participants, int) else list(participants)
    table = power_sweep(design_info, load_model(model, design_info), counts, sims, seed, alpha,
                        correction=correction)
    return table.drop(columns="datasets_per_second")


def import_responses(path: PathLike, design_dir: PathLike) -> ImportResult:
    """``shapemotion responses`` / the first step of ``analyze``: a response export (Qualtrics,
    jsPsych, long CSV, or a folder of them) matched to the design's stimuli, with every excluded row
    and the reason (``.data``, ``.exclusions``, ``.summary()``).

    >>> import tempfile
    >>> work = Path(tempfile.mkdtemp())
    >>> _ = design(bundled_protocol("exp1_shape_motion"), out=work / "design")
    >>> _ = simulate(work / "design", participants=4, seed=1, out=work / "answers.csv", format="qualtrics")
    >>> imported = import_responses(work / "answers.csv", work / "design")
    >>> imported.format, imported.summary()["participants"]
    ('qualtrics', 4)
    """
    from analysis.responses import import_responses as read

    return read(path, _design_info(design_dir))


def analyze(design_dir: PathLike, responses: PathLike, out: PathLike, models: bool = True) -> dict:
    """``shapemotion analyze``: import the responses, run the protocol's analysis (ANOVA, post-hoc
    tests, and with ``models`` the mixed/ordinal models), write tables, figures, ``exclusions.csv`` and
    ``report.html`` into the folder ``out``; returns the summary (``summary.json``). See the module's
    example."""
    from analysis.report import analyze as run

    return run(design_dir, responses, out, models=models)


def anova(data: pd.DataFrame | PathLike, dv: str, subject: str, within: list[str] | tuple[str, ...] = (),
          between: list[str] | tuple[str, ...] = (), alpha: float = 0.05) -> AnovaTable:
    """``shapemotion anova``: a split-plot (mixed) ANOVA of long data (a DataFrame or CSV file; one row
    per subject × cell, repeated rows averaged) with sphericity corrections, effect sizes and power.

    >>> import pandas as pd
    >>> data = pd.DataFrame({"subject": [1, 1, 2, 2, 3, 3, 4, 4], "cond": ["a", "b"] * 4,
    ...                      "score": [1, 3, 2, 5, 1, 2, 3, 6]})
    >>> table = anova(data, dv="score", subject="subject", within=["cond"])
    >>> round(float(table.effect("cond")["F"]), 2), round(float(table.effect("cond")["p"]), 4)
    (22.09, 0.0182)
    """
    from analysis.anova import anova as fit

    if isinstance(data, (str, Path)):
        from analysis.anova_data import read_anova_csv

        data = read_anova_csv(data, used=[dv, subject, *within, *between])
    return fit(data, dv, subject, within, between, alpha)


# -- helpers --------------------------------------------------------------------------------------------

def _protocol(protocol: PathLike | Protocol) -> Protocol:
    return load_protocol(protocol) if isinstance(protocol, (str, Path)) else protocol


def _design_info(design_dir: PathLike) -> DesignInfo:
    from analysis.io_design import load_design

    return load_design(design_dir)
