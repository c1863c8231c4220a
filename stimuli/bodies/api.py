"""Public entry points: one body from targets, the body of a protocol actor, all bodies of a protocol."""

from __future__ import annotations

import dataclasses
import math
import time

from stimuli.bodies import backend, cache
from stimuli.bodies.body import Body, FitReport, build_body
from stimuli.bodies.fit import BMI_TOLERANCE, FITTER_VERSION, HEIGHT_TOLERANCE_M, Targets, fit, phenotypes
from stimuli.errors import StimuliError

_SEXES = {"F": "F", "FEMALE": "F", "W": "F", "M": "M", "MALE": "M"}


class BodyFitError(StimuliError):
    """A target the body model cannot reach within tolerance; ``nearest`` is the closest body it can."""

    def __init__(self, message: str, nearest: Body | None = None):
        super().__init__(message)
        self.nearest = nearest


def normalise_sex(sex) -> str:
    """'F'/'M' from common spellings; StimuliError naming the value otherwise."""
    key = str(sex).strip().upper() if sex is not None else ""
    if key not in _SEXES:
        raise StimuliError(f"sex must be 'F' or 'M' (got {sex!r}): the body model needs it to choose the phenotype")
    return _SEXES[key]


def _check_number(name: str, value, low: float, high: float) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise StimuliError(f"{name} must be a number (got {value!r})") from None
    if not math.isfinite(value) or not low < value < high:
        raise StimuliError(f"{name} = {value} is not a human value (expected between {low} and {high})")
    return value


def _check_girth(name: str, value) -> float:
    """A girth within the protocol's human range: the fitter treats girths as soft targets, so one
    far outside it would be missed without an error. (Height and BMI keep wide sanity limits here:
    a target out of the model's reach is reported by BodyFitError with the nearest body.)"""
    from stimuli.protocol import GIRTH_RANGES_M

    low, high = GIRTH_RANGES_M[name]
    value = _check_number(name, value, -math.inf, math.inf)
    if not low <= value <= high:
        raise StimuliError(f"{name} = {value} m is not a human girth (expected {low}–{high} m)")
    return value


def girth_errors(body: Body) -> dict[str, float]:
    """Measured minus target girth (m) for each girth target of ``body``."""
    measured = body.anthropometry.as_dict()
    return {k: float(measured[k] - v) for k, v in body.targets.items()
            if k in ("waist_m", "hip_m", "chest_m") and v is not None}


BACKENDS = ("anny", "smplx")


def fit_body(sex, height_m, bmi, *, waist_m=None, hip_m=None, chest_m=None, age_years: float = 30.0,
             body_id: str | None = None, on_unreachable: str = "raise", use_cache: bool = True,
             backend_name: str = "anny", smplx_dir=None) -> Body:
    """A body of the given sex, height (m) and BMI (kg/m²), optionally waist/hip/chest girths (m).

    Raises BodyFitError (with ``.nearest``) when the target is out of reach of the body model
    (|height error| > 1 cm or |BMI error| > 0.5) unless ``on_unreachable="nearest"``, which returns
    the nearest body with ``fit.reachable`` False. ``backend_name="smplx"`` with ``smplx_dir`` (a
    folder of SMPL-X model files) fits SMPL-X betas instead (height and BMI only, not cached).

    Examples
    --------
    >>> body = fit_body("F", 1.60, 28.1)                        # doctest: +SKIP
    >>> round(body.anthropometry.height_m, 2), round(body.anthropometry.bmi, 1)  # doctest: +SKIP
    (1.6, 28.1)
    """
    if on_unreachable not in ("raise", "nearest"):
        raise ValueError("on_unreachable must be 'raise' or 'nearest'")
    if backend_name not in BACKENDS:
        raise StimuliError(f"unknown body backend {backend_name!r}; known backends: {', '.join(BACKENDS)}")
    if backend_name == "smplx":
        if smplx_dir is None:
            raise StimuliError("the smplx backend needs the folder of your SMPL-X model files (--smplx-dir)")
        from stimuli.bodies.smplx_backend import fit_smplx_body

        return fit_smplx_body(normalise_sex(sex), _check_number("height_m", height_m, 0.0, 10.0),
                              _check_number("bmi", bmi, 0.0, 1000.0), smplx_dir, body_id, on_unreachable)
    targets = Targets(
        sex=normalise_sex(sex), height_m=_check_number("height_m", height_m, 0.0, 10.0),
        bmi=_check_number("bmi", bmi, 0.0, 1000.0),
        waist_m=None if waist_m is None else _check_girth("waist_m", waist_m),
        hip_m=None if hip_m is None else _check_girth("hip_m", hip_m),
        chest_m=None if chest_m is None else _check_girth("chest_m", chest_m),
        age_years=_check_number("age_years", age_years, 17.9, 90.1),
    )
    body_id = body_id or f"{targets.sex}_h{targets.height_m * 100:.0f}_b{targets.bmi:.1f}"
    key = cache.cache_key(targets.key(), FITTER_VERSION)
    body = cache.load(key, body_id) if use_cache else None
    if body is None:
        body = _fit_new(targets, body_id)
        if use_cache:
            cache.save(body, key)
    elif not body.fit.reachable:   # the cached message names the body it was first fitted as
        body.fit = dataclasses.replace(body.fit, message=_unreachable_message(
            body_id, targets, targets.height_m + body.fit.height_error_m, targets.bmi + body.fit.bmi_error))
    if not body.fit.reachable and on_unreachable == "raise":
        raise BodyFitError(body.fit.message, nearest=body)
    return body


def _fit_new(targets: Targets, body_id: str) -> Body:
    start = time.perf_counter()
    result = fit(targets)
    names = tuple(result.parameters)
    import numpy as np

    x = np.array([result.parameters[n] for n in names])
    out = backend.evaluate(phenotypes(targets, x, names))
    height_err = result.measured["height_m"] - targets.height_m
    bmi_err = result.measured["bmi"] - targets.bmi
    message = "" if result.reachable else _unreachable_message(body_id, targets, result.measured["height_m"],
                                                               result.measured["bmi"])
    report = FitReport(reachable=result.reachable, height_error_m=height_err, bmi_error=bmi_err,
                       seconds=time.perf_counter() - start, cached=False, iterations=result.iterations,
                       message=message)
    target_dict = {"height_m": targets.height_m, "bmi": targets.bmi, "waist_m": targets.waist_m,
                   "hip_m": targets.hip_m, "chest_m": targets.chest_m}
    return build_body(body_id, targets.sex, target_dict, result.phenotype, out, 0, report)


def _unreachable_message(body_id: str, targets: Targets, height_m: float, bmi: float) -> str:
    """What BodyFitError says about a target out of reach, whose nearest body measures ``height_m``, ``bmi``."""
    return (f"body {body_id}: {targets.sex} height {targets.height_m:.3f} m, BMI {targets.bmi:.1f} is out of reach of "
            f"the Anny body model (tolerance ±{HEIGHT_TOLERANCE_M * 100:.0f} cm, ±{BMI_TOLERANCE} BMI); the nearest "
            f"body has height {height_m:.3f} m and BMI {bmi:.1f}")


def body_for_actor(actor, **kwargs) -> Body:
    """The body of a ``stimuli.protocol.Actor`` (its sex, height, BMI and any girths); id = actor.id."""
    return fit_body(actor.sex, actor.height_m, actor.bmi, waist_m=getattr(actor, "waist_m", None),
                    hip_m=getattr(actor, "hip_m", None), chest_m=getattr(actor, "chest_m", None),
                    body_id=actor.id, **kwargs)


def fit_protocol_bodies(protocol, allow_nearest: bool = False, progress: bool = False, include_practice: bool = True,
                        **kwargs) -> list[Body]:
    """Every actor's body, in protocol order (cached after the first fit; ``kwargs`` go to
    :func:`fit_body`, e.g. ``use_cache``). Unreachable targets are collected and reported together
    (StimuliError) unless ``allow_nearest``, which keeps the nearest bodies (``fit.reachable`` False)."""
    from tqdm import tqdm

    actors = [a for a in protocol.actors if include_practice or not a.practice_only]
    bodies, problems = [], []
    for actor in tqdm(actors, desc="bodies", unit="body", disable=not progress):
        try:
            bodies.append(body_for_actor(actor, **kwargs))
        except BodyFitError as exc:
            problems.append(str(exc))
            bodies.append(exc.nearest)
    if problems and not allow_nearest:
        raise StimuliError(f"protocol {protocol.name}: {len(problems)} actor(s) cannot be built: "
                           + "; ".join(problems) + " (use --allow-nearest to write the nearest bodies anyway)")
    return bodies
