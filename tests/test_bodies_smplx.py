"""The optional SMPL-X backend on tiny synthetic model files in the official .npz format (no real SMPL-X files)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from stimuli.bodies import BodyFitError, fit_body
from stimuli.bodies.smplx_backend import JOINT_NAMES, load_model
from stimuli.errors import StimuliError

PARENTS = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 15, 15, 15,
           20, 25, 26, 20, 28, 29, 20, 31, 32, 20, 34, 35, 20, 37, 38,
           21, 40, 41, 21, 43, 44, 21, 46, 47, 21, 49, 50, 21, 52, 53]
BODY_JOINTS = {
    "pelvis": (0, 0, 0), "left_hip": (0.08, -0.05, 0), "right_hip": (-0.08, -0.05, 0), "spine1": (0, 0.1, 0),
    "left_knee": (0.08, -0.45, 0), "right_knee": (-0.08, -0.45, 0), "spine2": (0, 0.25, 0),
    "left_ankle": (0.07, -0.8, 0), "right_ankle": (-0.07, -0.8, 0), "spine3": (0, 0.38, 0),
    "left_foot": (0.06, -0.86, 0.05), "right_foot": (-0.06, -0.86, 0.05), "neck": (0, 0.6, 0),
    "left_collar": (0.05, 0.52, 0), "right_collar": (-0.05, 0.52, 0), "head": (0, 0.72, 0),
    "left_shoulder": (0.14, 0.48, 0), "right_shoulder": (-0.14, 0.48, 0), "left_elbow": (0.17, 0.25, 0),
    "right_elbow": (-0.17, 0.25, 0), "left_wrist": (0.17, 0.05, 0), "right_wrist": (-0.17, 0.05, 0),
    "jaw": (0, 0.66, 0.05), "left_eye_smplhf": (0.03, 0.76, 0.06), "right_eye_smplhf": (-0.03, 0.76, 0.06),
}


def _joint_position(name: str) -> np.ndarray:
    if name in BODY_JOINTS:
        return np.array(BODY_JOINTS[name], float)
    side = 1.0 if name.startswith("left") else -1.0
    finger = ["index", "middle", "pinky", "ring", "thumb"].index(name.split("_")[1][:-1])
    knuckle = int(name[-1])
    return np.array([side * (0.16 + 0.005 * finger), 0.03 - 0.02 * knuckle, 0.01 * finger])


def write_model(path, subdivisions: int, width: float):
    """An ellipsoid 'person' (1.8 m tall at betas 0) with the 55 SMPL-X joints; beta0 = height, beta1 = girth."""
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions)
    v = np.asarray(mesh.vertices) * [width, 0.9, 0.12]
    shapedirs = np.zeros(v.shape + (10,))
    shapedirs[:, 1, 0] = 0.05 * v[:, 1]           # +5 % height per unit of beta0
    shapedirs[:, [0, 2], 1] = 0.1 * v[:, [0, 2]]  # +10 % width and depth per unit of beta1
    positions = np.array([_joint_position(n) for n in JOINT_NAMES])
    regressor = np.zeros((len(JOINT_NAMES), len(v)))
    for j, p in enumerate(positions):
        d = np.linalg.norm(v - p, axis=1)
        near = np.argsort(d)[:8]
        regressor[j, near] = 1.0 / (d[near] + 1e-3)
        regressor[j] /= regressor[j].sum()
    weights = np.zeros((len(v), len(JOINT_NAMES)))
    weights[np.arange(len(v)), np.argmin(np.linalg.norm(v[:, None] - positions[None, :22], axis=2), axis=1)] = 1.0
    kintree = np.array([[2**32 - 1] + PARENTS[1:], list(range(len(JOINT_NAMES)))], dtype=np.uint32)
    np.savez(path, v_template=v, f=np.asarray(mesh.faces, dtype=np.uint32), shapedirs=shapedirs,
             J_regressor=regressor, weights=weights, kintree_table=kintree, posedirs=np.zeros((len(v), 3, 1)))


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("smplx")
    write_model(folder / "SMPLX_FEMALE.npz", subdivisions=3, width=0.19)
    write_model(folder / "SMPLX_MALE.npz", subdivisions=4, width=0.21)
    return folder


@pytest.mark.parametrize("sex, height, bmi", [("F", 1.60, 28.1), ("M", 1.83, 35.8), ("M", 1.81, 22.7)])
def test_betas_fit_height_and_bmi(model_dir, sex, height, bmi):
    body = fit_body(sex, height, bmi, backend_name="smplx", smplx_dir=model_dir)
    a = body.anthropometry
    assert abs(a.height_m - height) <= 0.01 and abs(a.bmi - bmi) <= 0.5 and body.fit.reachable
    assert body.vertices[:, 1].min() == pytest.approx(0.0)
    assert set(body.phenotype) >= {"beta0", "beta1"}


def test_sex_selects_the_model_file(model_dir):
    female = fit_body("F", 1.7, 24, backend_name="smplx", smplx_dir=model_dir)
    male = fit_body("M", 1.7, 24, backend_name="smplx", smplx_dir=model_dir)
    assert female.n_vertices == 642 and male.n_vertices == 2562


def test_rig_segments_and_skinning(model_dir):
    body = fit_body("M", 1.8, 25, backend_name="smplx", smplx_dir=model_dir)
    assert body.rig.names == JOINT_NAMES and body.rig.parents[0] == -1 and body.rig.parents[18] == 16
    assert len(body.segments) == 15
    assert body.segments_frame()["mass_volume_kg"].sum() == pytest.approx(body.anthropometry.mass_kg, rel=1e-6)
    rot, root = body.rest_pose()
    assert np.allclose(body.skin(rot, root)[0], body.vertices, atol=1e-9)
    turn = Rotation.from_euler("y", 30, degrees=True)
    rot[0, 0] = turn.as_quat()[[3, 0, 1, 2]]
    moved = body.skin(rot, root + [0, 0, 1.0])[0]
    assert np.allclose(moved, (body.vertices - root) @ turn.as_matrix().T + root + [0, 0, 1.0])


def test_unreachable_and_bad_files(model_dir, tmp_path):
    with pytest.raises(BodyFitError, match="out of reach of the SMPL-X model") as info:
        fit_body("F", 1.6, 300, backend_name="smplx", smplx_dir=model_dir)
    assert info.value.nearest.anthropometry.height_m == pytest.approx(1.6, abs=0.01)
    with pytest.raises(StimuliError, match="SMPLX_FEMALE.npz"):
        fit_body("F", 1.6, 22, backend_name="smplx", smplx_dir=tmp_path)
    np.savez(tmp_path / "SMPLX_MALE.npz", v_template=np.zeros((3, 3)))
    with pytest.raises(StimuliError, match="missing f, shapedirs"):
        load_model(str(tmp_path / "SMPLX_MALE.npz"))
    with pytest.raises(StimuliError, match="--smplx-dir"):
        fit_body("F", 1.6, 22, backend_name="smplx")
    with pytest.raises(StimuliError, match="unknown body backend"):
        fit_body("F", 1.6, 22, backend_name="smpl-y")


def test_cli_single_body_with_smplx(model_dir, tmp_path, run_cli):
    code, out, _ = run_cli("bodies", "--sex", "F", "--height", "1.65", "--bmi", "23", "--backend", "smplx",
                           "--smplx-dir", model_dir, "--out", tmp_path / "s.ply")
    assert code == 0 and "BMI 23.0" in out
    mesh = trimesh.load(tmp_path / "s.ply", process=False)
    assert np.ptp(mesh.vertices[:, 1]) == pytest.approx(1.65, abs=0.01)
    code, _, err = run_cli("bodies", "--sex", "F", "--height", "1.65", "--bmi", "23", "--backend", "smplx",
                           "--out", tmp_path / "s.ply")
    assert code == 2 and "--smplx-dir" in err
