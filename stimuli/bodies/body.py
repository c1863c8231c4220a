"""The ``Body``: a fitted Anny mesh with its rig, anthropometry and segment table (project frame)."""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import numpy as np

from stimuli.bodies import backend, frame
from stimuli.bodies.measure import Anthropometry, max_girth, measure, unique_edges
from stimuli.bodies.rig import Rig
from stimuli.bodies.segments import ANNY, Segment, SkeletonProfile, build_segments, face_segments, segment_labels

# Bones whose flesh the chest girth may cross (not the shoulders or arms).
_CHEST_SEGMENT = "spine"
_HIP_SEGMENTS = ("pelvis", "upper_leg.L", "upper_leg.R")


@dataclasses.dataclass(frozen=True)
class FitReport:
    """How a body was obtained: errors against the targets, timing, cache use."""

    reachable: bool
    height_error_m: float
    bmi_error: float
    seconds: float
    cached: bool
    iterations: int
    message: str = ""


@dataclasses.dataclass
class Body:
    """A rest-pose body in the project frame (metres; y up, faces +z, feet on y = 0)."""

    body_id: str
    sex: str
    targets: dict[str, float | None]
    phenotype: dict[str, float]
    vertices: np.ndarray
    faces: np.ndarray
    rig: Rig
    anthropometry: Anthropometry
    segments: list[Segment]
    fit: FitReport
    skinner: object = dataclasses.field(default=None, repr=False)  # None: Anny's skinning

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    def rest_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Identity rotations (1, J, 4) and the rest root position (1, 3): skinning them gives ``vertices``."""
        rotations = np.zeros((1, self.rig.n_bones, 4))
        rotations[..., 0] = 1.0
        return rotations, self.rig.rest_heads[:1].copy()

    def joint_positions(self, local_rotations, root_translation) -> np.ndarray:
        """Posed bone heads (T, J, 3) — forward kinematics only."""
        return self.rig.forward_kinematics(local_rotations, root_translation)[1]

    def skin(self, local_rotations, root_translation, out: np.ndarray | None = None, chunk: int = 64) -> np.ndarray:
        """Posed vertices (T, V, 3) by Anny's linear-blend skinning, batched over frames.

        ``local_rotations``: (T, J, 4) w-first quaternions or (T, J, 3, 3); ``root_translation``:
        (T, 3) absolute root (pelvis) positions; ``out``: optional (T, V, 3) array filled in place.
        See :mod:`stimuli.bodies.rig` for the convention.
        """
        import torch

        transforms = self.rig.skinning_transforms(local_rotations, root_translation)
        n_frames = transforms.shape[0]
        if out is None:
            out = np.empty((n_frames, self.n_vertices, 3), dtype=np.float64)
        elif out.shape != (n_frames, self.n_vertices, 3):
            raise ValueError(f"out has shape {out.shape}, expected {(n_frames, self.n_vertices, 3)}")
        rest = torch.as_tensor(self.vertices, dtype=torch.float64)[None]
        with torch.no_grad():
            for start in range(0, n_frames, chunk):  # bounded memory for long clips
                part = torch.as_tensor(transforms[start:start + chunk], dtype=torch.float64)
                skinned = (self.skinner or backend.skin)(rest, part)
                out[start:start + chunk] = skinned.numpy()
        return out

    def to_trimesh(self):
        import trimesh

        return trimesh.Trimesh(self.vertices, self.faces, process=False)

    def save_ply(self, path: str | Path) -> Path:
        """Binary PLY of the rest mesh (written atomically)."""
        from stimuli.fileio import atomic_write_bytes

        data = self.to_trimesh().export(file_type="ply")
        atomic_write_bytes(path, data)
        return Path(path)

    def segments_frame(self):
        """The segment table as a pandas DataFrame (one row per segment, vectors as _x/_y/_z)."""
        import pandas as pd

        return pd.DataFrame([s.as_row() for s in self.segments])


@functools.lru_cache(maxsize=1)
def mesh_parts() -> dict[str, object]:
    """Topology-level data shared by all bodies: faces, face segments, girth edge sets."""
    topo = backend.topology()
    faces = topo["faces"]
    face_seg = face_segments(faces, topo["weights"], topo["indices"], topo["bone_names"])
    trunk_edges, hip_edges = girth_edges(faces, face_seg)
    return {**topo, "face_seg": face_seg, "trunk_edges": trunk_edges, "hip_edges": hip_edges}


def project_arrays(anny_out: dict, i: int) -> dict[str, np.ndarray]:
    """Vertices, bone heads and rotations of batch row ``i`` in the project frame, feet on y = 0."""
    vertices = anny_out["rest_vertices"][i]
    shift = frame.ground_shift_for(vertices)
    return {
        "vertices": frame.points_to_project(vertices, shift),
        "heads": frame.points_to_project(anny_out["rest_bone_heads"][i], shift),
        "rotations": frame.rotations_to_project(anny_out["rest_bone_poses"][i][:, :3, :3]),
    }


def _landmarks(heads: np.ndarray, names: list[str], profile: SkeletonProfile = ANNY) -> dict[str, float]:
    left, right = profile.hip_joints
    hip = 0.5 * (heads[names.index(left), 1] + heads[names.index(right), 1])
    return {"hip_joint": float(hip), "chest": float(heads[names.index(profile.chest_joint), 1])}


def girth_edges(faces: np.ndarray, face_seg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mesh edges of the trunk (chest girth) and of the pelvis + thighs (hip girth)."""
    labels = segment_labels()
    trunk = faces[face_seg == labels.index(_CHEST_SEGMENT)]
    hips = faces[np.isin(face_seg, [labels.index(s) for s in _HIP_SEGMENTS])]
    return unique_edges(trunk), unique_edges(hips)


def candidate_girths(anny_out: dict, i: int) -> dict[str, float]:
    """Hip and chest girths of one fitting candidate (used only when the targets ask for them)."""
    parts = mesh_parts()
    arrays = project_arrays(anny_out, i)
    v, lm = arrays["vertices"], _landmarks(arrays["heads"], parts["bone_names"])
    height = v[:, 1].max() - v[:, 1].min()
    return {
        "hip_m": max_girth(v, parts["hip_edges"], lm["hip_joint"] - 0.06 * height, lm["hip_joint"] + 0.03 * height),
        "chest_m": max_girth(v, parts["trunk_edges"], lm["chest"] - 0.03 * height, lm["chest"] + 0.04 * height),
    }


def rest_tails(heads: np.ndarray, parents: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """A tail per bone: the mean head of its children, else 5 cm along the bone's own y axis
    (Anny's 'cached' bone orientation stores no tails; Blender bones point along local y)."""
    tails = heads + 0.05 * rotations[:, :, 1]
    for j in range(len(heads)):
        children = np.flatnonzero(parents == j)
        if len(children):
            tails[j] = heads[children].mean(axis=0)
    return tails


def build_body(body_id: str, sex: str, targets: dict, phenotype: dict[str, float], anny_out: dict, i: int,
               fit: FitReport) -> Body:
    """Assemble a Body from row ``i`` of an Anny evaluation."""
    parts = mesh_parts()
    arrays = project_arrays(anny_out, i)
    return assemble_body(
        body_id, sex, targets, phenotype, arrays["vertices"], parts["faces"], list(parts["bone_names"]),
        np.asarray(parts["bone_parents"]), arrays["heads"], arrays["rotations"], float(anny_out["waist"][i]), parts,
        fit, ANNY)


def assemble_body(body_id, sex, targets, phenotype, vertices, faces, names, parents, heads, rotations, waist_m,
                  parts, fit, profile, skinner=None) -> Body:
    """A Body from project-frame arrays of any backend. ``parts`` holds ``face_seg``, ``trunk_edges``
    and ``hip_edges``; ``skinner`` replaces Anny's skinning (other backends)."""
    rig = Rig(names=names, parents=parents, rest_heads=heads,
              rest_tails=rest_tails(heads, parents, rotations), rest_rotations=rotations)
    anthro = measure(vertices, faces, waist_m, _landmarks(heads, names, profile), parts["trunk_edges"],
                     parts["hip_edges"], backend.ANNY_DENSITY)
    segments = build_segments(anthro.mass_kg, heads, names, vertices, faces, parts["face_seg"],
                              backend.ANNY_DENSITY, profile)
    return Body(body_id=body_id, sex=sex, targets=targets, phenotype=phenotype, vertices=vertices, faces=faces,
                rig=rig, anthropometry=anthro, segments=segments, fit=fit, skinner=skinner)
