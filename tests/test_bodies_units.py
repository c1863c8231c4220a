"""Bodies, pure-numpy parts: frame change, rig kinematics, measurements, segment split (no Anny needed)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from stimuli.bodies import frame
from stimuli.bodies.fit import BUILD_MAX, build_path
from stimuli.bodies.measure import absi, bai, bsa_mosteller, mesh_volume, slice_girth, unique_edges
from stimuli.bodies.rig import Rig, as_matrices, quaternions_to_matrices
from stimuli.bodies.segments import TABLE1, bone_segment, segment_labels, split_volumes


def test_frame_is_a_proper_rotation_mapping_up_and_forward():
    c = frame.ANNY_TO_PROJECT
    assert np.allclose(c @ c.T, np.eye(3)) and np.isclose(np.linalg.det(c), 1.0)
    assert np.allclose(c @ [0, 0, 1], [0, 1, 0])      # Anny up (z) -> project up (y)
    assert np.allclose(c @ [0, -1, 0], [0, 0, 1])     # Anny forward (-y) -> project forward (+z)
    assert np.allclose(c @ [1, 0, 0], [1, 0, 0])      # body's left stays +x


def test_points_and_rotations_convert_consistently():
    rng = np.random.default_rng(1)
    r = Rotation.random(5, random_state=2).as_matrix()
    p = rng.normal(size=(5, 3))
    lhs = frame.points_to_project(np.einsum("nij,nj->ni", r, p))
    rhs = np.einsum("nij,nj->ni", frame.rotations_to_project(r), frame.points_to_project(p))
    assert np.allclose(lhs, rhs)
    pts = np.array([[0.0, 0.0, -0.8], [0.0, 0.1, 0.9]])
    shifted = frame.points_to_project(pts, frame.ground_shift_for(pts))
    assert shifted[:, 1].min() == pytest.approx(0.0) and shifted[1, 1] == pytest.approx(1.7)


def test_quaternions_w_first_match_scipy():
    q = Rotation.random(20, random_state=3).as_quat()  # x, y, z, w
    mine = quaternions_to_matrices(q[:, [3, 0, 1, 2]])
    assert np.allclose(mine, Rotation.from_quat(q).as_matrix())
    assert np.allclose(quaternions_to_matrices(np.zeros(4)), np.eye(3))  # zero quaternion -> identity


def _chain_rig():
    """root at y=1 -> a (1 up) -> b (1 up), plus a second child c of root to the side."""
    heads = np.array([[0, 1.0, 0], [0, 2.0, 0], [0, 3.0, 0], [1.0, 1.0, 0]])
    return Rig(names=["root", "a", "b", "c"], parents=np.array([-1, 0, 1, 0]), rest_heads=heads,
               rest_tails=heads + [0, 1, 0], rest_rotations=np.tile(np.eye(3), (4, 1, 1)))


def test_forward_kinematics_chains_rotations_in_rest_axes():
    rig = _chain_rig()
    rz = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    rots = np.tile(np.eye(3), (1, 4, 1, 1))
    rots[0, 1] = rz                                  # rotate a: moves b only
    glob, heads = rig.forward_kinematics(rots, [[0.5, 1.0, 0.0]])
    assert np.allclose(heads[0], [[0.5, 1, 0], [0.5, 2, 0], [-0.5, 2, 0], [1.5, 1, 0]])
    assert np.allclose(glob[0, 2], rz)               # b inherits a's rotation
    with pytest.raises(ValueError, match="frames"):
        rig.forward_kinematics(rots, np.zeros((2, 3)))


def test_skinning_transforms_are_identity_at_rest_and_rigid_in_pose():
    rig = _chain_rig()
    rest = rig.skinning_transforms(np.tile([1.0, 0, 0, 0], (1, 4, 1)), rig.rest_heads[:1])
    assert np.allclose(rest, np.eye(4))
    rots = quaternions_to_matrices(Rotation.random(4, random_state=5).as_quat()[:, [3, 0, 1, 2]])[None]
    t = rig.skinning_transforms(rots, [[0.0, 1.2, 0.3]])
    glob, heads = rig.forward_kinematics(rots, [[0.0, 1.2, 0.3]])
    moved = np.einsum("bij,bj->bi", t[0, :, :3, :3], rig.rest_heads) + t[0, :, :3, 3]
    assert np.allclose(moved, heads[0])               # each bone's transform carries its head to its pose


def test_rotation_shapes_are_checked():
    with pytest.raises(ValueError, match="quaternions"):
        as_matrices(np.zeros((2, 5, 3)), 4)
    assert as_matrices(np.tile(np.eye(3), (2, 4, 1, 1)), 4).shape == (2, 4, 3, 3)


def test_indices_against_hand_computed_values():
    assert bsa_mosteller(1.80, 80.0) == pytest.approx(2.0)
    assert bai(1.00, 1.60) == pytest.approx(100 / 1.6**1.5 - 18)
    assert absi(0.94, 24.7, 1.80) == pytest.approx(0.94 / (24.7 ** (2 / 3) * 1.80**0.5))


def _cylinder(radius=0.15, height=1.0, sections=256):
    import trimesh

    mesh = trimesh.creation.cylinder(radius=radius, height=height, sections=sections)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]))  # axis along y
    return mesh


def test_girth_and_volume_of_a_cylinder():
    mesh = _cylinder()
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    assert slice_girth(v, unique_edges(f), 0.1) == pytest.approx(2 * np.pi * 0.15, rel=1e-3)
    assert mesh_volume(v, f) == pytest.approx(np.pi * 0.15**2, rel=1e-3)
    assert slice_girth(v, unique_edges(f), 5.0) == 0.0      # a level that misses the mesh


def test_split_volumes_partition_a_closed_mesh_exactly():
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    centres = v[f].mean(axis=1)
    labels = (centres[:, 1] > 0.1).astype(int) + (centres[:, 0] > 0.2).astype(int)  # three uneven pieces
    volume, centroid = split_volumes(v, f, labels, 3)
    assert volume.sum() == pytest.approx(mesh.volume, rel=1e-9)
    assert np.all(volume > 0)
    total = (volume[:, None] * centroid).sum(0) / volume.sum()
    assert np.allclose(total, mesh.center_mass, atol=1e-9)
    top = labels == 2
    assert centroid[2, 0] > 0.2 and centroid[2, 1] > 0.1 and top.any()  # the piece sits where its faces are


def test_table1_weight_factors_sum_to_one():
    total = sum((x_w or 0.0) * (1 if name in ("head", "spine", "pelvis") else 2) for name, (x_w, _) in TABLE1.items())
    assert total == pytest.approx(1.0)
    assert len(segment_labels()) == 15


@pytest.mark.parametrize("bone, expected", [
    ("root", ("pelvis", "")), ("spine05", ("pelvis", "")), ("spine01", ("spine", "")), ("neck02", ("head", "")),
    ("upperarm02.R", ("upper_arm", "R")), ("finger3-2.L", ("hand", "L")), ("toe5-3.R", ("foot", "R")),
    ("lowerleg01.L", ("lower_leg", "L")), ("clavicle.L", ("spine", "")),
])
def test_bone_segments(bone, expected):
    assert bone_segment(bone) == expected


def test_build_path_is_continuous_and_bounded():
    s = np.linspace(0, BUILD_MAX, 241)
    w, m = build_path(s)
    assert np.all(np.abs(np.diff(w)) < 0.01) and np.all(np.abs(np.diff(m)) < 0.01)
    assert w.min() == 0.0 and w.max() == pytest.approx(1.2) and m.min() == pytest.approx(-0.2)
