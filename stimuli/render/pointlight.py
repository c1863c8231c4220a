"""Point-light walkers: the 15 markers of SPEC §1.3 as white dots on black.

Markers (Shewhorak 2017): hips, left/right upper leg (mid-thigh), knees, heels, shoulders,
elbows, wrists, torso (chest) and head. They follow the body's skeleton by forward kinematics —
no mesh is skinned — and each dot is one small sphere node whose pose changes per frame.
"""

from __future__ import annotations

import numpy as np

from stimuli.render.gl import pyrender_module

MARKERS = ("head", "torso", "shoulder.L", "shoulder.R", "elbow.L", "elbow.R", "wrist.L", "wrist.R",
           "hips", "upper_leg.L", "upper_leg.R", "knee.L", "knee.R", "heel.L", "heel.R")
DOT_RADIUS_M = 0.035


def _heel_offset(body, side: str) -> np.ndarray:
    """Rest-pose vector from the ankle (foot bone head) to the back of the heel, 3 cm above the sole."""
    rig = body.rig
    ankle = rig.rest_heads[rig.index(f"foot.{side}")]
    v = body.vertices
    near = (np.abs(v[:, 0] - ankle[0]) < 0.035) & (v[:, 1] < ankle[1])
    back = v[near][np.argmin(v[near][:, 2])]
    return np.array([back[0], 0.03, back[2]]) - ankle


def marker_positions(body, rotations: np.ndarray, root_translation: np.ndarray) -> np.ndarray:
    """Marker positions (T, 15, 3), in the order of :data:`MARKERS`."""
    rig = body.rig
    glob, heads = rig.forward_kinematics(rotations, root_translation)
    j = rig.index
    head_bone = j("head")
    head_mid = 0.5 * (rig.rest_tails[head_bone] - rig.rest_heads[head_bone])
    out = {
        "head": heads[:, head_bone] + glob[:, head_bone] @ head_mid,
        "torso": heads[:, j("spine01")],
        "hips": heads[:, j("root")],
    }
    for s in ("L", "R"):
        out[f"shoulder.{s}"] = heads[:, j(f"upperarm01.{s}")]
        out[f"elbow.{s}"] = heads[:, j(f"lowerarm01.{s}")]
        out[f"wrist.{s}"] = heads[:, j(f"wrist.{s}")]
        out[f"knee.{s}"] = heads[:, j(f"lowerleg01.{s}")]
        out[f"upper_leg.{s}"] = 0.5 * (heads[:, j(f"upperleg01.{s}")] + heads[:, j(f"lowerleg01.{s}")])
        foot = j(f"foot.{s}")
        out[f"heel.{s}"] = heads[:, foot] + glob[:, foot] @ _heel_offset(body, s)
    return np.stack([out[name] for name in MARKERS], axis=1)


class DotFigure:
    """Sphere nodes for one walker's markers on a stage; :meth:`set_frame` moves them."""

    def __init__(self, stage, markers: np.ndarray, radius: float = DOT_RADIUS_M):
        import trimesh

        pyrender = pyrender_module()
        self.markers = markers
        sphere = trimesh.creation.icosphere(subdivisions=2, radius=radius)
        material = pyrender.MetallicRoughnessMaterial(baseColorFactor=(1.0, 1.0, 1.0, 1.0))
        mesh = pyrender.Mesh.from_trimesh(sphere, material=material)
        self.nodes = [stage.add(mesh, pose=self._pose(markers[0, k])) for k in range(markers.shape[1])]
        self.scene = stage.scene

    @staticmethod
    def _pose(position) -> np.ndarray:
        pose = np.eye(4)
        pose[:3, 3] = position
        return pose

    def set_frame(self, i: int) -> None:
        for k, node in enumerate(self.nodes):
            self.scene.set_pose(node, self._pose(self.markers[i, k]))
