"""Point-light walkers: the 15 markers of SPEC §1.3 as white dots on black.

The markers are :mod:`stimuli.motion.markers`' (``body_markers``: the same positions as the CSV of
``shapemotion motion markers --body``). They follow the body's skeleton by forward kinematics — no
mesh is skinned — and each dot is one small sphere node whose pose changes per frame.
"""

from __future__ import annotations

import numpy as np

from stimuli.render.gl import pyrender_module

DOT_RADIUS_M = 0.035


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
