"""Optional SMPL-X backend: bodies from shape coefficients (betas) of a user's SMPL-X model files.

SMPL-X model files are not redistributable, so none ship with shapemotion: point ``model_dir`` to a
folder holding ``SMPLX_FEMALE.npz`` and ``SMPLX_MALE.npz`` (the ``.npz`` files of the official
download, the format the ``smplx`` package reads: ``v_template`` (V, 3), ``f`` (F, 3), ``shapedirs``
(V, 3, B), ``J_regressor`` (J, V), ``weights`` (V, J), ``kintree_table`` (2, J)). They are read
with numpy alone. SMPL-X's canonical frame is already the project's (y up, faces +z, +x the body's
left); only the feet are lifted onto y = 0. Shape only: no pose correctives (plain linear-blend
skinning), the first two betas fitted to height and BMI (the rest 0), volume × 980 kg/m³ as for
Anny so that BMIs compare. Bodies of this backend are not cached (a fit takes milliseconds).
"""

from __future__ import annotations

import functools
import time
from pathlib import Path

import numpy as np

from stimuli.bodies.body import Body, FitReport, assemble_body, girth_edges
from stimuli.bodies.fit import BMI_TOLERANCE, HEIGHT_TOLERANCE_M, NEAREST_SCALE, SCALE, solve
from stimuli.bodies.measure import mesh_volume, slice_girth
from stimuli.bodies.segments import SMPLX, face_segments
from stimuli.errors import StimuliError

# The 55 SMPL-X joints in model order (body 22, jaw and eyes 3, hands 2 × 15).
_FINGERS = [f"{f}{k}" for f in ("index", "middle", "pinky", "ring", "thumb") for k in (1, 2, 3)]
JOINT_NAMES = [
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle", "right_ankle",
    "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "jaw", "left_eye_smplhf",
    "right_eye_smplhf", *[f"left_{f}" for f in _FINGERS], *[f"right_{f}" for f in _FINGERS],
]
FILES = {"F": "SMPLX_FEMALE.npz", "M": "SMPLX_MALE.npz"}
_KEYS = ("v_template", "f", "shapedirs", "J_regressor", "weights", "kintree_table")
BETA_BOUND = 5.0


@functools.lru_cache(maxsize=4)
def load_model(path: str) -> dict[str, np.ndarray]:
    """Arrays of one SMPL-X ``.npz`` model file (StimuliError naming the file and key when unusable)."""
    file = Path(path)
    if not file.is_file():
        raise StimuliError(f"SMPL-X model file {file} not found (expected {' and '.join(FILES.values())} "
                           f"in the folder given to the smplx backend)")
    try:
        with np.load(file, allow_pickle=False) as data:
            missing = [k for k in _KEYS if k not in data.files]
            if missing:
                raise StimuliError(f"{file}: not an SMPL-X model file, missing {', '.join(missing)}")
            model = {k: np.asarray(data[k]) for k in _KEYS}
    except (OSError, ValueError) as exc:
        raise StimuliError(f"{file}: cannot read it as an SMPL-X .npz model ({exc})") from None
    n_joints = model["weights"].shape[1]
    if n_joints != len(JOINT_NAMES) or model["J_regressor"].shape != (n_joints, len(model["v_template"])):
        raise StimuliError(f"{file}: expected {len(JOINT_NAMES)} joints with a (J, V) J_regressor, got weights "
                           f"{model['weights'].shape} and J_regressor {model['J_regressor'].shape}")
    parents = model["kintree_table"][0].astype(np.int64)
    parents[0] = -1  # stored as 2^32 − 1 in the official files
    model["parents"] = parents
    model["f"] = model["f"].astype(np.int64)
    return model


def shape(model: dict, betas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rest vertices and joints (SMPL-X frame) for betas (missing betas are 0)."""
    betas = np.asarray(betas, dtype=float)
    n = min(len(betas), model["shapedirs"].shape[2])
    vertices = model["v_template"] + model["shapedirs"][:, :, :n] @ betas[:n]
    return vertices, model["J_regressor"] @ vertices


def _measure(model: dict, betas: np.ndarray) -> dict[str, float]:
    vertices, _ = shape(model, betas)
    height = float(np.ptp(vertices[:, 1]))
    return {"height_m": height, "bmi": mesh_volume(vertices, model["f"]) * 980.0 / height**2}


def fit_smplx_body(sex: str, height_m: float, bmi: float, model_dir, body_id: str | None = None,
                   on_unreachable: str = "raise") -> Body:
    """An SMPL-X body whose betas[0:2] meet the height and BMI (see the module docstring)."""
    from stimuli.bodies.api import BodyFitError

    start = time.perf_counter()
    model = load_model(str(Path(model_dir) / FILES[sex]))
    wanted = {"height_m": height_m, "bmi": bmi}

    def linearise(x, scale=SCALE, step=1e-4):
        rows = [_measure(model, p) for p in [x] + [x + np.eye(2)[k] * step for k in range(2)]]
        res = [np.array([(r[k] - v) / scale[k] for k, v in wanted.items()]) for r in rows]
        return res[0], np.stack([(res[k + 1] - res[0]) / step for k in range(2)], axis=1), rows[0]

    def within(m):
        return abs(m["height_m"] - height_m) <= HEIGHT_TOLERANCE_M and abs(m["bmi"] - bmi) <= BMI_TOLERANCE

    bound = np.full(2, BETA_BOUND)
    x, measured, iterations, _ = solve(
        linearise, np.zeros(2), -bound, bound,
        lambda m: abs(m["height_m"] - height_m) < 5e-4 and abs(m["bmi"] - bmi) < 0.01)
    if not within(measured):  # nearest body: keep the height, then the closest BMI (as for Anny)
        x, measured, more, _ = solve(lambda p: linearise(p, NEAREST_SCALE), x, -bound, bound, lambda m: False)
        iterations += more
    reachable = within(measured)
    body_id = body_id or f"{sex}_h{height_m * 100:.0f}_b{bmi:.1f}_smplx"
    message = "" if reachable else (
        f"body {body_id}: {sex} height {height_m:.3f} m, BMI {bmi:.1f} is out of reach of the SMPL-X model "
        f"(betas within ±{BETA_BOUND:g}); the nearest body has height {measured['height_m']:.3f} m and BMI "
        f"{measured['bmi']:.1f}")
    report = FitReport(reachable=reachable, height_error_m=measured["height_m"] - height_m,
                       bmi_error=measured["bmi"] - bmi, seconds=time.perf_counter() - start, cached=False,
                       iterations=iterations, message=message)
    body = _assemble(model, x, sex, body_id, {"height_m": height_m, "bmi": bmi, "waist_m": None, "hip_m": None,
                                              "chest_m": None}, report)
    if not reachable and on_unreachable == "raise":
        raise BodyFitError(message, nearest=body)
    return body


def _assemble(model, betas, sex, body_id, targets, report) -> Body:
    vertices, joints = shape(model, betas)
    shift = -float(vertices[:, 1].min())  # SMPL-X is already y-up: only the feet go to y = 0
    vertices = vertices + [0.0, shift, 0.0]
    joints = joints + [0.0, shift, 0.0]
    weights = model["weights"]
    top = np.argsort(-weights, axis=1)[:, :4]
    face_seg = face_segments(model["f"], np.take_along_axis(weights, top, 1), top, JOINT_NAMES, SMPLX)
    trunk_edges, hip_edges = girth_edges(model["f"], face_seg)
    parts = {"face_seg": face_seg, "trunk_edges": trunk_edges, "hip_edges": hip_edges}
    names = list(JOINT_NAMES)
    waist = _natural_waist(vertices, trunk_edges, joints, names)
    rotations = np.tile(np.eye(3), (len(names), 1, 1))
    return assemble_body(body_id, sex, targets, {f"beta{i}": float(b) for i, b in enumerate(betas)}, vertices,
                         model["f"], names, model["parents"], joints, rotations, waist, parts, report, SMPLX,
                         skinner=functools.partial(_dense_lbs, weights))


def _natural_waist(vertices, trunk_edges, joints, names) -> float:
    """Narrowest trunk girth between the hip joints and the chest joint (SMPL-X has no waist loop)."""
    low = joints[names.index("left_hip"), 1]
    high = joints[names.index("spine3"), 1]
    girths = [slice_girth(vertices, trunk_edges, y) for y in np.linspace(low, high, 15)]
    girths = [g for g in girths if g > 0]
    return min(girths) if girths else float("nan")


def _dense_lbs(weights: np.ndarray, rest, transforms):
    """Linear-blend skinning with dense (V, J) weights: torch (1, V, 3) rest, (T, J, 4, 4) transforms."""
    import torch

    w = torch.as_tensor(weights, dtype=transforms.dtype)
    blended = torch.einsum("vj,tjab->tvab", w, transforms[:, :, :3, :])
    return torch.einsum("tvab,vb->tva", blended[..., :3], rest[0]) + blended[..., 3]
