"""Fitting Anny phenotype parameters to a target sex, height and BMI (optionally waist, hip, chest).

The search space is kept small and plausible. Gender is fixed by the sex (Anny: 0 male, 1
female), age by an adult age (30 years by default, through Anny's calibrated age mapping) and
proportions at 0.5. Two free parameters carry the targets:

- ``height`` (Anny's height phenotype) sets the stature;
- ``build`` s moves weight and muscle together along a path of real MakeHuman shapes:
  s = 0 thin (weight 0, muscle 0) → s = 1 average (0.5, 0.5) → s = 2 heavy (1, 0), extended
  linearly to s = 2.4 (weight 1.2, muscle −0.2: a mild extrapolation that women need to reach
  BMI 40). Along the path BMI rises monotonically, so every BMI has one body.

Only when the protocol gives a waist, hip or chest girth are two more parameters freed: a muscle
shift (−0.3…0.3 around the path, at equal BMI more muscle means a slimmer waist) and proportions
(0…1), both pulled gently towards their defaults.

The solver is a bounded Levenberg–Marquardt on residuals scaled so that height (0.2 mm) and BMI
(0.1) dominate; Jacobians are forward differences evaluated as one batch through Anny. The
start point comes from a coarse grid. A target outside the reachable box ends at the nearest
body on its boundary, which the caller reports (never returned silently as a fit).
"""

from __future__ import annotations

import dataclasses
import functools
import time

import numpy as np

from stimuli.bodies import backend

FITTER_VERSION = "1"
HEIGHT_TOLERANCE_M = 0.01
BMI_TOLERANCE = 0.5
ADULT_AGE_YEARS = 30.0
BUILD_MAX = 2.4
# (lower, upper) of each free parameter: height phenotype, build, muscle shift, proportions.
BOUNDS = {"height": (0.0, 1.0), "build": (0.0, BUILD_MAX), "muscle_shift": (-0.3, 0.3), "proportions": (0.0, 1.0)}
# Residual scales (one unit each). Height weighs most, so an out-of-reach BMI is approached at the
# target height (the nearest body is "right height, closest BMI"); BMI outweighs the girths, which
# only use the freedom left; the extra parameters are pulled towards their defaults.
SCALE = {"height_m": 0.0002, "bmi": 0.1, "waist_m": 0.05, "hip_m": 0.05, "chest_m": 0.05}
REGULARISER = {"muscle_shift": 0.3, "proportions": 0.5}
# When a target is out of reach, a second pass weighs BMI 100 times less, so that the nearest body
# keeps the height and only then gets as close to the BMI as the model allows.
NEAREST_SCALE = {**SCALE, "bmi": 10.0}


@dataclasses.dataclass(frozen=True)
class Targets:
    """What a body must measure: sex, height (m), BMI, optional girths (m), adult age (years)."""

    sex: str
    height_m: float
    bmi: float
    waist_m: float | None = None
    hip_m: float | None = None
    chest_m: float | None = None
    age_years: float = ADULT_AGE_YEARS

    @property
    def girths(self) -> dict[str, float]:
        return {k: v for k, v in (("waist_m", self.waist_m), ("hip_m", self.hip_m), ("chest_m", self.chest_m))
                if v is not None}

    def key(self) -> dict[str, object]:
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class FitResult:
    """Fitted phenotype, what it measures, and whether it meets the tolerances."""

    phenotype: dict[str, float]
    parameters: dict[str, float]
    measured: dict[str, float]
    reachable: bool
    iterations: int
    evaluations: int
    seconds: float


def build_path(s):
    """(weight, muscle) along the build path for s in [0, BUILD_MAX].

    >>> build_path(np.array([0.0, 1.0, 2.0, 2.4]))
    (array([0. , 0.5, 1. , 1.2]), array([ 0. ,  0.5,  0. , -0.2]))
    """
    s = np.asarray(s, dtype=float)
    weight = np.where(s <= 1.0, 0.5 * s, 0.5 + 0.5 * (s - 1.0))
    muscle = np.where(s <= 1.0, 0.5 * s, 0.5 - 0.5 * (s - 1.0))
    return weight, muscle


@functools.lru_cache(maxsize=16)
def anny_age(years: float) -> float:
    """Anny's age phenotype for an age in years (Anny's WHO-calibrated morphological age mapping)."""
    import torch
    from anny.paths import get_anny_root_dir
    from anny.shape_distribution import MorphologicalAgeMapping

    state = torch.load(get_anny_root_dir() / "data" / "shape_calibration" / "boys.pth", weights_only=True,
                       map_location="cpu")["morphological_age_mapping"]
    mapping = MorphologicalAgeMapping()
    mapping.load_state_dict(state)
    return float(mapping.morphological_to_anny_age(torch.tensor([float(years)], dtype=torch.float64))[0])


def phenotypes(targets: Targets, x: np.ndarray, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """Anny phenotype kwargs (batched) for free-parameter rows ``x`` (B, len(names))."""
    x = np.atleast_2d(x)
    col = {n: x[:, i] for i, n in enumerate(names)}
    weight, muscle = build_path(col["build"])
    muscle = muscle + col.get("muscle_shift", 0.0)
    n = x.shape[0]
    return {
        "gender": np.full(n, 1.0 if targets.sex == "F" else 0.0),
        "age": np.full(n, anny_age(targets.age_years)),
        "muscle": muscle,
        "weight": weight,
        "height": col["height"],
        "proportions": col.get("proportions", np.full(n, 0.5)),
    }


def measure_batch(targets: Targets, x: np.ndarray, names) -> tuple[list[dict[str, float]], dict]:
    """Height, BMI (and requested girths) of each candidate row, plus the raw Anny output."""
    from stimuli.bodies.body import candidate_girths

    out = backend.evaluate(phenotypes(targets, x, names))
    rows = []
    for i in range(x.shape[0]):
        row = {"height_m": float(out["height"][i]),
               "bmi": float(out["volume"][i] * backend.ANNY_DENSITY / out["height"][i] ** 2),
               "waist_m": float(out["waist"][i])}
        if targets.hip_m is not None or targets.chest_m is not None:
            row.update(candidate_girths(out, i))
        rows.append(row)
    return rows, out


def residuals(targets: Targets, measured: dict[str, float], x_row: np.ndarray, names, scale=SCALE) -> np.ndarray:
    """Scaled residual vector of one candidate."""
    wanted = {"height_m": targets.height_m, "bmi": targets.bmi, **targets.girths}
    r = [(measured[k] - v) / scale[k] for k, v in wanted.items()]
    defaults = {"muscle_shift": 0.0, "proportions": 0.5}
    r += [(x_row[names.index(k)] - defaults[k]) / REGULARISER[k] for k in names if k in REGULARISER]
    return np.array(r)


def within_tolerance(targets: Targets, measured: dict[str, float]) -> bool:
    return (abs(measured["height_m"] - targets.height_m) <= HEIGHT_TOLERANCE_M
            and abs(measured["bmi"] - targets.bmi) <= BMI_TOLERANCE)


@functools.lru_cache(maxsize=8)
def _start_grid(sex: str, age_years: float):
    """Heights and BMIs on a coarse (height, build) grid, once per sex and age (kept on disk too)."""
    hs, ss = np.array([0.15, 0.55]), np.linspace(0.0, BUILD_MAX, 9)
    path = (backend.project_cache_root() / "bodies"
            / f"start_grid_{backend.anny_version()}_{FITTER_VERSION}_{backend.code_digest()}_{sex}_{age_years:g}.npz")
    try:
        with np.load(path) as data:
            return hs, ss, data["height"], data["bmi"]
    except (OSError, ValueError, KeyError):
        pass  # absent or damaged: compute it
    grid = np.array([[h, s] for h in hs for s in ss])
    rows, _ = measure_batch(Targets(sex, 1.7, 22.0, age_years=age_years), grid, ("height", "build"))
    height = np.array([r["height_m"] for r in rows]).reshape(2, -1)
    bmi = np.array([r["bmi"] for r in rows]).reshape(2, -1)
    import io

    from stimuli.fileio import atomic_write_bytes

    buffer = io.BytesIO()
    np.savez(buffer, height=height, bmi=bmi)
    atomic_write_bytes(path, buffer.getvalue())
    return hs, ss, height, bmi


def start_point(targets: Targets) -> tuple[float, float]:
    """(height, build) whose grid interpolation meets the targets (clipped to the box)."""
    hs, ss, height, bmi = _start_grid(targets.sex, targets.age_years)
    frac = (targets.height_m - height[0]) / (height[1] - height[0])  # per build value
    h_star = hs[0] + frac * (hs[1] - hs[0])
    bmi_at = bmi[0] + frac * (bmi[1] - bmi[0])
    s0 = float(np.interp(targets.bmi, np.maximum.accumulate(bmi_at), ss))
    h0 = float(np.interp(s0, ss, h_star))
    return float(np.clip(h0, *BOUNDS["height"])), float(np.clip(s0, *BOUNDS["build"]))


def fit(targets: Targets, max_iterations: int = 40) -> FitResult:
    """Bounded Levenberg–Marquardt from the grid start; see the module docstring."""
    start_time = time.perf_counter()
    names = ("height", "build") + (("muscle_shift", "proportions") if targets.girths else ())
    lower = np.array([BOUNDS[n][0] for n in names])
    upper = np.array([BOUNDS[n][1] for n in names])
    x = np.array(list(start_point(targets)) + ([0.0, 0.5] if targets.girths else []))
    x, measured, iteration, evaluations = solve(
        lambda point: _linearise(targets, point, names, upper), x, lower, upper,
        lambda m: _converged(targets, m, names), max_iterations)
    if not within_tolerance(targets, measured):
        x, measured, more, extra = solve(
            lambda point: _linearise(targets, point, names, upper, scale=NEAREST_SCALE), x, lower, upper,
            lambda m: False, max_iterations)
        iteration, evaluations = iteration + more, evaluations + extra
    params = dict(zip(names, map(float, x)))
    pheno = {k: float(v[0]) for k, v in phenotypes(targets, x, names).items()}
    return FitResult(phenotype=pheno, parameters=params, measured=measured,
                     reachable=within_tolerance(targets, measured), iterations=iteration,
                     evaluations=evaluations * (len(names) + 1), seconds=time.perf_counter() - start_time)


def solve(linearise, x, lower, upper, converged, max_iterations: int = 40):
    """Bounded Levenberg–Marquardt. ``linearise(x) -> (residuals, jacobian, measured)``;
    ``converged(measured)`` stops early. Returns (x, measured, iterations, evaluations of linearise)."""
    lam = 1e-3
    r0, jac, measured = linearise(x)
    evaluations, iteration = 1, 0
    while iteration < max_iterations and not converged(measured):
        iteration += 1
        delta = _bounded_step(jac, r0, lam, x, lower, upper)
        if np.max(np.abs(delta)) < 1e-7:
            break
        x_new = np.clip(x + delta, lower, upper)
        r_new, jac_new, measured_new = linearise(x_new)
        evaluations += 1
        if r_new @ r_new < r0 @ r0:
            gain = 1.0 - (r_new @ r_new) / (r0 @ r0)
            x, r0, jac, measured, lam = x_new, r_new, jac_new, measured_new, lam / 3.0
            if gain < 1e-6:  # stalled at the best point (a bound): nothing left to gain
                break
        else:
            lam *= 4.0
            if lam > 1e8:
                break
    return x, measured, iteration, evaluations


def _linearise(targets: Targets, x, names, upper, step: float = 1e-4, scale=SCALE):
    """Residuals, forward-difference Jacobian and measurements at ``x``: one Anny batch of len(x)+1."""
    probes = np.array([x] + [x + _fd_step(x, k, step, upper) for k in range(len(x))])
    rows, _ = measure_batch(targets, probes, names)
    r0 = residuals(targets, rows[0], x, names, scale)
    jac = np.stack([(residuals(targets, rows[k + 1], probes[k + 1], names, scale) - r0) / (probes[k + 1, k] - x[k])
                    for k in range(len(x))], axis=1)
    return r0, jac, rows[0]


def _fd_step(x, k, step, upper):
    e = np.zeros_like(x)
    e[k] = step if x[k] + step <= upper[k] else -step
    return e


def _converged(targets: Targets, measured, names) -> bool:
    """Tight on height and BMI; with girths the LM runs until its step vanishes."""
    tight = abs(measured["height_m"] - targets.height_m) < 5e-4 and abs(measured["bmi"] - targets.bmi) < 0.01
    return tight and len(names) == 2


def _bounded_step(jac, r, lam, x, lower, upper):
    """LM step; parameters pinned at a bound that the step pushes outwards are held fixed."""
    free = np.ones(len(x), dtype=bool)
    for _ in range(len(x)):
        delta = np.zeros(len(x))
        j = jac[:, free]
        a = j.T @ j
        a = a + lam * np.diag(np.diag(a) + 1e-12)
        delta[free] = np.linalg.solve(a, -j.T @ r)
        pinned = ((x <= lower) & (delta < 0)) | ((x >= upper) & (delta > 0))
        if not (pinned & free).any():
            return delta
        free &= ~pinned
        if not free.any():
            return np.zeros(len(x))
    return delta
